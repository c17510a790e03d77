//! `iwsim bench …`: figures printed as text or JSON.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use hub::tiled::TiledWorld;

use anyhow::Context as _;

use crate::cli::{BenchLatencyArgs, BenchLockstepArgs, BenchWorldArgs, RawPeerArgs};

/// Result of `iwsim bench world`.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldBench {
    /// Chairs in the world.
    pub robots: usize,
    /// Ticks timed.
    pub ticks: u64,
    /// Ticks per second of `World::step` alone.
    pub ticks_per_s: f64,
    /// Microseconds per robot per tick.
    pub us_per_robot_tick: f64,
    /// Median time of one tick, milliseconds.
    pub p50_tick_ms: f64,
    /// Time to build the world and place the chairs, seconds.
    pub build_s: f64,
}

/// Steps tiled LIACC floors with `robots` chairs and times `World::step` (the controller that
/// makes the actions runs between ticks and is not timed).
/// The chairs first drive `warmup` ticks untimed, so every run times the same stretch of the
/// same (seeded) drive.
pub fn measure_world(robots: usize, ticks: u64, warmup: u64, seed: u64) -> anyhow::Result<WorldBench> {
    let t0 = Instant::now();
    let mut w = TiledWorld::build(robots, seed)?;
    let build_s = t0.elapsed().as_secs_f64();
    for _ in 0..warmup {
        w.tick(0.1);
    }
    let mut per_tick = Vec::with_capacity(ticks as usize);
    let mut total = Duration::ZERO;
    for _ in 0..ticks {
        w.control();
        let t = Instant::now();
        w.step_only(0.1);
        let dt = t.elapsed();
        total += dt;
        per_tick.push(dt);
    }
    per_tick.sort_unstable();
    let secs = total.as_secs_f64().max(1e-12);
    Ok(WorldBench {
        robots,
        ticks,
        ticks_per_s: ticks as f64 / secs,
        us_per_robot_tick: secs * 1e6 / (ticks as f64 * robots.max(1) as f64),
        p50_tick_ms: per_tick.get(per_tick.len() / 2).map_or(0.0, |d| d.as_secs_f64() * 1e3),
        build_s,
    })
}

/// `iwsim bench world`.
pub fn world(args: &BenchWorldArgs) -> anyhow::Result<ExitCode> {
    let b = measure_world(args.robots, args.ticks, args.warmup, args.seed)?;
    if args.json {
        println!(
            "{{\"robots\":{},\"ticks\":{},\"warmup\":{},\"ticks_per_s\":{:.1},\"us_per_robot_tick\":{:.4},\"p50_tick_ms\":{:.4},\"build_s\":{:.3}}}",
            b.robots, b.ticks, args.warmup, b.ticks_per_s, b.us_per_robot_tick, b.p50_tick_ms, b.build_s
        );
    } else {
        println!(
            "world: {} chairs on tiled LIACC floors, 8 proximity sensors each, noise on\n  {:.1} ticks/s  ({:.3} us per robot-tick, median tick {:.3} ms, {} ticks timed; built in {:.2} s)\n  real-time factor at 100 ms ticks: {:.1}x",
            b.robots,
            b.ticks_per_s,
            b.us_per_robot_tick,
            b.p50_tick_ms,
            b.ticks,
            b.build_s,
            b.ticks_per_s / 10.0
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Latency percentiles in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Percentiles {
    /// Samples.
    pub samples: usize,
    /// Median, µs.
    pub p50_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// 99.9th percentile, µs.
    pub p999_us: f64,
}

impl Percentiles {
    /// Percentiles of nanosecond samples.
    pub fn of_ns(samples: &[u64]) -> Self {
        let mut v = samples.to_vec();
        v.sort_unstable();
        let at = |q: f64| {
            if v.is_empty() {
                return 0.0;
            }
            let i = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1;
            v[i] as f64 / 1000.0
        };
        Self { samples: v.len(), p50_us: at(0.50), p99_us: at(0.99), p999_us: at(0.999) }
    }

    /// One JSON object.
    pub fn json(&self) -> String {
        format!(
            "{{\"samples\":{},\"p50_us\":{:.3},\"p99_us\":{:.3},\"p999_us\":{:.3}}}",
            self.samples, self.p50_us, self.p99_us, self.p999_us
        )
    }

    /// Reads the object `json` printed.
    pub fn parse(text: &str) -> Option<Self> {
        let line = text.lines().rev().find(|l| l.contains("\"p50_us\""))?;
        let field = |k: &str| -> Option<f64> {
            let key = format!("\"{k}\":");
            let rest = &line[line.find(&key)? + key.len()..];
            rest[..rest.find([',', '}'])?].parse().ok()
        };
        Some(Self {
            samples: field("samples")? as usize,
            p50_us: field("p50_us")?,
            p99_us: field("p99_us")?,
            p999_us: field("p999_us")?,
        })
    }
}

fn iwsim_exe() -> anyhow::Result<std::path::PathBuf> {
    std::env::current_exe().context("finding the iwsim executable")
}

fn spawn_self(args: &[String]) -> anyhow::Result<std::process::Child> {
    std::process::Command::new(iwsim_exe()?)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .context("starting an iwsim process")
}

fn finish(child: std::process::Child, what: &str) -> anyhow::Result<String> {
    let out = child.wait_with_output().with_context(|| format!("waiting for the {what}"))?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        anyhow::bail!("the {what} failed: {}{}", stdout, String::from_utf8_lossy(&out.stderr));
    }
    Ok(stdout)
}

/// Hub publish → agent has its sensor block, through the real hub and agent processes.
fn hub_latency(samples: u64, busy: bool) -> anyhow::Result<Percentiles> {
    let session = format!("bench-lat-{}-{}", std::process::id(), busy as u8);
    let s = |x: &str| x.to_owned();
    let hub = spawn_self(&[
        s("hub"),
        s("--session"),
        session.clone(),
        s("--lockstep"),
        s("--ticks"),
        (samples + 100).to_string(),
        s("--wait-agents"),
        s("1"),
        s("--no-noise"),
        s("--json"),
    ])?;
    let mut agent_args =
        vec![s("agent"), s("wheelchair"), s("--session"), session, s("--report-latency"), s("--powers"), s("0.2,0.2")];
    if busy {
        agent_args.push(s("--busy-poll"));
    }
    let agent = spawn_self(&agent_args)?;
    finish(hub, "hub")?;
    let out = finish(agent, "agent")?;
    Percentiles::parse(&out).context("the agent printed no latency figures")
}

/// The same one-way latency for a bare iceoryx2 publish (+ notify) of a sample of the sensor
/// block's size, answered by a pong, between this process and a peer. The driver waits for
/// each pong asleep, as the hub waits for actions, so both sides tick at a similar pace.
fn raw_latency(samples: u64, busy: bool) -> anyhow::Result<Percentiles> {
    use ipc_services::iceoryx2::prelude::*;
    let session = ipc_services::Session::new(&format!("bench-raw-{}-{}", std::process::id(), busy as u8))?;
    let node = session.node("raw-driver")?;
    let (ping, ping_ev, pong, pong_ev) = raw::services(&session, &node, true)?;
    let publisher = ping.publisher_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let notifier = ping_ev.notifier_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let subscriber = pong.subscriber_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let listener = pong_ev.listener_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let peer = spawn_self(&[
        "bench".into(),
        "raw-peer".into(),
        "--session".into(),
        session.name().to_owned(),
        "--samples".into(),
        (samples + 100).to_string(),
        if busy { "--busy-poll".into() } else { "--blocking".into() },
    ])?;
    let start = Instant::now();
    while ping.dynamic_config().number_of_subscribers() == 0 || ping_ev.dynamic_config().number_of_listeners() == 0 {
        anyhow::ensure!(start.elapsed() < Duration::from_secs(10), "the raw peer did not connect");
        std::thread::sleep(Duration::from_millis(1));
    }
    for seq in 0..samples + 100 {
        let mut sample = publisher.loan_uninit().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let mut ping_msg = raw::Ping { seq, t_pub_ns: 0, payload: [0; raw::PAYLOAD] };
        ping_msg.t_pub_ns = ipc_types::monotonic_ns();
        sample.payload_mut().write(ping_msg);
        #[allow(unsafe_code)]
        // SAFETY: the payload was written in full on the line above.
        let sample = unsafe { sample.assume_init() };
        sample.send().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        notifier.notify().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            if let Some(p) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))?
                && *p.payload() == seq
            {
                break;
            }
            anyhow::ensure!(Instant::now() < deadline, "the raw peer stopped answering");
            // The driver plays the hub, which sleeps until the agent answers whatever the
            // agent's own wait: only the receiving side differs between the two modes.
            listener.timed_wait(|_| {}, Duration::from_millis(100)).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
    }
    let out = finish(peer, "raw peer")?;
    drop((publisher, notifier, subscriber, listener, ping, ping_ev, pong, pong_ev, node));
    session.release_if_unused();
    Percentiles::parse(&out).context("the raw peer printed no latency figures")
}

/// The peer of the raw ping-pong: receives pings, records their one-way latency, answers.
pub fn raw_peer(args: &RawPeerArgs) -> anyhow::Result<ExitCode> {
    let session = ipc_services::Session::new(&args.session)?;
    let node = session.node("raw-peer")?;
    let (ping, ping_ev, pong, pong_ev) = raw::services(&session, &node, false)?;
    let subscriber = ping.subscriber_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let listener = ping_ev.listener_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let publisher = pong.publisher_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let notifier = pong_ev.notifier_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut lat = Vec::with_capacity(args.samples as usize);
    let deadline = Instant::now() + Duration::from_secs(120);
    while (lat.len() as u64) < args.samples {
        anyhow::ensure!(Instant::now() < deadline, "the raw driver stopped sending");
        if let Some(p) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            let now = ipc_types::monotonic_ns();
            lat.push(now.saturating_sub(p.payload().t_pub_ns));
            publisher.send_copy(p.payload().seq).map_err(|e| anyhow::anyhow!("{e:?}"))?;
            notifier.notify().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        } else if !args.busy_poll {
            listener.timed_wait(|_| {}, Duration::from_millis(100)).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
    }
    println!("{}", Percentiles::of_ns(&lat[lat.len().min(100)..]).json());
    drop((subscriber, listener, publisher, notifier, ping, ping_ev, pong, pong_ev, node));
    session.release_if_unused();
    Ok(ExitCode::SUCCESS)
}

mod raw {
    use ipc_services::iceoryx2::node::Node;
    use ipc_services::iceoryx2::prelude::ZeroCopySend;
    use ipc_services::{EventService, Session, Svc};

    /// Bytes after the header, so a ping is as large as a sensor block.
    pub const PAYLOAD: usize = 816;

    /// A ping of the size of a sensor block.
    #[repr(C)]
    #[derive(Debug, Clone, Copy, ZeroCopySend)]
    #[type_name("iwsim::bench::Ping.v1")]
    pub struct Ping {
        pub seq: u64,
        pub t_pub_ns: u64,
        pub payload: [u8; PAYLOAD],
    }
    const _: () = assert!(core::mem::size_of::<Ping>() == core::mem::size_of::<ipc_types::SensorBlock>());

    type PingService = ipc_services::iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, Ping, ()>;
    type PongService = ipc_services::iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, u64, ()>;

    pub fn services(
        session: &Session,
        node: &Node<Svc>,
        create: bool,
    ) -> anyhow::Result<(PingService, EventService, PongService, EventService)> {
        let name = |p: &str| {
            ipc_services::iceoryx2::prelude::ServiceName::new(&session.service_name(p))
                .map_err(|e| anyhow::anyhow!("{e:?}"))
        };
        let ping = node
            .service_builder(&name("ping")?)
            .publish_subscribe::<Ping>()
            .subscriber_max_buffer_size(1)
            .enable_safe_overflow(true);
        let pong = node
            .service_builder(&name("pong")?)
            .publish_subscribe::<u64>()
            .subscriber_max_buffer_size(1)
            .enable_safe_overflow(true);
        let ping_ev = node.service_builder(&name("ping")?).event();
        let pong_ev = node.service_builder(&name("pong")?).event();
        let e = |e: &dyn std::fmt::Debug| anyhow::anyhow!("{e:?}");
        Ok(if create {
            (
                ping.create().map_err(|x| e(&x))?,
                ping_ev.create().map_err(|x| e(&x))?,
                pong.create().map_err(|x| e(&x))?,
                pong_ev.create().map_err(|x| e(&x))?,
            )
        } else {
            (
                ping.open().map_err(|x| e(&x))?,
                ping_ev.open().map_err(|x| e(&x))?,
                pong.open().map_err(|x| e(&x))?,
                pong_ev.open().map_err(|x| e(&x))?,
            )
        })
    }
}

/// `iwsim bench latency`.
pub fn latency(args: &BenchLatencyArgs) -> anyhow::Result<ExitCode> {
    let n = args.samples;
    let raw_busy = raw_latency(n, true)?;
    let hub_busy = hub_latency(n, true)?;
    let raw_block = raw_latency(n, false)?;
    let hub_block = hub_latency(n, false)?;
    let r = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    if args.json {
        println!(
            "{{\"samples\":{n},\"busy_poll\":{{\"hub\":{},\"raw\":{},\"ratio_p50\":{:.3},\"ratio_p99\":{:.3}}},\"blocking\":{{\"hub\":{},\"raw\":{},\"ratio_p50\":{:.3},\"ratio_p99\":{:.3}}}}}",
            hub_busy.json(),
            raw_busy.json(),
            r(hub_busy.p50_us, raw_busy.p50_us),
            r(hub_busy.p99_us, raw_busy.p99_us),
            hub_block.json(),
            raw_block.json(),
            r(hub_block.p50_us, raw_block.p50_us),
            r(hub_block.p99_us, raw_block.p99_us),
        );
    } else {
        println!("latency: hub publishes a tick -> the agent has its sensor block ({n} samples each, one-way, us)");
        println!("  {:<22} {:>9} {:>9} {:>9}", "", "p50", "p99", "p99.9");
        for (name, p) in [
            ("busy-poll  iwsim hub", hub_busy),
            ("busy-poll  raw iceoryx2", raw_busy),
            ("blocking   iwsim hub", hub_block),
            ("blocking   raw iceoryx2", raw_block),
        ] {
            println!("  {:<22} {:>9.2} {:>9.2} {:>9.2}", name, p.p50_us, p.p99_us, p.p999_us);
        }
        println!(
            "  ratio iwsim / raw: busy-poll p50 {:.2}x p99 {:.2}x; blocking p50 {:.2}x p99 {:.2}x",
            r(hub_busy.p50_us, raw_busy.p50_us),
            r(hub_busy.p99_us, raw_busy.p99_us),
            r(hub_block.p50_us, raw_block.p50_us),
            r(hub_block.p99_us, raw_block.p99_us)
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Result of `iwsim bench lockstep`.
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepBench {
    /// Agent processes.
    pub agents: usize,
    /// Robots per agent.
    pub robots_per_agent: usize,
    /// Ticks run.
    pub ticks: u64,
    /// Ticks per second, end to end.
    pub ticks_per_s: f64,
}

/// A hub in lock-step with `agents` agent processes of `robots_per_agent` robots each, physics
/// and sensors on, on an open 400 m lab; ticks per second from the first step to the last.
/// Robots stand in lattices 5 m apart (one per 25 m², about three times the density of the
/// LIACC floor in `bench world`), driving slow arcs.
pub fn measure_lockstep(agents: usize, robots_per_agent: usize, ticks: u64) -> anyhow::Result<LockstepBench> {
    let dir = std::env::temp_dir().join(format!("iwsim-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let lab = dir.join("lab.xml");
    std::fs::write(
        &lab,
        "<Lab Name=\"bench\" Width=\"400\" Height=\"400\">\n  <Wall Height=\"2\"><Corner X=\"200\" Y=\"0\"/><Corner X=\"201\" Y=\"0\"/><Corner X=\"201\" Y=\"150\"/><Corner X=\"200\" Y=\"150\"/></Wall>\n</Lab>\n",
    )?;
    let session = format!("bench-ls-{}", std::process::id());
    let hub = spawn_self(&[
        "hub".into(),
        "--session".into(),
        session.clone(),
        "--lab".into(),
        lab.display().to_string(),
        "--lockstep".into(),
        "--ticks".into(),
        ticks.to_string(),
        "--wait-agents".into(),
        agents.to_string(),
        "--json".into(),
    ])?;
    const SPACING: f64 = 5.0;
    let rows = robots_per_agent.div_ceil(10).max(1) as f64 * SPACING + SPACING;
    let mut children = Vec::new();
    for i in 0..agents {
        let (bx, by) = (5.0 + (10.0 * SPACING + SPACING) * (i % 7) as f64, 5.0 + rows * (i / 7) as f64);
        children.push(spawn_self(&[
            "agent".into(),
            "wheelchair".into(),
            "--session".into(),
            session.clone(),
            "--robots".into(),
            robots_per_agent.to_string(),
            "--pose".into(),
            format!("{bx},{by},0"),
            "--spacing".into(),
            SPACING.to_string(),
            "--powers".into(),
            "0.3,0.28".into(),
            "--connect-timeout".into(),
            "30".into(),
        ])?);
    }
    let out = finish(hub, "hub")?;
    for c in children {
        finish(c, "agent")?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    let field = |k: &str| -> Option<f64> {
        let key = format!("\"{k}\":");
        let rest = &out[out.find(&key)? + key.len()..];
        rest[..rest.find([',', '}'])?].parse().ok()
    };
    let run_s = field("run_s").context("hub printed no run time")?;
    let ticks_done = field("ticks").context("hub printed no tick count")? as u64;
    Ok(LockstepBench { agents, robots_per_agent, ticks: ticks_done, ticks_per_s: ticks_done as f64 / run_s.max(1e-9) })
}

/// `iwsim bench lockstep`.
pub fn lockstep(args: &BenchLockstepArgs) -> anyhow::Result<ExitCode> {
    let b = measure_lockstep(args.agents, args.robots_per_agent, args.ticks)?;
    if args.json {
        println!(
            "{{\"agents\":{},\"robots_per_agent\":{},\"ticks\":{},\"ticks_per_s\":{:.1}}}",
            b.agents, b.robots_per_agent, b.ticks, b.ticks_per_s
        );
    } else {
        println!(
            "lockstep: {} agent processes x {} robots, physics and sensors on\n  {:.1} ticks/s over {} ticks",
            b.agents, b.robots_per_agent, b.ticks_per_s, b.ticks
        );
    }
    Ok(ExitCode::SUCCESS)
}
