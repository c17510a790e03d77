//! `iwsim bench ros2`: lock-step ticks per second with N chairs driven over ROS 2 topics
//! (`iwsim ros2`, a Zenoh router, and a ROS-side controller answering every chair's `odom`
//! with a `cmd_vel`), beside the same chairs driven by one shared-memory agent, in one run,
//! rounds interleaved.
//!
//! The ROS-side controller is this process: a Zenoh client session that speaks rmw_zenoh's
//! wire format (the bridge's own `names`, `cdr` and `msgs` modules, which the tests check
//! against rmw_zenoh's documentation and PyPI `rosbags`). Each chair turns on the spot (no
//! contacts), so every tick costs the same.

use std::process::{Child, ExitCode};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ros2_bridge::msgs::{self, Message as _};
use ros2_bridge::names;
use run_records::outcome::HubOutcome;
use sim_model::PoseDeg;
use zenoh::Wait as _;

use crate::args::BenchRos2Args;
use crate::repeat::Spread;

/// Children killed when a run fails before they end.
struct Children(Vec<Child>);

impl Drop for Children {
    fn drop(&mut self) {
        for c in &mut self.0 {
            if matches!(c.try_wait(), Ok(None)) {
                let _ = c.kill();
            }
            let _ = c.wait();
        }
    }
}

/// The chairs' start poses: rows of ten, 3 m apart, on an empty 40 m x 40 m floor.
fn pose(k: usize) -> PoseDeg {
    [3.0 + 3.0 * (k % 10) as f64, 3.0 + 3.0 * (k / 10) as f64, 0.0]
}

fn free_port() -> anyhow::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// One lock-step run of `chairs` chairs over `ticks` ticks: ticks/s.
fn run_once(chairs: usize, ticks: u64, ros2: bool, dir: &std::path::Path) -> anyhow::Result<f64> {
    let lab = dir.join("floor.xml");
    std::fs::write(&lab, "<Lab Name=\"bench-ros2\" Width=\"40\" Height=\"40\"></Lab>\n")?;
    static RUN: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let session = format!("bench-ros2-{}-{n}", std::process::id());
    let s = |x: &str| x.to_owned();
    let hub_args = vec![
        s("hub"),
        s("--session"),
        session.clone(),
        s("--lab"),
        lab.display().to_string(),
        s("--lockstep"),
        s("--ticks"),
        ticks.to_string(),
        s("--wait-agents"),
        s("1"),
        s("--no-noise"),
        s("--json"),
    ];
    let mut children = Children(Vec::new());
    let mut router = Children(Vec::new());
    let hub = crate::spawn_self(&hub_args)?;
    let mut controller = None;
    if ros2 {
        let endpoint = format!("tcp/127.0.0.1:{}", free_port()?);
        router.0.push(crate::spawn_self(&[s("zenoh-router"), s("--listen"), endpoint.clone()])?);
        let mut args = vec![
            s("ros2"),
            s("--session"),
            session.clone(),
            s("--connect"),
            endpoint.clone(),
            s("--connect-timeout"),
            s("30"),
        ];
        for k in 0..chairs {
            let [x, y, d] = pose(k);
            args.extend([s("--chair"), format!("chair{k}={x},{y},{d}")]);
        }
        children.0.push(crate::spawn_self(&args)?);
        controller = Some(Controller::start(&endpoint, chairs)?);
    } else {
        let [x, y, d] = pose(0);
        children.0.push(crate::spawn_self(&[
            s("agent"),
            s("wheelchair"),
            s("--session"),
            session.clone(),
            s("--robots"),
            chairs.to_string(),
            s("--pose"),
            format!("{x},{y},{d}"),
            s("--spacing"),
            s("3"),
            s("--powers"),
            s("-0.2,0.2"),
            s("--connect-timeout"),
            s("30"),
        ])?);
    }
    let out = crate::finish(hub, "hub")?;
    let outcome = HubOutcome::from_stdout(&out).context("reading how the hub's run ended")?;
    if let Some(c) = controller {
        // Every chair's odom of every tick was answered, or the run did not carry the load.
        let want = chairs as u64 * outcome.ticks;
        anyhow::ensure!(c.answered() >= want, "the ROS-side controller answered {} odoms of {want}", c.answered());
        c.close();
    }
    // The bridge and the agent end with the run; the router (dropped last, killed: it holds
    // no shared state) runs until told.
    for c in &mut children.0 {
        let deadline = Instant::now() + Duration::from_secs(10);
        while matches!(c.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    drop(children);
    drop(router);
    Ok(outcome.ticks as f64 / outcome.run_s.max(1e-9))
}

/// The ROS side: one Zenoh session answering each chair's `odom` with a `cmd_vel`.
struct Controller {
    z: zenoh::Session,
    answered: Arc<std::sync::atomic::AtomicU64>,
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl Controller {
    fn start(endpoint: &str, chairs: usize) -> anyhow::Result<Self> {
        let cfg = agent_sdk::remote::config(None, "client", &[], &[endpoint.to_owned()])?;
        let z = open_within(cfg, Duration::from_secs(20))?;
        let answered = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let turn = msgs::Twist { linear: [0.0; 3], angular: [0.0, 0.0, 0.3] }.to_cdr();
        let mut subs = Vec::new();
        let mut tokens = Vec::new();
        let node =
            names::Node { domain: 0, zid: z.zid().to_string(), id: 0, namespace: "/".into(), name: "bench".into() };
        for k in 0..chairs {
            // A ROS node's publisher token: it tells the bridge the chair has a controller
            // (a first sample could be lost while Zenoh's routes are still being made).
            let token = node.entity_token(
                k as u32 + 1,
                names::EntityKind::Publisher,
                &format!("/chair{k}/cmd_vel"),
                &msgs::TWIST,
                names::Qos::reliable(10),
            );
            tokens
                .push(z.liveliness().declare_token(token).wait().map_err(|e| anyhow::anyhow!("declare a token: {e}"))?);
            let publisher = z
                .declare_publisher(names::data_key(0, &format!("/chair{k}/cmd_vel"), &msgs::TWIST))
                .wait()
                .map_err(|e| anyhow::anyhow!("declare cmd_vel: {e}"))?;
            let gid = [k as u8; 16];
            let (twist, count) = (turn.clone(), answered.clone());
            let mut seq = 0i64;
            let sub = z
                .declare_subscriber(names::data_key(0, &format!("/chair{k}/odom"), &msgs::ODOMETRY))
                .callback_mut(move |_| {
                    seq += 1;
                    let _ = publisher.put(twist.clone()).attachment(names::attachment(seq, 0, &gid).to_vec()).wait();
                    count.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                })
                .wait()
                .map_err(|e| anyhow::anyhow!("subscribe to odom: {e}"))?;
            subs.push(sub);
        }
        Ok(Self { z, answered, _subs: subs, _tokens: tokens })
    }

    fn answered(&self) -> u64 {
        self.answered.load(std::sync::atomic::Ordering::Relaxed)
    }

    fn close(self) {
        let _ = self.z.close().wait();
    }
}

fn open_within(cfg: zenoh::Config, timeout: Duration) -> anyhow::Result<zenoh::Session> {
    let start = Instant::now();
    loop {
        match zenoh::open(cfg.clone()).wait() {
            Ok(z) => return Ok(z),
            Err(_) if start.elapsed() < timeout => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => anyhow::bail!("connect to the router: {e}"),
        }
    }
}

/// `iwsim bench ros2`.
pub fn run(a: &BenchRos2Args) -> anyhow::Result<ExitCode> {
    let dir = std::env::temp_dir().join(format!("iwsim-bench-ros2-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let cpu = crate::traffic::cpu_model();
    let mut rows = Vec::new();
    for &chairs in &a.chairs {
        let (mut over_ros2, mut over_shm) = (Vec::new(), Vec::new());
        for _ in 0..a.runs {
            over_ros2.push(run_once(chairs, a.ticks, true, &dir)?);
            over_shm.push(run_once(chairs, a.ticks, false, &dir)?);
        }
        let ratios: Vec<f64> = over_ros2.iter().zip(&over_shm).map(|(r, s)| r / s.max(1e-9)).collect();
        let spread = |v: &[f64]| Spread::of(v).unwrap_or(Spread { median: 0.0, min: 0.0, max: 0.0, runs: 0 });
        rows.push((chairs, spread(&over_ros2), spread(&over_shm), spread(&ratios)));
    }
    let _ = std::fs::remove_dir_all(&dir);
    if a.json {
        let items: Vec<String> = rows
            .iter()
            .map(|(n, r, s, q)| {
                format!(
                    "{{\"chairs\":{n},\"ros2_ticks_per_s\":{{\"median\":{:.1},\"min\":{:.1},\"max\":{:.1}}},\"shm_ticks_per_s\":{{\"median\":{:.1},\"min\":{:.1},\"max\":{:.1}}},\"ros2_over_shm\":{{\"median\":{:.3},\"min\":{:.3},\"max\":{:.3}}}}}",
                    r.median, r.min, r.max, s.median, s.min, s.max, q.median, q.min, q.max
                )
            })
            .collect();
        println!("{{\"cpu\":{cpu:?},\"ticks\":{},\"runs\":{},\"sizes\":[{}]}}", a.ticks, a.runs, items.join(","));
    } else {
        println!("lock-step ticks/s, {} ticks, median [min, max] of {} runs ({cpu})", a.ticks, a.runs);
        for (n, r, s, q) in &rows {
            println!(
                "{n:>3} chairs: over ROS 2 {:.0} [{:.0}, {:.0}], one shared-memory agent {:.0} [{:.0}, {:.0}], ROS 2 / shm {:.2} [{:.2}, {:.2}]",
                r.median, r.min, r.max, s.median, s.min, s.max, q.median, q.min, q.max
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
