//! `iwsim bench`: the benchmarks that need processes or the whole simulator — world
//! throughput on tiled LIACC floors, hub latency against a raw iceoryx2 ping-pong measured in
//! the same run, lock-step rates over shared memory and over the UDP/XML bridge, and the
//! viewer's cost. Each prints figures (or one JSON object with `--json`).
//!
//! The benchmark world ([`tiled`]) lives here, not in the production libraries.
#![warn(missing_docs)]

pub mod args;
pub mod browser;
mod crew;
pub mod load;
pub mod repeat;
pub mod ros2;
pub mod serial;
pub mod tiled;
pub mod traffic;
pub mod viewer;

pub use args::BenchCommand;

/// Runs one `iwsim bench` subcommand.
pub fn run(command: &BenchCommand) -> anyhow::Result<std::process::ExitCode> {
    match command {
        BenchCommand::World(a) => world(a),
        BenchCommand::Latency(a) => latency(a),
        BenchCommand::Lockstep(a) => lockstep(a),
        BenchCommand::Viewer(a) => viewer::run(a),
        BenchCommand::Serial(a) => serial::run(a),
        BenchCommand::Traffic(a) => traffic::run(a),
        BenchCommand::Ros2(a) => ros2::run(a),
        BenchCommand::RawPeer(a) => raw_peer(a),
        BenchCommand::UdpClient(a) => udp_client(a),
        BenchCommand::LoadAgent(a) => load::load_agent(a),
    }
}

use std::process::ExitCode;
use std::time::{Duration, Instant};

use crate::tiled::TiledWorld;

use anyhow::Context as _;
use ipc_services::{RawPingPong, Role};
use ipc_types::{PING_PAYLOAD_BYTES, Ping};

use crate::args::{BenchLatencyArgs, BenchLockstepArgs, BenchWorldArgs, RawPeerArgs, Transport, UdpClientArgs};
use crate::repeat::Spread;

/// One timed run of `iwsim bench world`.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldBench {
    /// Chairs in the world.
    pub robots: usize,
    /// Ticks timed.
    pub ticks: u64,
    /// Threads the step used.
    pub threads: usize,
    /// Ticks per second of `World::step` alone.
    pub ticks_per_s: f64,
    /// Microseconds per robot per tick.
    pub us_per_robot_tick: f64,
    /// Median time of one tick, milliseconds.
    pub p50_tick_ms: f64,
    /// The world's state hash after the timed ticks: the same for every thread count.
    pub state_hash: u64,
}

/// Builds tiled LIACC floors with `robots` chairs and drives them `warmup` ticks (on every
/// core: the warm state does not depend on it); returns the warm world and how long building
/// took, seconds.
pub fn warm_world(robots: usize, warmup: u64, seed: u64) -> anyhow::Result<(TiledWorld, f64)> {
    let t0 = Instant::now();
    let mut w = TiledWorld::build(robots, seed)?;
    let build_s = t0.elapsed().as_secs_f64();
    let threads = w.world.threads();
    w.world.set_threads(cores());
    for _ in 0..warmup {
        w.tick(0.1);
    }
    w.world.set_threads(threads);
    Ok((w, build_s))
}

/// Times `ticks` steps of `World::step` on a copy of `start` stepping with `threads`' threads
/// (the controller that makes the actions runs between ticks and is not timed).
pub fn measure_world(start: &TiledWorld, threads: &world::World, ticks: u64) -> WorldBench {
    let mut w = start.clone();
    w.world.use_threads_of(threads);
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
    let robots = w.robots.len();
    WorldBench {
        robots,
        ticks,
        threads: w.world.threads(),
        ticks_per_s: ticks as f64 / secs,
        us_per_robot_tick: secs * 1e6 / (ticks as f64 * robots.max(1) as f64),
        p50_tick_ms: per_tick.get(per_tick.len() / 2).map_or(0.0, |d| d.as_secs_f64() * 1e3),
        state_hash: w.world.state_hash(),
    }
}

/// The machine's cores.
fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

/// The thread counts `iwsim bench world` times by default: one, and one per core.
fn default_threads() -> Vec<usize> {
    if cores() > 1 { vec![1, cores()] } else { vec![1] }
}

/// `iwsim bench world`: every thread count timed `runs` times from one warm world, interleaved;
/// fails (exit 1) if two thread counts end in different states.
pub fn world(args: &BenchWorldArgs) -> anyhow::Result<ExitCode> {
    let threads: Vec<usize> = if args.threads.is_empty() {
        default_threads()
    } else {
        args.threads.iter().map(|&t| if t == 0 { cores() } else { t }).collect()
    };
    let (start, build_s) = warm_world(args.robots, args.warmup, args.seed)?;
    // One world per thread count holds its pool, so no run pays for starting threads.
    let pools: Vec<world::World> = threads
        .iter()
        .map(|&t| {
            let mut w = world::World::new(start.world.lab(), start.world.params().clone(), args.seed)?;
            w.set_parallel_min_robots(args.parallel_min_robots);
            w.set_threads(t);
            Ok(w)
        })
        .collect::<Result<_, world::WorldBuildError>>()?;
    let runs = repeat::interleaved(args.runs, threads.len(), |_, v| {
        Ok::<_, std::convert::Infallible>(measure_world(&start, &pools[v], args.ticks))
    })
    .unwrap_or_else(|e| match e {});
    let hashes: Vec<u64> = runs.iter().flat_map(|r| r.iter().map(|b| b.state_hash)).collect();
    let same = hashes.windows(2).all(|w| w[0] == w[1]);
    let spread = |r: &[WorldBench], f: fn(&WorldBench) -> f64| {
        Spread::of(&r.iter().map(f).collect::<Vec<_>>()).unwrap_or(Spread { median: 0.0, min: 0.0, max: 0.0, runs: 0 })
    };
    // One line of figures per thread count, for the JSON and the text alike.
    struct Variant {
        threads: usize,
        rate: Spread,
        us: f64,
        p50_ms: f64,
        hash: u64,
    }
    let variants: Vec<Variant> = runs
        .iter()
        .map(|r| Variant {
            threads: r[0].threads,
            rate: spread(r, |b| b.ticks_per_s),
            us: spread(r, |b| b.us_per_robot_tick).median,
            p50_ms: spread(r, |b| b.p50_tick_ms).median,
            hash: r[0].state_hash,
        })
        .collect();
    let one = variants[0].rate.median.max(1e-12);
    if args.json {
        let json: Vec<String> = variants
            .iter()
            .map(|v| {
                format!(
                    "{{\"threads\":{},\"ticks_per_s\":{{\"median\":{:.1},\"min\":{:.1},\"max\":{:.1}}},\"us_per_robot_tick\":{:.4},\"p50_tick_ms\":{:.4},\"speedup\":{:.3},\"state_hash\":\"{:016x}\"}}",
                    v.threads,
                    v.rate.median,
                    v.rate.min,
                    v.rate.max,
                    v.us,
                    v.p50_ms,
                    v.rate.median / one,
                    v.hash
                )
            })
            .collect();
        let last = variants.last().map_or(0.0, |v| v.rate.median);
        println!(
            "{{\"robots\":{},\"ticks\":{},\"warmup\":{},\"runs\":{},\"build_s\":{:.3},\"ticks_per_s\":{:.1},\"us_per_robot_tick\":{:.4},\"same_state_hash\":{},\"variants\":[{}]}}",
            args.robots,
            args.ticks,
            args.warmup,
            args.runs,
            build_s,
            last,
            1e6 / (last.max(1e-12) * args.robots.max(1) as f64),
            same,
            json.join(",")
        );
    } else {
        println!(
            "world: {} chairs on tiled LIACC floors, 8 proximity sensors each, noise on; {} ticks timed after {} untimed, {} runs each, median [min, max]; built in {:.2} s",
            args.robots, args.ticks, args.warmup, args.runs, build_s
        );
        for v in &variants {
            println!(
                "  {} thread{}: {:.1} ticks/s [{:.1}, {:.1}]  ({:.3} us per robot-tick, median tick {:.3} ms, {:.2}x one thread, {:.1}x real time at 100 ms)  state {:016x}",
                v.threads,
                if v.threads == 1 { " " } else { "s" },
                v.rate.median,
                v.rate.min,
                v.rate.max,
                v.us,
                v.p50_ms,
                v.rate.median / one,
                v.rate.median / 10.0,
                v.hash
            );
        }
        println!("  same state on every thread count: {}", if same { "yes" } else { "NO" });
    }
    if !same {
        eprintln!("iwsim bench world: thread counts ended in different states: {hashes:016x?}");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

pub use run_records::latency::Percentiles;
use run_records::outcome::HubOutcome;

fn iwsim_exe() -> anyhow::Result<std::path::PathBuf> {
    std::env::current_exe().context("finding the iwsim executable")
}

pub(crate) fn spawn_self(args: &[String]) -> anyhow::Result<std::process::Child> {
    spawn_self_in(None, args)
}

/// [`spawn_self`] in network namespace `netns` (`ip netns exec`, which execs iwsim in place).
pub(crate) fn spawn_self_in(netns: Option<&str>, args: &[String]) -> anyhow::Result<std::process::Child> {
    let mut cmd = match netns {
        Some(ns) => {
            let mut c = std::process::Command::new("ip");
            c.args(["netns", "exec", ns]).arg(iwsim_exe()?);
            c
        }
        None => std::process::Command::new(iwsim_exe()?),
    };
    cmd.args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .context("starting an iwsim process")
}

pub(crate) fn finish(child: std::process::Child, what: &str) -> anyhow::Result<String> {
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
        // Like the raw driver, the hub sleeps until the agent answers, and it tells a blocking
        // agent to sleep for its tick too (a lock-step hub with one agent on two cores would
        // otherwise have both spin): this compares the same waits.
        s("--answer-spin-us"),
        s("0"),
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
    let RawPingPong { ping, ping_event: ping_ev, pong, pong_event: pong_ev } =
        session.raw_ping_pong(&node, Role::Hub)?;
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
        let mut ping_msg = Ping { seq, t_pub_ns: 0, payload: [0; PING_PAYLOAD_BYTES] };
        ping_msg.t_pub_ns = ipc_services::monotonic_ns();
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
    let RawPingPong { ping, ping_event: ping_ev, pong, pong_event: pong_ev } =
        session.raw_ping_pong(&node, Role::Client)?;
    let subscriber = ping.subscriber_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let listener = ping_ev.listener_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let publisher = pong.publisher_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let notifier = pong_ev.notifier_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut lat = Vec::with_capacity(args.samples as usize);
    let deadline = Instant::now() + Duration::from_secs(120);
    while (lat.len() as u64) < args.samples {
        anyhow::ensure!(Instant::now() < deadline, "the raw driver stopped sending");
        if let Some(p) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            let now = ipc_services::monotonic_ns();
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
    /// Junk datagrams sent at the bridge during the run (UDP only).
    pub flood_sent: u64,
    /// Bytes the bridge wrote to stderr (UDP only).
    pub bridge_stderr_bytes: u64,
    /// Bytes of the hub's recording (0: not recorded).
    pub recorded_bytes: u64,
    /// The hub process's peak resident set size, KiB (`VmHWM`, read just before it exited;
    /// 0: not read).
    pub hub_peak_rss_kib: u64,
    /// What the agents read (real load only; zero otherwise).
    pub readings: load::Readings,
    /// One tick's round trip as the hub timed it: from its publication to the last answer
    /// (through the bridge from remote agents), percentiles over the run's ticks.
    pub round_trip: Option<run_records::latency::Percentiles>,
}

/// A hub in lock-step with `agents` agent processes of `robots_per_agent` robots each, physics
/// and sensors on; ticks per second from the first step to the last, and the hub's peak
/// memory.
///
/// IPC only (`plan.real` false): on an open lab of at least 400 m, robots stand in lattices
/// 5 m apart (one per 25 m², about three times the density of the LIACC floor in `bench
/// world`) with the four default sensors, driving slow arcs on constant powers that their
/// agents send without reading their sensors. With the real load, robots stand on one lattice
/// 2 m apart with eight sensors each ([`load`]), and every agent reads every sensor block and
/// steers. Over UDP, each agent is a Ciber-Rato-style client process (one socket per robot,
/// one `<Actions>` per `<Measures>`; with the real load it parses every Measures) talking to
/// `iwsim udp`. With `plan.flood` > 0 (UDP only), a thread sends that many junk datagrams at
/// the bridge while the run goes on.
pub fn measure_lockstep(
    agents: usize,
    robots_per_agent: usize,
    ticks: u64,
    plan: VariantPlan,
    away: Option<&Away>,
) -> anyhow::Result<LockstepBench> {
    let VariantPlan { udp, zenoh, flood, record, real, .. } = plan;
    // Repeated runs in one invocation each get a session and folder of their own, so nothing a
    // run leaves behind can be mistaken for the next run's.
    static RUN: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let run = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tag = format!("{}{}-{}-{}-{}-{run}", udp as u8, zenoh as u8, (flood > 0) as u8, record as u8, real as u8);
    let dir = std::env::temp_dir().join(format!("iwsim-bench-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let lab = dir.join("lab.xml");
    let lab_xml = if real {
        load::Lattice::new(agents * robots_per_agent).lab_xml()
    } else {
        // 400 m square, or taller when the agents' lattices need it (1,000 robots in one agent
        // are 100 rows of ten, 500 m).
        let height =
            400f64.max(ipc_origin(agents.saturating_sub(1), robots_per_agent).1 + ipc_block_height(robots_per_agent));
        format!(
            "<Lab Name=\"bench\" Width=\"400\" Height=\"{height}\">\n  <Wall Height=\"2\"><Corner X=\"200\" Y=\"0\"/><Corner X=\"201\" Y=\"0\"/><Corner X=\"201\" Y=\"150\"/><Corner X=\"200\" Y=\"150\"/></Wall>\n</Lab>\n"
        )
    };
    std::fs::write(&lab, lab_xml)?;
    let session = format!("bench-ls-{}-{tag}", std::process::id());
    let recording = record.then(|| dir.join("run.mcap"));
    let run = run_lockstep(&session, &lab, (agents, robots_per_agent, ticks), plan, recording.as_deref(), away);
    let _ = std::fs::remove_dir_all(&dir);
    // A run that failed stopped its hub, perhaps before the hub could clean up (a helper that
    // fails at once stops it while it starts): remove what a dead hub left of the session.
    if let Ok(s) = ipc_services::Session::new(&session) {
        s.release_if_unused();
    }
    let (out, flood_sent, bridge_stderr_bytes) = run?;
    let hub_out = HubOutcome::from_stdout(&out.hub).context("reading how the hub's run ended")?;
    let ticks_per_s = hub_out.ticks as f64 / hub_out.run_s.max(1e-9);
    let readings = load::Readings::sum_of(&out.helpers);
    if real {
        // A loaded run whose agents read nothing did not carry the load it reports.
        anyhow::ensure!(readings.ticks > 0 && readings.total > 0, "the loaded agents reported no readings");
    }
    Ok(LockstepBench {
        agents,
        robots_per_agent,
        ticks: hub_out.ticks,
        ticks_per_s,
        flood_sent,
        bridge_stderr_bytes,
        recorded_bytes: hub_out.recorded_bytes,
        hub_peak_rss_kib: out.hub_peak_rss_kib,
        readings,
        round_trip: hub_out.answer_wait,
    })
}

/// Another host for the bridges' clients: a network namespace, and this host's address on the
/// link to it (`bench lockstep --netns NS --netns-address ADDRESS`).
#[derive(Debug, Clone)]
pub struct Away {
    /// The namespace the UDP clients and the Zenoh agents run in.
    pub netns: String,
    /// Where they reach the bridges.
    pub address: std::net::IpAddr,
}

/// Robots of the IPC-only lattices stand this far apart, ten to a row.
const IPC_SPACING: f64 = 5.0;

/// The depth of one agent's IPC-only lattice, metres, with a gap to the next.
fn ipc_block_height(robots_per_agent: usize) -> f64 {
    robots_per_agent.div_ceil(10).max(1) as f64 * IPC_SPACING + IPC_SPACING
}

/// Where agent `i`'s IPC-only lattice starts: seven lattices to a row.
fn ipc_origin(i: usize, robots_per_agent: usize) -> (f64, f64) {
    (
        5.0 + (10.0 * IPC_SPACING + IPC_SPACING) * (i % 7) as f64,
        5.0 + ipc_block_height(robots_per_agent) * (i / 7) as f64,
    )
}

/// One lock-step run in `session` on `lab`: what the crew printed (and the hub's memory), the
/// junk datagrams sent and the bytes the bridge wrote to stderr.
fn run_lockstep(
    session: &str,
    lab: &std::path::Path,
    (agents, robots_per_agent, ticks): (usize, usize, u64),
    plan: VariantPlan,
    record: Option<&std::path::Path>,
    away: Option<&Away>,
) -> anyhow::Result<(crew::CrewOutput, u64, u64)> {
    let VariantPlan { udp, zenoh, flood, real, .. } = plan;
    // Where the bridges' clients run, and the address the bridges serve them on.
    let there = away.map(|a| a.netns.as_str());
    let bridge_ip = away.map_or(std::net::IpAddr::from([127, 0, 0, 1]), |a| a.address);
    // Over a bridge (UDP or Zenoh) the bridge is the hub's one agent, whatever the number of
    // clients.
    let hub_agents = if udp || zenoh { 1 } else { agents };
    let mut hub_args = vec![
        "hub".into(),
        "--session".into(),
        session.to_owned(),
        "--lab".into(),
        lab.display().to_string(),
        "--lockstep".into(),
        "--ticks".into(),
        ticks.to_string(),
        "--wait-agents".into(),
        hub_agents.to_string(),
        "--json".into(),
    ];
    if let Some(path) = record {
        hub_args.extend(["--record".into(), path.display().to_string()]);
    }
    let crew = crew::Crew::new(spawn_self(&hub_args)?);
    let shape = (agents, robots_per_agent);
    let (crew, Helpers { flooder, stderr_bytes, client_outputs, agent_errs }) = if udp {
        start_udp_clients(crew, session, (bridge_ip, there), shape, real, flood)?
    } else {
        start_agents(crew, session, (bridge_ip, there), shape, real, zenoh)?
    };
    let mut out = crew.finish()?;
    // The UDP clients' stdout was taken to read their registration: the rest of it (their
    // report) is read here, now that they have exited; and the rest of the agents' stderr.
    for mut client in client_outputs {
        let _ = std::io::Read::read_to_string(&mut client, &mut out.helpers);
    }
    for mut err in agent_errs {
        let _ = std::io::copy(&mut err, &mut std::io::sink());
    }
    let flood_sent = flooder.map_or(0, Flood::stop);
    // The bridge has exited: its stderr is closed and the counting thread ends.
    let bridge_stderr_bytes = stderr_bytes.map_or(0, |h| h.join().unwrap_or(0));
    Ok((out, flood_sent, bridge_stderr_bytes))
}

/// What a lock-step bench run started besides the hub, to read or stop once it ends.
#[derive(Default)]
struct Helpers {
    flooder: Option<Flood>,
    /// The bridge's stderr, counted by a thread until it closes.
    stderr_bytes: Option<std::thread::JoinHandle<u64>>,
    /// The UDP clients' stdout, read past their registration line.
    client_outputs: Vec<std::io::BufReader<std::process::ChildStdout>>,
    /// The agents' stderr, read past their registration.
    agent_errs: Vec<std::io::BufReader<std::process::ChildStderr>>,
}

/// The UDP bridge on `bridge_ip` and `agents` Ciber-Rato-like clients of `robots_per_agent`
/// robots each (in network namespace `there`, if given), each once the last registered; then
/// the flood, if asked for. The crew comes back with them in it (or, on a failure, is ended).
fn start_udp_clients(
    mut crew: crew::Crew,
    session: &str,
    (bridge_ip, there): (std::net::IpAddr, Option<&str>),
    (agents, robots_per_agent): (usize, usize),
    real: bool,
    flood: u64,
) -> anyhow::Result<(crew::Crew, Helpers)> {
    let mut started = Helpers::default();
    let origin = |i: usize| ipc_origin(i, robots_per_agent);
    let total = (agents * robots_per_agent).to_string();
    let mut bridge = spawn_self(&[
        "udp".into(),
        "--session".into(),
        session.to_owned(),
        "--port".into(),
        "0".into(),
        "--bind".into(),
        bridge_ip.to_string(),
        "--connect-timeout".into(),
        "30".into(),
        // The hub starts when the bridge is ready: with every client's robots in, so
        // that every tick measured carries all of them.
        "--wait-robots".into(),
        total.clone(),
    ])?;
    let announced = bridge_address(&mut bridge);
    crew.push(bridge, "bridge");
    let (server, bytes) = announced?;
    started.stderr_bytes = Some(bytes);
    let mut registered = Vec::new();
    for i in 0..agents {
        let (bx, by) = origin(i);
        let mut client_args = vec![
            "bench".into(),
            "udp-client".into(),
            "--server".into(),
            server.to_string(),
            "--robots".into(),
            robots_per_agent.to_string(),
            "--pose".into(),
            format!("{bx},{by}"),
        ];
        if real {
            client_args.extend([
                "--real".into(),
                "--first".into(),
                (i * robots_per_agent).to_string(),
                "--total".into(),
                total.clone(),
            ]);
        }
        let mut client = spawn_self_in(there, &client_args)?;
        registered.push(std::io::BufReader::new(client.stdout.take().context("a UDP client's stdout")?));
        crew.push(client, "UDP client");
    }
    // The bridge is helper 0, the clients follow.
    // The flood starts once every robot is in: a registration lost in it would leave the
    // hub waiting for ever, and what is measured is the run under the flood.
    for (i, out) in registered.iter_mut().enumerate() {
        let mut line = String::new();
        let _ = std::io::BufRead::read_line(out, &mut line);
        if !line.starts_with(UDP_CLIENT_REGISTERED) {
            return Err(crew.helper_failed(1 + i, "a UDP client ended before registering its robots"));
        }
    }
    started.client_outputs = registered;
    if flood > 0 {
        started.flooder = Some(start_flood(server, flood)?);
    }
    Ok((crew, started))
}

/// `agents` shared-memory agents of `robots_per_agent` robots each, or through a Zenoh bridge
/// on `bridge_ip` (the agents in network namespace `there`, if given), joining in waves.
fn start_agents(
    mut crew: crew::Crew,
    session: &str,
    (bridge_ip, there): (std::net::IpAddr, Option<&str>),
    (agents, robots_per_agent): (usize, usize),
    real: bool,
    zenoh: bool,
) -> anyhow::Result<(crew::Crew, Helpers)> {
    let mut started = Helpers::default();
    let origin = |i: usize| ipc_origin(i, robots_per_agent);
    let total = (agents * robots_per_agent).to_string();
    // Through Zenoh: the bridge on a free port (loopback, or the link to the other host),
    // and every agent told to use it.
    let mut via = Vec::new();
    if zenoh {
        let port = std::net::TcpListener::bind((bridge_ip, 0))?.local_addr()?.port();
        let endpoint = format!("tcp/{bridge_ip}:{port}");
        let mut bridge = spawn_self(&[
            "zenoh".into(),
            "--session".into(),
            session.to_owned(),
            "--listen".into(),
            endpoint.clone(),
            "--connect-timeout".into(),
            "30".into(),
            // Every agent in before the first tick: the ticks counted are the same for all.
            "--wait-agents".into(),
            agents.to_string(),
        ])?;
        // Keep draining its stderr, so the bridge never blocks on a full pipe.
        let mut err = bridge.stderr.take().context("the Zenoh bridge's stderr")?;
        started.stderr_bytes =
            Some(std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()).unwrap_or(0)));
        crew.push(bridge, "Zenoh bridge");
        via = vec!["--zenoh".to_owned(), endpoint];
    }
    // Agents join in waves, each wave once the last has registered: a hub that met a
    // hundred hellos at once would make them in one pass of its loop, and the first agents
    // would wait longer than their 5 s for the map it hands out between passes. Only the
    // start is staggered; the ticks are timed once every agent is in.
    for wave in (0..agents).collect::<Vec<_>>().chunks(AGENT_WAVE) {
        let first_helper = crew.len();
        let mut announced = Vec::new();
        for &i in wave {
            let args: Vec<String> = if real {
                [
                    "bench",
                    "load-agent",
                    "--session",
                    session,
                    "--robots",
                    &robots_per_agent.to_string(),
                    "--first",
                    &(i * robots_per_agent).to_string(),
                    "--total",
                    &total,
                ]
                .map(str::to_owned)
                .into()
            } else {
                let (bx, by) = origin(i);
                [
                    "agent",
                    "wheelchair",
                    "--session",
                    session,
                    "--robots",
                    &robots_per_agent.to_string(),
                    "--pose",
                    &format!("{bx},{by},0"),
                    "--spacing",
                    &IPC_SPACING.to_string(),
                    "--powers",
                    "0.3,0.28",
                    "--connect-timeout",
                    "30",
                ]
                .map(str::to_owned)
                .into()
            };
            let mut args = args;
            args.extend(via.iter().cloned());
            let mut agent = spawn_self_in(if zenoh { there } else { None }, &args)?;
            announced.push(std::io::BufReader::new(agent.stderr.take().context("an agent's stderr")?));
            crew.push(agent, "agent");
        }
        for (k, err) in announced.iter_mut().enumerate() {
            if !registered(err) {
                return Err(crew.helper_failed(first_helper + k, "an agent ended before registering its robots"));
            }
        }
        started.agent_errs.extend(announced);
    }
    Ok((crew, started))
}

/// Shared-memory agents that join the hub at once (see `run_lockstep`).
const AGENT_WAVE: usize = 10;

/// Reads an agent's stderr up to the line saying its robots are registered ("… drives robots
/// …", from the wheelchair and the load agent alike); false when it ends first.
fn registered(stderr: &mut impl std::io::BufRead) -> bool {
    let mut line = String::new();
    loop {
        line.clear();
        match stderr.read_line(&mut line) {
            Ok(n) if n > 0 => {
                if line.contains(" drives robots ") {
                    return true;
                }
            }
            _ => return false,
        }
    }
}

/// What the UDP bench client prints on stdout once all its robots are registered.
const UDP_CLIENT_REGISTERED: &str = "registered";

/// A thread sending junk datagrams at a bridge until it has sent its count or is stopped
/// (at the latest when dropped, as when a run fails).
struct Flood {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<u64>>,
}

impl Flood {
    /// Stops the flood; the datagrams it sent.
    fn stop(mut self) -> u64 {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.take().map_or(0, |t| t.join().unwrap_or(0))
    }
}

impl Drop for Flood {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Registers a panel at `server` (so the bridge opens a client port), then sends `count`
/// junk datagrams as fast as the socket takes them: half malformed registrations to the
/// registration port, half to the panel's port from another socket (foreign datagrams).
fn start_flood(server: std::net::SocketAddr, count: u64) -> anyhow::Result<Flood> {
    use std::net::UdpSocket;
    let panel = UdpSocket::bind("127.0.0.1:0").context("bind the flood's panel socket")?;
    panel.set_read_timeout(Some(Duration::from_secs(10)))?;
    panel.send_to(b"<Panel/>", server)?;
    let mut buf = [0u8; 4096];
    let (_, client_port) = panel.recv_from(&mut buf).context("the bridge did not answer the flood's panel")?;
    let junk = UdpSocket::bind("127.0.0.1:0").context("bind the flood socket")?;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stopped = stop.clone();
    let thread = std::thread::spawn(move || {
        let _panel = panel;
        let mut sent = 0u64;
        while sent < count && !stopped.load(std::sync::atomic::Ordering::Relaxed) {
            let to = if sent.is_multiple_of(2) { server } else { client_port };
            let datagram = format!("<Robot Id=\"junk{sent}\"");
            if junk.send_to(datagram.as_bytes(), to).is_ok() {
                sent += 1;
            }
        }
        sent
    });
    Ok(Flood { stop, thread: Some(thread) })
}

/// Reads the bridge's "registrations on ADDR" line from its stderr; the thread that drains
/// the rest of it returns how many bytes the bridge wrote in all.
fn bridge_address(
    bridge: &mut std::process::Child,
) -> anyhow::Result<(std::net::SocketAddr, std::thread::JoinHandle<u64>)> {
    use std::io::BufRead;
    let stderr = bridge.stderr.take().context("bridge stderr")?;
    let mut reader = std::io::BufReader::new(stderr);
    let mut bytes = 0u64;
    loop {
        let mut line = String::new();
        let n = reader.read_line(&mut line).context("reading the bridge's stderr")?;
        anyhow::ensure!(n > 0, "the bridge exited before announcing its port");
        bytes += n as u64;
        if let Some(addr) = line.split("registrations on ").nth(1) {
            let addr = addr.trim().parse().context("the bridge's address")?;
            // Keep draining stderr so the bridge never blocks on a full pipe.
            let drain =
                std::thread::spawn(move || bytes + std::io::copy(&mut reader, &mut std::io::sink()).unwrap_or(0));
            return Ok((addr, drain));
        }
    }
}

/// The UDP bench client: registers robots like a Ciber-Rato client (one socket each) and
/// answers every `<Measures>` with one `<Actions>`, until the Measures stop. IPC only, it
/// answers constant powers unread; with `--real` it registers the bench's eight-sensor chairs
/// on the lattice, parses every Measures in full and steers each robot by the reactive rule.
pub fn udp_client(args: &UdpClientArgs) -> anyhow::Result<ExitCode> {
    use std::net::UdpSocket;
    let lattice = load::Lattice::new(args.total);
    let mut socks = Vec::new();
    for k in 0..args.robots {
        // Loopback to a bridge on loopback; any address to one on another host's link.
        let local: std::net::IpAddr =
            if args.server.ip().is_loopback() { [127, 0, 0, 1].into() } else { [0, 0, 0, 0].into() };
        let s = UdpSocket::bind((local, 0)).context("bind a client socket")?;
        s.set_read_timeout(Some(Duration::from_secs(10)))?;
        let reg = if args.real {
            let g = args.first + k;
            load::chair_registration_xml(&format!("udp{g}"), lattice.pose(g))
        } else {
            let (x, y) = (args.pose[0] + 5.0 * (k % 10) as f64, args.pose[1] + 5.0 * (k / 10) as f64);
            format!("<Robot Name=\"udp{k}\" X=\"{x}\" Y=\"{y}\" Dir=\"0\"/>")
        };
        s.send_to(reg.as_bytes(), args.server)?;
        let mut buf = [0u8; 4096];
        let (n, from) = s.recv_from(&mut buf).context("no registration reply")?;
        anyhow::ensure!(
            buf[..n].starts_with(b"<Reply Status=\"Ok\""),
            "registration refused: {}",
            String::from_utf8_lossy(&buf[..n])
        );
        s.connect(from)?;
        socks.push(s);
    }
    println!("{UDP_CLIENT_REGISTERED} {} robots", socks.len());
    let mut answered = 0u64;
    let mut readings = load::Readings::default();
    let mut distances = Vec::with_capacity(ipc_types::MAX_PROXIMITY);
    let mut buf = [0u8; 4096];
    let mut over = false;
    'run: while !over {
        for s in &socks {
            // The run is over when the Measures say both Buttons are off (the bridge then
            // goes on sending them until its clients leave, as Ciber-Rato's simulator does),
            // or when they stop. The last tick's Measures are read by every robot first.
            let timeout = if answered == 0 { Duration::from_secs(30) } else { Duration::from_millis(1500) };
            s.set_read_timeout(Some(timeout))?;
            let got = s.recv(&mut buf);
            if let Ok(n) = got {
                over |= answered > 0 && run_over(&buf[..n]);
            }
            match got {
                Ok(n) if args.real => {
                    let m = udp_bridge::codec::decode_measures(&buf[..n]).context("a Measures from the bridge")?;
                    // On a tie, turn towards the side the chair already faces.
                    let actions = load::answer(&m, &mut distances, m.compass.is_none_or(|c| c >= 0.0));
                    readings.add(&distances);
                    s.send(actions.as_bytes())?;
                    answered += 1;
                }
                Ok(_) => {
                    s.send(b"<Actions LeftMotor=\"0.045\" RightMotor=\"0.042\"/>")?;
                    answered += 1;
                }
                Err(_) => break 'run,
            }
        }
        readings.ticks += 1;
    }
    eprintln!("udp client: answered {answered} Measures");
    if args.real {
        println!("{}", readings.line());
    }
    Ok(ExitCode::SUCCESS)
}

/// Whether a Measures says the run is over (Ciber-Rato's Buttons both off).
fn run_over(measures: &[u8]) -> bool {
    const OVER: &[u8] = b"<Buttons Start=\"Off\" Stop=\"Off\"/>";
    measures.windows(OVER.len()).any(|w| w == OVER)
}

/// One variant of `iwsim bench lockstep` (shared memory or UDP, IPC only or with the real
/// load, UDP under a flood, shared memory recorded) and its runs.
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepVariant {
    /// `shm`, `udp`, `udp+flood`, `shm+record`, `shm+real` or `udp+real`.
    pub name: &'static str,
    /// Every run, in the order they ran.
    pub runs: Vec<LockstepBench>,
}

impl LockstepVariant {
    /// Median, min and max ticks per second over the runs.
    pub fn ticks_per_s(&self) -> Spread {
        let rates: Vec<f64> = self.runs.iter().map(|b| b.ticks_per_s).collect();
        Spread::of(&rates).unwrap_or(Spread { median: 0.0, min: 0.0, max: 0.0, runs: 0 })
    }

    /// The fewest junk datagrams any run sent: every run had at least this flood.
    pub fn flood_sent(&self) -> u64 {
        self.runs.iter().map(|b| b.flood_sent).min().unwrap_or(0)
    }

    /// The most bytes the bridge wrote to stderr in one run: the bound a user cares about.
    pub fn bridge_stderr_bytes(&self) -> u64 {
        self.runs.iter().map(|b| b.bridge_stderr_bytes).max().unwrap_or(0)
    }

    /// The hub's peak resident set over the runs, MiB: the most any run needed.
    pub fn hub_peak_rss_mib(&self) -> f64 {
        self.runs.iter().map(|b| b.hub_peak_rss_kib).max().unwrap_or(0) as f64 / 1024.0
    }

    /// What the agents read over all runs.
    pub fn readings(&self) -> load::Readings {
        self.runs.iter().fold(load::Readings::default(), |a, b| load::Readings {
            ticks: a.ticks + b.readings.ticks,
            total: a.total + b.readings.total,
            near: a.near + b.readings.near,
        })
    }

    /// Whether the agents carried the real load.
    pub fn real(&self) -> bool {
        self.name.ends_with("+real")
    }

    /// One tick's round trip, µs: the spread over the runs of each run's median, and of each
    /// run's 99th percentile; `None` when the hub reported none.
    pub fn round_trip_us(&self) -> Option<(Spread, Spread)> {
        let p: Vec<_> = self.runs.iter().filter_map(|b| b.round_trip).collect();
        let p50: Vec<f64> = p.iter().map(|p| p.p50_us).collect();
        let p99: Vec<f64> = p.iter().map(|p| p.p99_us).collect();
        Some((Spread::of(&p50)?, Spread::of(&p99)?))
    }
}

/// A ratio of two variants: of their medians, and its spread over the rounds, each round's two
/// runs having run back to back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LockstepRatio {
    /// Median of the first variant over median of the second.
    pub of_medians: f64,
    /// The ratio round by round.
    pub by_round: Spread,
}

impl LockstepRatio {
    /// `a` against `b`.
    pub fn of(a: &LockstepVariant, b: &LockstepVariant) -> LockstepRatio {
        let per_round: Vec<f64> =
            a.runs.iter().zip(&b.runs).map(|(x, y)| x.ticks_per_s / y.ticks_per_s.max(1e-9)).collect();
        let of_medians = a.ticks_per_s().median / b.ticks_per_s().median.max(1e-9);
        let by_round =
            Spread::of(&per_round).unwrap_or(Spread { median: of_medians, min: of_medians, max: of_medians, runs: 0 });
        LockstepRatio { of_medians, by_round }
    }
}

/// How one variant of `iwsim bench lockstep` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VariantPlan {
    /// Its name in the report.
    pub name: &'static str,
    /// Agents attach through the UDP/XML bridge.
    pub udp: bool,
    /// Agents attach through the Zenoh bridge (loopback).
    pub zenoh: bool,
    /// Junk datagrams sent at the bridge during the run.
    pub flood: u64,
    /// The hub records the run.
    pub record: bool,
    /// The agents carry the real load ([`load`]).
    pub real: bool,
}

impl VariantPlan {
    const fn new(name: &'static str, udp: bool) -> Self {
        Self { name, udp, zenoh: false, flood: 0, record: false, real: false }
    }
}

const SHM: VariantPlan = VariantPlan::new("shm", false);
const UDP: VariantPlan = VariantPlan::new("udp", true);
const SHM_REAL: VariantPlan = VariantPlan { real: true, ..VariantPlan::new("shm+real", false) };
const UDP_REAL: VariantPlan = VariantPlan { real: true, ..VariantPlan::new("udp+real", true) };
const ZENOH: VariantPlan = VariantPlan { zenoh: true, ..VariantPlan::new("zenoh", false) };
const ZENOH_REAL: VariantPlan = VariantPlan { zenoh: true, real: true, ..VariantPlan::new("zenoh+real", false) };

/// The variants one invocation runs, in the order each round runs them.
fn lockstep_variants(args: &BenchLockstepArgs) -> Vec<VariantPlan> {
    let has = |t: Transport| args.transport.iter().any(|&x| x == t || x == Transport::All);
    let shm = has(Transport::Shm) || has(Transport::Both);
    let udp = has(Transport::Udp) || has(Transport::Both);
    let zenoh = has(Transport::Zenoh);
    let mut v = Vec::new();
    if args.load.ipc() {
        // A shared-memory flood run is a UDP run: `--transport shm --flood N` compares UDP with
        // and without the flood alone, unless the recorder is asked for too.
        if shm && (args.flood == 0 || args.record) {
            v.push(SHM);
        }
        if udp {
            v.push(UDP);
        }
        if zenoh {
            v.push(ZENOH);
        }
    }
    if args.flood > 0 {
        // The flood is at the bridge: compare UDP runs with and without it, in one invocation.
        if !v.contains(&UDP) {
            v.push(UDP);
        }
        v.push(VariantPlan { flood: args.flood, ..VariantPlan::new("udp+flood", true) });
    }
    if args.record {
        // The recorder's cost: the same shared-memory run with the hub recording.
        if !v.contains(&SHM) {
            v.push(SHM);
        }
        v.push(VariantPlan { record: true, ..VariantPlan::new("shm+record", false) });
    }
    if args.load.real() {
        if shm {
            v.push(SHM_REAL);
        }
        if udp {
            v.push(UDP_REAL);
        }
        if zenoh {
            v.push(ZENOH_REAL);
        }
    }
    v
}

/// Runs every variant `args.runs` times, interleaved round by round.
pub fn measure_lockstep_runs(args: &BenchLockstepArgs) -> anyhow::Result<Vec<LockstepVariant>> {
    let variants = lockstep_variants(args);
    let away = args.netns.clone().zip(args.netns_address).map(|(netns, address)| Away { netns, address });
    let runs = repeat::interleaved(args.runs, variants.len(), |round, i| {
        let plan = variants[i];
        measure_lockstep(args.agents, args.robots_per_agent, args.ticks, plan, away.as_ref())
            .with_context(|| format!("run {} of {}", round + 1, plan.name))
    })?;
    Ok(variants.iter().zip(runs).map(|(plan, runs)| LockstepVariant { name: plan.name, runs }).collect())
}

/// The ratios and figures of a lock-step bench's variants that both of its reports print.
struct LockstepFigures<'a> {
    shm_udp: Option<LockstepRatio>,
    shm_udp_real: Option<LockstepRatio>,
    zenoh_udp: Option<LockstepRatio>,
    shm_zenoh: Option<LockstepRatio>,
    zenoh_udp_real: Option<LockstepRatio>,
    real_shm: Option<LockstepRatio>,
    real_udp: Option<LockstepRatio>,
    flood: Option<&'a LockstepVariant>,
    quiet: Option<&'a LockstepVariant>,
    flood_ratio: Option<LockstepRatio>,
    record_ratio: Option<LockstepRatio>,
    bytes_per_robot_tick: Option<f64>,
    neighbours: Option<f64>,
    ticks: u64,
}

impl<'a> LockstepFigures<'a> {
    fn of(args: &BenchLockstepArgs, variants: &'a [LockstepVariant]) -> Self {
        let find = |n: &str| variants.iter().find(|v| v.name == n);
        let pair = |a: &str, b: &str| match (find(a), find(b)) {
            (Some(a), Some(b)) => Some(LockstepRatio::of(a, b)),
            _ => None,
        };
        let shm_udp = pair("shm", "udp");
        let shm_udp_real = pair("shm+real", "udp+real");
        let zenoh_udp = pair("zenoh", "udp");
        let shm_zenoh = pair("shm", "zenoh");
        let zenoh_udp_real = pair("zenoh+real", "udp+real");
        let real_shm = pair("shm+real", "shm");
        let real_udp = pair("udp+real", "udp");
        let (flood, quiet) = (find("udp+flood"), find("udp"));
        let flood_ratio = pair("udp+flood", "udp");
        let recorded = find("shm+record");
        let record_ratio = pair("shm+record", "shm");
        // The recording's size per robot per tick, from the median-sized file.
        let bytes_per_robot_tick = recorded.map(|r| {
            let mut b: Vec<u64> = r.runs.iter().map(|b| b.recorded_bytes).collect();
            b.sort_unstable();
            let robots = (args.agents * args.robots_per_agent).max(1) as f64;
            b.get(b.len() / 2).copied().unwrap_or(0) as f64
                / robots
                / r.runs.first().map_or(1, |b| b.ticks.max(1)) as f64
        });
        let neighbours = variants.iter().any(LockstepVariant::real).then(|| {
            load::Lattice::new(args.agents * args.robots_per_agent).mean_neighbours_within(load::sensor_range_m())
        });
        let ticks = variants.first().and_then(|v| v.runs.first()).map_or(0, |b| b.ticks);
        Self {
            shm_udp,
            shm_udp_real,
            zenoh_udp,
            shm_zenoh,
            zenoh_udp_real,
            real_shm,
            real_udp,
            flood,
            quiet,
            flood_ratio,
            record_ratio,
            bytes_per_robot_tick,
            neighbours,
            ticks,
        }
    }
}

/// What `iwsim bench lockstep` prints for `variants` (text, or one JSON object with `--json`).
pub fn lockstep_report(args: &BenchLockstepArgs, variants: &[LockstepVariant]) -> String {
    let f = LockstepFigures::of(args, variants);
    if args.json { lockstep_json(args, variants, &f) } else { lockstep_text(args, variants, &f) }
}

/// [`lockstep_report`] as one JSON object.
fn lockstep_json(args: &BenchLockstepArgs, variants: &[LockstepVariant], f: &LockstepFigures) -> String {
    let ticks = f.ticks;
    let mut s = String::new();
    s += &format!(
        "{{\"agents\":{},\"robots_per_agent\":{},\"ticks\":{ticks},\"runs\":{}",
        args.agents, args.robots_per_agent, args.runs
    );
    if let (Some(ns), Some(a)) = (&args.netns, args.netns_address) {
        s += &format!(",\"netns\":{ns:?},\"netns_address\":\"{a}\"");
    }
    for v in variants {
        let t = v.ticks_per_s();
        // One variant keeps the old `transport` and `ticks_per_s` keys; several are named.
        let (key, prefix) = if variants.len() == 1 {
            s += &format!(",\"transport\":\"{}\"", v.name);
            ("ticks_per_s".to_owned(), String::new())
        } else {
            let name = v.name.replace('+', "_");
            (format!("{name}_ticks_per_s"), format!("{name}_"))
        };
        s += &format!(",\"{key}\":{:.1},\"{key}_min\":{:.1},\"{key}_max\":{:.1}", t.median, t.min, t.max);
        if v.hub_peak_rss_mib() > 0.0 {
            s += &format!(",\"{prefix}hub_peak_rss_mib\":{:.1}", v.hub_peak_rss_mib());
        }
        if let Some((p50, p99)) = v.round_trip_us() {
            s += &format!(
                ",\"{prefix}round_trip_p50_us\":{:.1},\"{prefix}round_trip_p99_us\":{:.1}",
                p50.median, p99.median
            );
        }
        if v.real() {
            let r = v.readings();
            s += &format!(
                ",\"{prefix}readings\":{},\"{prefix}readings_near\":{},\"{prefix}readings_near_fraction\":{:.3}",
                r.total,
                r.near,
                r.near_fraction()
            );
        }
    }
    if let Some(n) = f.neighbours {
        s += &format!(",\"real_neighbours_in_range\":{n:.2},\"real_near_m\":{}", load::NEAR_M);
    }
    let ratio = |s: &mut String, key: &str, r: &LockstepRatio| {
        *s += &format!(
            ",\"{key}\":{:.2},\"{key}_min\":{:.2},\"{key}_max\":{:.2}",
            r.of_medians, r.by_round.min, r.by_round.max
        );
    };
    for (key, r) in [
        ("ratio_shm_over_udp", &f.shm_udp),
        ("ratio_shm_real_over_udp_real", &f.shm_udp_real),
        ("ratio_shm_real_over_shm", &f.real_shm),
        ("ratio_udp_real_over_udp", &f.real_udp),
        ("ratio_zenoh_over_udp", &f.zenoh_udp),
        ("ratio_shm_over_zenoh", &f.shm_zenoh),
        ("ratio_zenoh_real_over_udp_real", &f.zenoh_udp_real),
    ] {
        if let Some(r) = r {
            ratio(&mut s, key, r);
        }
    }
    if let (Some(f), Some(r), Some(q)) = (f.flood, &f.flood_ratio, f.quiet) {
        s += &format!(",\"flood_sent\":{}", f.flood_sent());
        ratio(&mut s, "ratio_flood_over_udp", r);
        s += &format!(
            ",\"udp_stderr_bytes\":{},\"flood_stderr_bytes\":{}",
            q.bridge_stderr_bytes(),
            f.bridge_stderr_bytes()
        );
    }
    if let (Some(r), Some(bytes)) = (&f.record_ratio, f.bytes_per_robot_tick) {
        ratio(&mut s, "ratio_record_over_shm", r);
        s += &format!(",\"recorded_bytes_per_robot_tick\":{bytes:.0}");
    }
    s += "}\n";
    s
}

/// [`lockstep_report`] as text.
fn lockstep_text(args: &BenchLockstepArgs, variants: &[LockstepVariant], f: &LockstepFigures) -> String {
    let ticks = f.ticks;
    let mut s = String::new();
    if let (Some(ns), Some(a)) = (&args.netns, args.netns_address) {
        s += &format!("the bridges' clients in network namespace {ns}, reaching them at {a}\n");
    }
    for v in variants {
        let t = v.ticks_per_s();
        let rate = if t.runs > 1 {
            format!("{:.1} ticks/s (median of {} runs, min {:.1}, max {:.1})", t.median, t.runs, t.min, t.max)
        } else {
            format!("{:.1} ticks/s", t.median)
        };
        let flooded =
            if v.flood_sent() > 0 { format!(", {} junk datagrams sent", v.flood_sent()) } else { String::new() };
        let stderr = match (args.flood > 0 && v.name.starts_with("udp"), t.runs > 1) {
            (true, true) => format!("; bridge stderr {} bytes (most in one run)", v.bridge_stderr_bytes()),
            (true, false) => format!("; bridge stderr {} bytes", v.bridge_stderr_bytes()),
            _ => String::new(),
        };
        let rss = if v.hub_peak_rss_mib() > 0.0 {
            format!("; hub peak RSS {:.1} MiB", v.hub_peak_rss_mib())
        } else {
            String::new()
        };
        let (transport, what) = match v.name.split_once('+') {
            Some((transport, "real")) => (transport, "real load: every sensor read, reactive steering"),
            _ => (v.name, "IPC only, physics and sensors on"),
        };
        let near = if v.real() {
            let r = v.readings();
            format!("; {:.0}% of {} readings under {} m", 100.0 * r.near_fraction(), r.total, load::NEAR_M)
        } else {
            String::new()
        };
        let trip = match v.round_trip_us() {
            Some((p50, p99)) if t.runs > 1 => format!(
                "; a tick's round trip p50 {:.0} us ({:.0}-{:.0}), p99 {:.0} us ({:.0}-{:.0})",
                p50.median, p50.min, p50.max, p99.median, p99.min, p99.max
            ),
            Some((p50, p99)) => format!("; a tick's round trip p50 {:.0} us, p99 {:.0} us", p50.median, p99.median),
            None => String::new(),
        };
        s += &format!(
            "lockstep over {transport}: {} agents x {} robots, {what}: {rate} over {ticks} ticks{trip}{flooded}{stderr}{near}{rss}\n",
            args.agents, args.robots_per_agent
        );
    }
    let ratio = |r: &LockstepRatio| {
        if r.by_round.runs > 1 {
            format!(
                "{:.2}x (of the medians; {:.2}x to {:.2}x run by run)",
                r.of_medians, r.by_round.min, r.by_round.max
            )
        } else {
            format!("{:.2}x", r.of_medians)
        }
    };
    if let Some(r) = &f.shm_udp {
        s += &format!("  shared memory / UDP: {}\n", ratio(r));
    }
    if let Some(r) = &f.shm_udp_real {
        s += &format!("  shared memory / UDP, real load: {}\n", ratio(r));
    }
    if let Some(r) = &f.zenoh_udp {
        s += &format!("  Zenoh / UDP: {}\n", ratio(r));
    }
    if let Some(r) = &f.shm_zenoh {
        s += &format!("  shared memory / Zenoh: {}\n", ratio(r));
    }
    if let Some(r) = &f.zenoh_udp_real {
        s += &format!("  Zenoh / UDP, real load: {}\n", ratio(r));
    }
    if let Some(r) = &f.real_shm {
        s += &format!("  real load / IPC only, shared memory: {}\n", ratio(r));
    }
    if let Some(r) = &f.real_udp {
        s += &format!("  real load / IPC only, UDP: {}\n", ratio(r));
    }
    if let Some(r) = &f.flood_ratio {
        s += &format!("  UDP with the flood / without: {}\n", ratio(r));
    }
    if let (Some(r), Some(bytes)) = (&f.record_ratio, f.bytes_per_robot_tick) {
        s += &format!("  recording / not: {} ticks/s; {bytes:.0} bytes per robot per tick recorded\n", ratio(r));
    }
    if let Some(n) = f.neighbours {
        s += &format!(
            "  IPC only: robots {IPC_SPACING} m apart, 4 sensors each, agents send constant powers unread. Real load: robots {} m apart, 8 sensors each, {n:.1} neighbours within {} m on average at the start; agents read every sensor block (UDP clients parse every Measures) and steer each robot by a reactive rule\n",
            load::SPACING_M,
            load::sensor_range_m()
        );
    }
    s
}

/// `iwsim bench lockstep`.
pub fn lockstep(args: &BenchLockstepArgs) -> anyhow::Result<ExitCode> {
    let variants = measure_lockstep_runs(args)?;
    print!("{}", lockstep_report(args, &variants));
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(subcommand)]
        command: BenchCommand,
    }

    fn lockstep_args(line: &[&str]) -> Result<BenchLockstepArgs, clap::Error> {
        let argv = ["bench", "lockstep"].iter().chain(line);
        match Cli::try_parse_from(argv)?.command {
            BenchCommand::Lockstep(a) => Ok(a),
            other => panic!("parsed as {other:?}"),
        }
    }

    fn run(ticks_per_s: f64, flood_sent: u64, bridge_stderr_bytes: u64) -> LockstepBench {
        LockstepBench {
            agents: 1,
            robots_per_agent: 10,
            ticks: 2000,
            ticks_per_s,
            flood_sent,
            bridge_stderr_bytes,
            recorded_bytes: 0,
            hub_peak_rss_kib: 0,
            readings: load::Readings::default(),
            round_trip: None,
        }
    }

    /// A flood invocation's three rounds: udp, then udp+flood, in each.
    fn flood_variants() -> Vec<LockstepVariant> {
        vec![
            LockstepVariant { name: "udp", runs: vec![run(4000.0, 0, 90), run(3000.0, 0, 95), run(3800.0, 0, 90)] },
            LockstepVariant {
                name: "udp+flood",
                runs: vec![run(2000.0, 100_000, 603), run(2400.0, 99_000, 700), run(1900.0, 100_000, 603)],
            },
        ]
    }

    #[test]
    fn lockstep_runs_five_times_unless_told() {
        assert_eq!(lockstep_args(&[]).expect("parses").runs, 5);
        assert_eq!(lockstep_args(&["--runs", "1"]).expect("parses").runs, 1);
    }

    #[test]
    fn lockstep_refuses_zero_runs_naming_the_option() {
        let err = lockstep_args(&["--runs", "0"]).expect_err("0 runs is refused").to_string();
        let first = err.lines().next().expect("a line");
        assert!(first.contains("--runs"), "{err}");
    }

    #[test]
    fn a_flood_invocation_runs_udp_quiet_and_flooded() {
        let names = |line: &[&str]| -> Vec<&'static str> {
            lockstep_variants(&lockstep_args(line).expect("parses")).iter().map(|v| v.name).collect()
        };
        let a = lockstep_args(&["--transport", "udp", "--flood", "10", "--load", "ipc"]).expect("parses");
        let flooded = VariantPlan { flood: 10, ..VariantPlan::new("udp+flood", true) };
        assert_eq!(lockstep_variants(&a), vec![UDP, flooded]);
        assert_eq!(names(&["--transport", "both", "--load", "ipc"]), ["shm", "udp"]);
        assert_eq!(names(&["--transport", "all", "--load", "ipc"]), ["shm", "udp", "zenoh"]);
        assert_eq!(names(&["--transport", "zenoh,udp", "--load", "real"]), ["udp+real", "zenoh+real"]);
        // The flood is an IPC-only comparison; the real load adds its own variant.
        assert_eq!(names(&["--transport", "udp", "--flood", "10"]), ["udp", "udp+flood", "udp+real"]);
    }

    #[test]
    fn one_invocation_runs_ipc_only_and_the_real_load_unless_told() {
        let names = |line: &[&str]| -> Vec<&'static str> {
            lockstep_variants(&lockstep_args(line).expect("parses")).iter().map(|v| v.name).collect()
        };
        assert_eq!(names(&[]), ["shm", "shm+real"]);
        assert_eq!(names(&["--transport", "both"]), ["shm", "udp", "shm+real", "udp+real"]);
        assert_eq!(names(&["--transport", "udp", "--load", "real"]), ["udp+real"]);
        let plans = lockstep_variants(&lockstep_args(&["--transport", "both"]).expect("parses"));
        assert_eq!(
            plans.iter().map(|v| (v.udp, v.real)).collect::<Vec<_>>(),
            [(false, false), (true, false), (false, true), (true, true)]
        );
    }

    #[test]
    fn the_report_labels_ipc_only_and_real_load_lines_with_the_hub_memory() {
        let loaded = |ticks_per_s: f64, near: u64| LockstepBench {
            hub_peak_rss_kib: 20 * 1024,
            readings: load::Readings { ticks: 10, total: 8000, near },
            ..run(ticks_per_s, 0, 0)
        };
        let ipc = LockstepBench { hub_peak_rss_kib: 18 * 1024, ..run(8000.0, 0, 0) };
        let v = [
            LockstepVariant { name: "shm", runs: vec![ipc] },
            LockstepVariant { name: "shm+real", runs: vec![loaded(6000.0, 6000)] },
        ];
        let a = lockstep_args(&["--runs", "1"]).expect("parses");
        let out = lockstep_report(&a, &v);
        let lines: Vec<&str> = out.lines().collect();
        assert!(
            lines[0].contains("over shm: 1 agents x 100 robots, IPC only") && lines[0].contains("18.0 MiB"),
            "{out}"
        );
        assert!(
            lines[1].contains("over shm: 1 agents x 100 robots, real load")
                && lines[1].contains("75% of 8000 readings under 2.5 m")
                && lines[1].ends_with("hub peak RSS 20.0 MiB"),
            "{out}"
        );
        assert!(out.contains("real load / IPC only, shared memory: 0.75x"), "{out}");
        let a = lockstep_args(&["--runs", "1", "--json"]).expect("parses");
        let j: serde_json::Value = serde_json::from_str(&lockstep_report(&a, &v)).expect("one JSON object");
        assert_eq!(j["shm_hub_peak_rss_mib"], 18.0);
        assert_eq!(j["shm_real_hub_peak_rss_mib"], 20.0);
        assert_eq!(j["shm_real_readings_near_fraction"], 0.75);
        assert_eq!(j["ratio_shm_real_over_shm"], 0.75);
        assert_eq!(j["real_neighbours_in_range"], 6.84);
    }

    #[test]
    fn the_report_gives_a_ticks_round_trip_and_where_the_clients_ran() {
        let trip = |p50: f64, p99: f64| LockstepBench {
            round_trip: Some(run_records::latency::Percentiles {
                samples: 1000,
                p50_us: p50,
                p99_us: p99,
                p999_us: p99,
            }),
            ..run(2000.0, 0, 0)
        };
        let v =
            [LockstepVariant { name: "zenoh", runs: vec![trip(300.0, 900.0), trip(250.0, 700.0), trip(400.0, 800.0)] }];
        let a =
            lockstep_args(&["--transport", "zenoh", "--netns", "far", "--netns-address", "10.0.0.1"]).expect("parses");
        let out = lockstep_report(&a, &v);
        assert!(out.starts_with("the bridges' clients in network namespace far, reaching them at 10.0.0.1\n"), "{out}");
        assert!(out.contains("a tick's round trip p50 300 us (250-400), p99 800 us (700-900)"), "{out}");
        let a = lockstep_args(&["--transport", "zenoh", "--json"]).expect("parses");
        let j: serde_json::Value = serde_json::from_str(&lockstep_report(&a, &v)).expect("one JSON object");
        assert_eq!((j["round_trip_p50_us"].as_f64(), j["round_trip_p99_us"].as_f64()), (Some(300.0), Some(800.0)));
        // A namespace needs the address the bridges serve it on.
        assert!(lockstep_args(&["--netns", "far"]).is_err());
    }

    #[test]
    fn a_record_invocation_runs_shared_memory_with_and_without_the_recorder() {
        let a = lockstep_args(&["--record", "--load", "ipc"]).expect("parses");
        let recorded_plan = VariantPlan { record: true, ..VariantPlan::new("shm+record", false) };
        assert_eq!(lockstep_variants(&a), vec![SHM, recorded_plan]);
        let mut quiet = run(1000.0, 0, 0);
        let mut recorded = run(900.0, 0, 0);
        (quiet.robots_per_agent, recorded.robots_per_agent) = (100, 100);
        recorded.recorded_bytes = 2000 * 100 * 700;
        let variants = [
            LockstepVariant { name: "shm", runs: vec![quiet] },
            LockstepVariant { name: "shm+record", runs: vec![recorded] },
        ];
        let a = lockstep_args(&["--record", "--robots-per-agent", "100", "--runs", "1"]).expect("parses");
        let out = lockstep_report(&a, &variants);
        assert!(out.contains("recording / not: 0.90x ticks/s; 700 bytes per robot per tick recorded"), "{out}");
    }

    #[test]
    fn the_json_report_keeps_the_old_keys_and_adds_medians_min_max_and_runs() {
        let a = lockstep_args(&["--transport", "udp", "--flood", "100000", "--runs", "3", "--json"]).expect("parses");
        let out = lockstep_report(&a, &flood_variants());
        let j: serde_json::Value = serde_json::from_str(&out).expect("one JSON object");
        assert_eq!(j["runs"], 3);
        assert_eq!(j["ticks"], 2000);
        assert_eq!(j["udp_ticks_per_s"], 3800.0, "the median");
        assert_eq!(j["udp_ticks_per_s_min"], 3000.0);
        assert_eq!(j["udp_ticks_per_s_max"], 4000.0);
        assert_eq!(j["udp_flood_ticks_per_s"], 2000.0);
        assert_eq!(j["ratio_flood_over_udp"], 0.53, "2000 / 3800, the ratio of the medians");
        assert_eq!(j["ratio_flood_over_udp_min"], 0.5, "round 1: 2000 / 4000");
        assert_eq!(j["ratio_flood_over_udp_max"], 0.8, "round 2: 2400 / 3000");
        assert_eq!(j["flood_sent"], 99_000, "every run sent at least this many");
        assert_eq!(j["flood_stderr_bytes"], 700, "the most in one run");
        assert_eq!(j["udp_stderr_bytes"], 95);
    }

    #[test]
    fn one_variant_keeps_its_transport_and_ticks_per_s_keys() {
        let a = lockstep_args(&["--runs", "2", "--json"]).expect("parses");
        let v = [LockstepVariant { name: "shm", runs: vec![run(6000.0, 0, 0), run(7000.0, 0, 0)] }];
        let j: serde_json::Value = serde_json::from_str(&lockstep_report(&a, &v)).expect("one JSON object");
        assert_eq!(j["transport"], "shm");
        assert_eq!(j["ticks_per_s"], 6500.0);
        assert_eq!(j["ticks_per_s_min"], 6000.0);
        assert_eq!(j["ticks_per_s_max"], 7000.0);
    }

    #[test]
    fn the_text_report_gives_median_min_max_and_the_ratio_of_medians() {
        let a = lockstep_args(&["--transport", "udp", "--flood", "100000", "--runs", "3"]).expect("parses");
        let out = lockstep_report(&a, &flood_variants());
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 3, "{out}");
        assert!(
            lines[0].contains("over udp:")
                && lines[0].contains("3800.0 ticks/s (median of 3 runs, min 3000.0, max 4000.0)"),
            "{out}"
        );
        assert!(
            lines[1].contains("over udp+flood:") && lines[1].contains("bridge stderr 700 bytes (most in one run)"),
            "{out}"
        );
        assert!(
            lines[2].contains("UDP with the flood / without: 0.53x (of the medians; 0.50x to 0.80x run by run)"),
            "{out}"
        );
    }

    #[test]
    fn one_run_prints_as_before() {
        let a = lockstep_args(&["--transport", "udp", "--flood", "100000", "--runs", "1"]).expect("parses");
        let v: Vec<LockstepVariant> = flood_variants()
            .into_iter()
            .map(|mut v| {
                v.runs.truncate(1);
                v
            })
            .collect();
        let out = lockstep_report(&a, &v);
        assert!(out.contains(": 4000.0 ticks/s over 2000 ticks; bridge stderr 90 bytes\n"), "{out}");
        assert!(out.contains("UDP with the flood / without: 0.50x\n"), "{out}");
    }
}
