//! `iwsim bench`: the benchmarks that need processes or the whole simulator — world
//! throughput on tiled LIACC floors, hub latency against a raw iceoryx2 ping-pong measured in
//! the same run, lock-step rates over shared memory and over the UDP/XML bridge, and the
//! viewer's cost. Each prints figures (or one JSON object with `--json`).
//!
//! The benchmark world ([`tiled`]) lives here, not in the production libraries.
#![warn(missing_docs)]

pub mod args;
pub mod tiled;
pub mod viewer;

pub use args::BenchCommand;

/// Runs one `iwsim bench` subcommand.
pub fn run(command: &BenchCommand) -> anyhow::Result<std::process::ExitCode> {
    match command {
        BenchCommand::World(a) => world(a),
        BenchCommand::Latency(a) => latency(a),
        BenchCommand::Lockstep(a) => lockstep(a),
        BenchCommand::Viewer(a) => viewer::run(a),
        BenchCommand::RawPeer(a) => raw_peer(a),
        BenchCommand::UdpClient(a) => udp_client(a),
    }
}

use std::process::ExitCode;
use std::time::{Duration, Instant};

use crate::tiled::TiledWorld;

use anyhow::Context as _;
use ipc_services::{RawPingPong, Role};
use ipc_types::{PING_PAYLOAD_BYTES, Ping};

use crate::args::{BenchLatencyArgs, BenchLockstepArgs, BenchWorldArgs, RawPeerArgs, Transport, UdpClientArgs};

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

pub use records::latency::Percentiles;
use records::outcome::HubOutcome;

fn iwsim_exe() -> anyhow::Result<std::path::PathBuf> {
    std::env::current_exe().context("finding the iwsim executable")
}

pub(crate) fn spawn_self(args: &[String]) -> anyhow::Result<std::process::Child> {
    std::process::Command::new(iwsim_exe()?)
        .args(args)
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
}

/// A hub in lock-step with `agents` agent processes of `robots_per_agent` robots each, physics
/// and sensors on, on an open 400 m lab; ticks per second from the first step to the last.
/// Robots stand in lattices 5 m apart (one per 25 m², about three times the density of the
/// LIACC floor in `bench world`), driving slow arcs. Over UDP, each agent is a Ciber-Rato-style
/// client process (one socket per robot, one `<Actions>` per `<Measures>`) talking to
/// `iwsim udp`. With `flood` > 0 (UDP only), a thread sends that many junk datagrams at the
/// bridge while the run goes on.
pub fn measure_lockstep(
    agents: usize,
    robots_per_agent: usize,
    ticks: u64,
    udp: bool,
    flood: u64,
) -> anyhow::Result<LockstepBench> {
    let tag = format!("{}-{}", udp as u8, (flood > 0) as u8);
    let dir = std::env::temp_dir().join(format!("iwsim-bench-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let lab = dir.join("lab.xml");
    std::fs::write(
        &lab,
        "<Lab Name=\"bench\" Width=\"400\" Height=\"400\">\n  <Wall Height=\"2\"><Corner X=\"200\" Y=\"0\"/><Corner X=\"201\" Y=\"0\"/><Corner X=\"201\" Y=\"150\"/><Corner X=\"200\" Y=\"150\"/></Wall>\n</Lab>\n",
    )?;
    let session = format!("bench-ls-{}-{tag}", std::process::id());
    // Over UDP the bridge is the hub's one agent, whatever the number of UDP clients.
    let hub_agents = if udp { 1 } else { agents };
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
        hub_agents.to_string(),
        "--json".into(),
    ])?;
    const SPACING: f64 = 5.0;
    let rows = robots_per_agent.div_ceil(10).max(1) as f64 * SPACING + SPACING;
    let origin = |i: usize| (5.0 + (10.0 * SPACING + SPACING) * (i % 7) as f64, 5.0 + rows * (i / 7) as f64);
    let mut children = Vec::new();
    let mut bridge = None;
    let mut flooder = None;
    let mut stderr_bytes = None;
    if udp {
        let mut b = spawn_self(&[
            "udp".into(),
            "--session".into(),
            session.clone(),
            "--port".into(),
            "0".into(),
            "--connect-timeout".into(),
            "30".into(),
        ])?;
        let (server, bytes) = bridge_address(&mut b)?;
        stderr_bytes = Some(bytes);
        bridge = Some(b);
        if flood > 0 {
            flooder = Some(start_flood(server, flood)?);
        }
        // The hub starts when the bridge is ready, i.e. at its first robot: register every
        // client's robots before the first tick matters, which the clients do at once.
        for i in 0..agents {
            let (bx, by) = origin(i);
            children.push(spawn_self(&[
                "bench".into(),
                "udp-client".into(),
                "--server".into(),
                server.to_string(),
                "--robots".into(),
                robots_per_agent.to_string(),
                "--pose".into(),
                format!("{bx},{by}"),
            ])?);
        }
    } else {
        for i in 0..agents {
            let (bx, by) = origin(i);
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
    }
    let out = finish(hub, "hub")?;
    for c in children {
        finish(c, "agent")?;
    }
    if let Some(b) = bridge {
        finish(b, "bridge")?;
    }
    let flood_sent = match flooder {
        Some(f) => f.stop(),
        None => 0,
    };
    // The bridge has exited: its stderr is closed and the counting thread ends.
    let bridge_stderr_bytes = stderr_bytes.map_or(0, |h| h.join().unwrap_or(0));
    let _ = std::fs::remove_dir_all(&dir);
    let hub_out = HubOutcome::from_stdout(&out).context("reading how the hub's run ended")?;
    let ticks_per_s = hub_out.ticks as f64 / hub_out.run_s.max(1e-9);
    Ok(LockstepBench { agents, robots_per_agent, ticks: hub_out.ticks, ticks_per_s, flood_sent, bridge_stderr_bytes })
}

/// A thread sending junk datagrams at a bridge until it has sent its count or is stopped.
struct Flood {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<u64>,
}

impl Flood {
    /// Stops the flood; the datagrams it sent.
    fn stop(self) -> u64 {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap_or(0)
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
    Ok(Flood { stop, thread })
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
/// answers every `<Measures>` with one `<Actions>`, until the Measures stop.
pub fn udp_client(args: &UdpClientArgs) -> anyhow::Result<ExitCode> {
    use std::net::UdpSocket;
    let mut socks = Vec::new();
    for k in 0..args.robots {
        let s = UdpSocket::bind("127.0.0.1:0").context("bind a client socket")?;
        s.set_read_timeout(Some(Duration::from_secs(10)))?;
        let (x, y) = (args.pose[0] + 5.0 * (k % 10) as f64, args.pose[1] + 5.0 * (k / 10) as f64);
        let reg = format!("<Robot Name=\"udp{k}\" X=\"{x}\" Y=\"{y}\" Dir=\"0\"/>");
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
    let mut answered = 0u64;
    let mut buf = [0u8; 4096];
    'run: loop {
        for s in &socks {
            // After the run the bridge exits and the Measures stop: that is the end.
            let timeout = if answered == 0 { Duration::from_secs(30) } else { Duration::from_millis(1500) };
            s.set_read_timeout(Some(timeout))?;
            match s.recv(&mut buf) {
                Ok(_) => {
                    s.send(b"<Actions LeftMotor=\"0.045\" RightMotor=\"0.042\"/>")?;
                    answered += 1;
                }
                Err(_) => break 'run,
            }
        }
    }
    eprintln!("udp client: answered {answered} Measures");
    Ok(ExitCode::SUCCESS)
}

/// `iwsim bench lockstep`.
pub fn lockstep(args: &BenchLockstepArgs) -> anyhow::Result<ExitCode> {
    let m = |udp: bool, flood: u64| measure_lockstep(args.agents, args.robots_per_agent, args.ticks, udp, flood);
    let mut runs: Vec<(&str, LockstepBench)> = match args.transport {
        Transport::Shm if args.flood == 0 => vec![("shm", m(false, 0)?)],
        Transport::Shm => vec![],
        Transport::Udp => vec![("udp", m(true, 0)?)],
        Transport::Both => vec![("shm", m(false, 0)?), ("udp", m(true, 0)?)],
    };
    if args.flood > 0 {
        // The flood is at the bridge: compare UDP runs with and without it, in one invocation.
        if !runs.iter().any(|(name, _)| *name == "udp") {
            runs.push(("udp", m(true, 0)?));
        }
        runs.push(("udp+flood", m(true, args.flood)?));
    }
    let shm_udp = match (runs.first(), runs.get(1)) {
        (Some(("shm", a)), Some(("udp", b))) => Some(a.ticks_per_s / b.ticks_per_s.max(1e-9)),
        _ => None,
    };
    let flood = runs.iter().find(|(name, _)| *name == "udp+flood").map(|(_, f)| f);
    let quiet = runs.iter().find(|(name, _)| *name == "udp").map(|(_, q)| q);
    let flood_ratio = match (flood, quiet) {
        (Some(f), Some(q)) => Some(f.ticks_per_s / q.ticks_per_s.max(1e-9)),
        _ => None,
    };
    if args.json {
        let mut s = format!(
            "{{\"agents\":{},\"robots_per_agent\":{},\"ticks\":{}",
            args.agents, args.robots_per_agent, runs[0].1.ticks
        );
        if runs.len() == 1 {
            s += &format!(",\"transport\":\"{}\",\"ticks_per_s\":{:.1}", runs[0].0, runs[0].1.ticks_per_s);
        } else {
            for (name, b) in &runs {
                s += &format!(",\"{}_ticks_per_s\":{:.1}", name.replace('+', "_"), b.ticks_per_s);
            }
        }
        if let Some(r) = shm_udp {
            s += &format!(",\"ratio_shm_over_udp\":{r:.2}");
        }
        if let (Some(f), Some(r), Some(q)) = (flood, flood_ratio, quiet) {
            s += &format!(
                ",\"flood_sent\":{},\"ratio_flood_over_udp\":{r:.2},\"udp_stderr_bytes\":{},\"flood_stderr_bytes\":{}",
                f.flood_sent, q.bridge_stderr_bytes, f.bridge_stderr_bytes
            );
        }
        println!("{s}}}");
    } else {
        for (name, b) in &runs {
            let flooded =
                if b.flood_sent > 0 { format!(", {} junk datagrams sent", b.flood_sent) } else { String::new() };
            let stderr = if args.flood > 0 && name.starts_with("udp") {
                format!("; bridge stderr {} bytes", b.bridge_stderr_bytes)
            } else {
                String::new()
            };
            println!(
                "lockstep over {name}: {} agents x {} robots, physics and sensors on: {:.1} ticks/s over {} ticks{flooded}{stderr}",
                b.agents, b.robots_per_agent, b.ticks_per_s, b.ticks
            );
        }
        if let Some(r) = shm_udp {
            println!("  shared memory / UDP: {r:.2}x");
        }
        if let Some(r) = flood_ratio {
            println!("  UDP with the flood / without: {r:.2}x");
        }
    }
    Ok(ExitCode::SUCCESS)
}
