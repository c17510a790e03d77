//! Agents on other machines, through the Zenoh bridge (`iwsim zenoh`): another host is a
//! network namespace joined to this one by a veth pair, so the agents' traffic crosses a real
//! network link. Making namespaces needs root (CI runs as root); a test that cannot make them
//! fails and says so.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use run_records::summary::RunSummary;

use super::common::{Lines, Proc, assert_no_shared_memory_left, free_port, session, text};

/// Another host as far as the network goes: a network namespace with one end of a veth pair,
/// the other end here. Removed (namespace and link) when dropped.
struct Host {
    ns: String,
    link: String,
    /// This side's address, which the other host reaches us at.
    here: String,
    /// The other host's address.
    there: String,
}

impl Host {
    fn new() -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        #[allow(unsafe_code)]
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        assert!(
            root,
            "the Zenoh tests make network namespaces (`ip netns add`), which needs root: run the suite as root (CI does)"
        );
        let n = N.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id() % 100_000;
        let (ns, link, peer) = (format!("iwz{pid}n{n}"), format!("iwz{pid}h{n}"), format!("iwz{pid}p{n}"));
        let subnet = format!("10.{}.{}", 200 + n % 50, pid % 250);
        let here = format!("{subnet}.1");
        let host = Self { ns: ns.clone(), link: link.clone(), here: here.clone(), there: format!("{subnet}.2") };
        for args in [
            vec!["netns", "add", &ns],
            vec!["link", "add", &link, "type", "veth", "peer", "name", &peer],
            vec!["link", "set", &peer, "netns", &ns],
            vec!["addr", "add", &format!("{here}/30"), "dev", &link],
            vec!["link", "set", &link, "up"],
            vec!["-n", &ns, "addr", "add", &format!("{subnet}.2/30"), "dev", &peer],
            vec!["-n", &ns, "link", "set", &peer, "up"],
            vec!["-n", &ns, "link", "set", "lo", "up"],
        ] {
            ip(&args);
        }
        host
    }

    /// An endpoint on this side, on a port no one uses.
    fn endpoint_here(&self) -> String {
        format!("tcp/{}:{}", self.here, free_port())
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        // Deleting one end of a veth pair deletes both.
        let _ = Command::new("ip").args(["link", "del", &self.link]).status();
        let _ = Command::new("ip").args(["netns", "del", &self.ns]).status();
    }
}

fn ip(args: &[&str]) {
    let out = Command::new("ip").args(args).output().expect("ip (iproute2) runs");
    assert!(out.status.success(), "ip {}: {}", args.join(" "), text(&out.stderr));
}

/// A TCP port free at the moment (the kernel's pick).
fn work_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-zenoh-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("work dir");
    dir
}

/// `iwsim run ARGS --out DIR/NAME`; its summary.
fn run(dir: &Path, name: &str, args: &[&str]) -> RunSummary {
    let out = dir.join(name);
    let mut full = vec!["run"];
    full.extend_from_slice(args);
    full.extend(["--headless", "--quiet", "--out", out.to_str().expect("utf-8")]);
    let o = Proc::spawn(&full).wait(Duration::from_secs(300));
    assert!(o.status.success(), "iwsim {}: {}\n{}", full.join(" "), text(&o.stdout), text(&o.stderr));
    RunSummary::read(&out.join("summary.json")).unwrap_or_else(|e| panic!("{e}"))
}

/// `iwsim zenoh --session S OPTIONS --connect-timeout 20` once it serves, with the rest of
/// what it says on stderr; the line saying it serves is returned as well.
fn serving_bridge(s: &str, options: &[&str]) -> (Proc, Lines, String) {
    let mut args = vec!["zenoh", "--session", s];
    args.extend_from_slice(options);
    args.extend(["--connect-timeout", "20"]);
    let mut b = Proc::spawn(&args);
    let said = b.stderr_lines();
    let serving = said.said("served under", Duration::from_secs(20));
    (b, said, serving)
}

#[test]
fn the_navigator_on_another_host_drives_the_slalom_bit_for_bit_as_it_does_here() {
    let dir = work_dir("slalom");
    let host = Host::new();
    let here = run(&dir, "here", &["builtin:slalom", "--lockstep", "--seed", "3"]);
    let listen = host.endpoint_here();
    let remote = run(
        &dir,
        "remote",
        &[
            "builtin:slalom",
            "--lockstep",
            "--seed",
            "3",
            "--zenoh-agents",
            "all",
            "--zenoh-listen",
            &listen,
            "--zenoh-netns",
            &host.ns,
        ],
    );
    assert_eq!((remote.ticks, remote.state_hash), (here.ticks, here.state_hash));
    assert!(remote.passed, "the slalom is passed from the other host too");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn corridor_swap_with_one_chair_on_another_host_is_the_local_run() {
    let dir = work_dir("swap");
    let host = Host::new();
    let here = run(&dir, "here", &["builtin:corridor-swap", "--lockstep"]);
    let listen = host.endpoint_here();
    let mixed = run(
        &dir,
        "mixed",
        &[
            "builtin:corridor-swap",
            "--lockstep",
            "--zenoh-agents",
            "2",
            "--zenoh-listen",
            &listen,
            "--zenoh-netns",
            &host.ns,
        ],
    );
    assert_eq!((mixed.ticks, mixed.state_hash), (here.ticks, here.state_hash));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_agent_written_with_the_official_zenoh_binding_registers_reads_its_blocks_and_drives() {
    let s = session("zenoh-third-party");
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "60", "--wait-agents", "1"]);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (bridge, bridge_said, _) = serving_bridge(&s, &["--listen", &endpoint]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/zenoh/third_party_agent.py");
    let agent = Command::new(python)
        .arg(&script)
        .args([&endpoint, &s, "py-chair", "10.0", "6.1", "0.8", "--junk"])
        .output()
        .expect("python runs");
    assert!(agent.status.success(), "{}\n{}", text(&agent.stdout), text(&agent.stderr));
    let said = text(&agent.stdout);
    let value = |key: &str| -> u64 {
        said.lines()
            .find_map(|l| l.strip_prefix(key).and_then(|v| v.trim().parse().ok()))
            .unwrap_or_else(|| panic!("{key} in {said}"))
    };
    // Every tick brought its own robot's block, and only it; it answered each.
    assert_eq!((value("answered "), value("own_blocks ")), (60, 61), "{said}");
    let h = hub.wait(Duration::from_secs(30));
    let out = text(&h.stdout) + &text(&h.stderr);
    // Judged from the hub: the robot it registered drove forward from x = 10 m.
    let robot = value("robot ");
    let x: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix(&format!("robot {robot}: x ")))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("the hub's final pose of robot {robot}: {out}"));
    assert!(x > 11.0, "robot {robot} ended at x = {x}: {out}");
    // Its junk was refused or counted and dropped, and changed nothing else.
    assert!(said.contains("refused this bridge speaks"), "{said}");
    assert!(bridge.wait(Duration::from_secs(20)).status.success());
    let end = bridge_said.to_end(Duration::from_secs(5)).join("\n");
    assert!(end.contains("(1 malformed, 2 foreign, 1 hellos refused, 0 agents lost"), "{end}");
    assert_no_shared_memory_left(&s);
    // Nor a Zenoh shared-memory segment (the Python binding's, which the client turns off; no
    // other test runs that binding).
    let zenoh_files: Vec<String> = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".zenoh"))
        .collect();
    assert!(zenoh_files.is_empty(), "left in /dev/shm: {zenoh_files:?}");
}

/// The newest world snapshot's tick and robot `id`'s x, metres.
fn tick_and_x(observer: &mut observer::Observer, id: u32) -> (u64, f64) {
    let (h, robots) = observer.world().expect("world snapshot");
    let r = robots.iter().find(|r| r.id == id).unwrap_or_else(|| panic!("robot {id} in the world"));
    (h.tick, r.x_m)
}

/// Waits until the hub reaches `tick`; robot `id`'s x then.
fn x_at(observer: &mut observer::Observer, id: u32, tick: u64) -> f64 {
    let start = std::time::Instant::now();
    loop {
        let (t, x) = tick_and_x(observer, id);
        if t >= tick {
            return x;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "the hub stayed at tick {t} (< {tick})");
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn a_remote_agent_killed_mid_run_leaves_its_chair_standing_and_takes_it_back_when_restarted() {
    let s = session("zenoh-agent-killed");
    // Lock-step with a deadline no test waits out: a remote agent that goes is noticed by its
    // liveliness token, at once, not at the deadline.
    // Ticks without end (the hub runs free while no agent drives): the test stops the run.
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "10000000",
        "--wait-agents",
        "1",
        "--deadline-ms",
        "60000",
    ]);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (bridge, bridge_said, _) = serving_bridge(&s, &["--listen", &endpoint]);
    let agent =
        ["agent", "wheelchair", "--session", &s, "--zenoh", &endpoint, "--connect-timeout", "20", "--name", "chair1"];
    let mut first = Proc::spawn(&agent);
    let robots = first.announced("drives robots ", Duration::from_secs(30));
    assert!(robots.starts_with("[1]"), "{robots}");
    let mut observer = super::common::wait_for_tick(&s, 1, Duration::from_secs(30));
    let moving = x_at(&mut observer, 1, 50);
    first.kill9();
    // Its chair stops where it is (motors at rest) and the run goes on without it.
    let (killed_at, _) = tick_and_x(&mut observer, 1);
    let standing = x_at(&mut observer, 1, killed_at + 60);
    let still = x_at(&mut observer, 1, killed_at + 120);
    assert!(standing > moving, "it drove before: {moving} → {standing}");
    assert!((still - standing).abs() < 1e-3, "a chair whose agent went stands: {standing} → {still}");
    // A new agent registering the same name takes the same chair back, and drives it again.
    let mut second = Proc::spawn(&agent);
    let robots = second.announced("drives robots ", Duration::from_secs(30));
    assert!(robots.starts_with("[1]"), "the same robot taken back: {robots}");
    let (back_at, _) = tick_and_x(&mut observer, 1);
    let again = x_at(&mut observer, 1, back_at + 60);
    assert!(again > still + 0.1, "driven again after it was taken back: {still} → {again}");
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    let h = hub.wait(Duration::from_secs(120));
    assert!(h.status.success(), "{}", text(&h.stderr));
    let s2 = second.wait(Duration::from_secs(20));
    assert!(s2.status.success(), "{}", text(&s2.stderr));
    let b = bridge.wait(Duration::from_secs(20));
    assert!(b.status.success());
    assert!(bridge_said.to_end(Duration::from_secs(5)).iter().any(|l| l.contains("1 agents lost")));
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_killed_bridge_is_a_dead_agent_to_the_hub_and_its_remote_agents_say_so() {
    let s = session("zenoh-bridge-killed");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "10000000",
        "--wait-agents",
        "1",
        "--deadline-ms",
        "200",
    ]);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (mut bridge, _, _) = serving_bridge(&s, &["--listen", &endpoint]);
    let mut agent =
        Proc::spawn(&["agent", "wheelchair", "--session", &s, "--zenoh", &endpoint, "--connect-timeout", "20"]);
    let agent_said = agent.stderr_lines();
    agent_said.said("drives robots ", Duration::from_secs(30));
    let mut observer = super::common::wait_for_tick(&s, 20, Duration::from_secs(30));
    bridge.kill9();
    // The remote agent learns it at once (its link to the bridge closed)…
    let a = agent.wait(Duration::from_secs(20));
    assert!(!a.status.success(), "an agent whose bridge died must say so in its exit status");
    let said = agent_said.to_end(Duration::from_secs(5)).join("\n");
    assert!(said.contains("Zenoh bridge of session"), "{said}");
    // …and the hub, whose agent the bridge was, keeps its policy for a dead agent: the robot
    // frozen where it stands, the run stepped at the deadline's pace until an agent comes back.
    let (t, _) = tick_and_x(&mut observer, 1);
    x_at(&mut observer, 1, t + 5);
    let (_, robots) = observer.world().expect("world snapshot");
    assert!(robots[0].flags & ipc_types::ROBOT_FROZEN != 0, "{:?}", robots[0]);
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    let h = hub.wait(Duration::from_secs(30));
    assert!(h.status.success(), "{}", text(&h.stderr));
    assert!(text(&h.stdout).contains("agents: 1 connected, 1 died"), "{}", text(&h.stdout));
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_link_pulled_for_two_seconds_mid_run_stalls_nothing_and_loses_no_agent() {
    let s = session("zenoh-link-pulled");
    let host = Host::new();
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "10000000",
        "--wait-agents",
        "1",
        "--deadline-ms",
        "300",
    ]);
    let listen = host.endpoint_here();
    let (bridge, bridge_said, _) = serving_bridge(&s, &["--listen", &listen]);
    let mut agent = Proc::spawn_in(
        &host.ns,
        &["agent", "wheelchair", "--session", &s, "--zenoh", &listen, "--connect-timeout", "20"],
    );
    let agent_said = agent.stderr_lines();
    agent_said.said("drives robots ", Duration::from_secs(30));
    let mut observer = super::common::wait_for_tick(&s, 20, Duration::from_secs(30));
    ip(&["link", "set", &host.link, "down"]);
    let (cut_at, _) = tick_and_x(&mut observer, 1);
    // The hub keeps its deadline policy while the agent cannot answer: the run goes on (the
    // bridge answers without the agent at 90 % of the deadline, then no longer waits for it
    // until it speaks again), and the chair, its agent silent, comes to rest.
    x_at(&mut observer, 1, cut_at + 3);
    std::thread::sleep(Duration::from_secs(2));
    let (_, resting) = tick_and_x(&mut observer, 1);
    ip(&["link", "set", &host.link, "up"]);
    // Back on the link (TCP retransmits within seconds), the same agent drives it again.
    let start = std::time::Instant::now();
    loop {
        let (_, x) = tick_and_x(&mut observer, 1);
        if x > resting + 0.5 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the agent never drove again: still at {x} (rested at {resting})"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    assert!(hub.wait(Duration::from_secs(30)).status.success());
    let status = agent.wait(Duration::from_secs(30)).status;
    let b = bridge.wait(Duration::from_secs(20));
    assert!(
        status.success(),
        "{}\nthe bridge: {}",
        agent_said.to_end(Duration::from_secs(5)).join("\n"),
        bridge_said.so_far().join("\n")
    );
    assert!(b.status.success());
    // Whether or not Zenoh closed the link meanwhile, the agent was not lost for good: any
    // agent the bridge lost came back.
    let end = bridge_said.to_end(Duration::from_secs(5)).join("\n");
    let count = |what: &str| -> u64 {
        let before = end.split(what).next().and_then(|b| b.rsplit([' ', '(']).next()).unwrap_or("");
        before.parse().unwrap_or_else(|_| panic!("{what} in {end}"))
    };
    assert_eq!(count(" agents lost"), count(" came back"), "{end}");
    assert_no_shared_memory_left(&s);
}

/// The hub's `tick N state hash H` line.
fn hash_line(hub_output: &str) -> String {
    hub_output
        .lines()
        .find(|l| l.contains(" state hash "))
        .unwrap_or_else(|| panic!("no state hash in {hub_output}"))
        .to_owned()
}

/// A wheelchair agent with two chairs for 300 lock-step ticks in session `s`, its extra
/// options `via`, with a Zenoh bridge connected to `router` if given; the hub's state-hash line.
fn two_chairs(s: &str, netns: Option<&str>, via: &[&str], router: Option<&str>) -> String {
    let hub = Proc::spawn(&["hub", "--session", s, "--lockstep", "--ticks", "300", "--wait-agents", "1"]);
    let bridge = router.map(|r| serving_bridge(s, &["--connect", r]).0);
    let bin = env!("CARGO_BIN_EXE_iwsim");
    let mut cmd = match netns {
        Some(ns) => {
            let mut c = Command::new("ip");
            c.args(["netns", "exec", ns, bin]);
            c
        }
        None => Command::new(bin),
    };
    let agent = cmd
        .args([
            "agent",
            "wheelchair",
            "--session",
            s,
            "--robots",
            "2",
            "--powers",
            "0.6,0.5",
            "--connect-timeout",
            "20",
        ])
        .args(via)
        .output()
        .expect("the agent runs");
    assert!(agent.status.success(), "{}", text(&agent.stderr));
    let h = hub.wait(Duration::from_secs(60));
    assert!(h.status.success(), "{}", text(&h.stderr));
    if let Some(b) = bridge {
        assert!(b.wait(Duration::from_secs(20)).status.success());
    }
    hash_line(&text(&h.stdout))
}

#[test]
fn through_a_router_between_the_hosts_the_run_is_the_local_run() {
    let host = Host::new();
    let here = two_chairs(&session("zenoh-routed-here"), None, &[], None);
    // The router on this host's side of the link; the bridge reaches it on loopback, the
    // agent from the other host: neither listens for the other.
    let port = free_port();
    let mut router = Proc::spawn(&["zenoh-router", "--listen", &format!("tcp/0.0.0.0:{port}")]);
    router.announced("routing on", Duration::from_secs(20));
    let s = session("zenoh-routed");
    let via = format!("tcp/{}:{port}", host.here);
    let routed = two_chairs(&s, Some(&host.ns), &["--zenoh", &via], Some(&format!("tcp/127.0.0.1:{port}")));
    assert_eq!(routed, here);
    router.signal("TERM");
    assert!(router.wait(Duration::from_secs(20)).status.success());
    assert_no_shared_memory_left(&s);
}

/// Agents `a` and `b` (two chairs each, `b` started once `a` drives) in a 200-tick lock-step
/// run of session `s`: locally when `bridge` is `None`, else on the other host through a
/// bridge listening at `bridge` and waiting for both. The hub's state-hash line.
fn two_agents_one_after_the_other(s: &str, bridge: Option<(&Host, &str)>) -> String {
    let waited = if bridge.is_some() { "1" } else { "2" };
    let hub = Proc::spawn(&["hub", "--session", s, "--lockstep", "--ticks", "200", "--wait-agents", waited]);
    let mut zb = bridge.map(|(_, ep)| serving_bridge(s, &["--listen", ep, "--wait-agents", "2"]).0);
    let agent = |name: &str, powers: &str| {
        let mut args = vec!["agent", "wheelchair", "--session", s, "--name", name, "--robots", "2"];
        args.extend(["--powers", powers, "--connect-timeout", "20"]);
        match bridge {
            Some((host, ep)) => {
                args.extend(["--zenoh", ep]);
                Proc::spawn_in(&host.ns, &args)
            }
            None => Proc::spawn(&args),
        }
    };
    let mut a = agent("a", "0.6,0.5");
    a.announced("drives robots", Duration::from_secs(30));
    // The hub has not ticked: it waits for b, here or behind the bridge.
    let b = agent("b", "0.5,0.6");
    for p in [a, b] {
        let o = p.wait(Duration::from_secs(120));
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let h = hub.wait(Duration::from_secs(60));
    assert!(h.status.success(), "{}", text(&h.stderr));
    if let Some(b) = zb.take() {
        assert!(b.wait(Duration::from_secs(20)).status.success());
    }
    hash_line(&text(&h.stdout))
}

#[test]
fn a_bridge_waiting_for_two_remote_agents_starts_the_run_with_both_as_a_hub_does() {
    let host = Host::new();
    let here = two_agents_one_after_the_other(&session("zenoh-wait-here"), None);
    let s = session("zenoh-wait");
    let ep = host.endpoint_here();
    let there = two_agents_one_after_the_other(&s, Some((&host, &ep)));
    // Had the run started at a's word, b's chairs would have missed its first ticks.
    assert_eq!(there, here);
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_router_restarted_mid_run_costs_ticks_not_agents() {
    let host = Host::new();
    let s = session("zenoh-router-restart");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "10000000",
        "--wait-agents",
        "1",
        "--deadline-ms",
        "300",
    ]);
    let port = free_port();
    let listen = format!("tcp/0.0.0.0:{port}");
    let mut router = Proc::spawn(&["zenoh-router", "--listen", &listen]);
    router.announced("routing on", Duration::from_secs(20));
    let (bridge, _, _) = serving_bridge(&s, &["--connect", &format!("tcp/127.0.0.1:{port}")]);
    let via = format!("tcp/{}:{port}", host.here);
    let mut agent =
        Proc::spawn_in(&host.ns, &["agent", "wheelchair", "--session", &s, "--zenoh", &via, "--connect-timeout", "20"]);
    let agent_said = agent.stderr_lines();
    agent_said.said("drives robots ", Duration::from_secs(30));
    let mut observer = super::common::wait_for_tick(&s, 20, Duration::from_secs(30));
    router.kill9();
    let (cut_at, _) = tick_and_x(&mut observer, 1);
    // Without the router the run goes on at the deadline's pace, the chair at rest.
    x_at(&mut observer, 1, cut_at + 2);
    let (_, resting) = tick_and_x(&mut observer, 1);
    let mut router = Proc::spawn(&["zenoh-router", "--listen", &listen]);
    router.announced("routing on", Duration::from_secs(20));
    // Zenoh reconnects the bridge and the agent to the new router by itself, and the agent
    // drives its chair again.
    let start = std::time::Instant::now();
    loop {
        let (_, x) = tick_and_x(&mut observer, 1);
        if x > resting + 0.5 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the agent never drove again: still at {x} (rested at {resting})"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    assert!(hub.wait(Duration::from_secs(30)).status.success());
    let status = agent.wait(Duration::from_secs(30)).status;
    let b = bridge.wait(Duration::from_secs(20));
    assert!(status.success(), "{}", agent_said.to_end(Duration::from_secs(5)).join("\n"));
    assert!(b.status.success());
    router.signal("TERM");
    assert!(router.wait(Duration::from_secs(20)).status.success());
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_viewer_on_another_host_shows_the_run_only_when_the_bridge_serves_observers() {
    let host = Host::new();
    let s = session("zenoh-viewer");
    let hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "10", "--no-noise"]);
    let agent = Proc::spawn(&[
        "agent",
        "wheelchair",
        "--session",
        &s,
        "--robots",
        "2",
        "--pose",
        "10,6.1,0",
        "--powers",
        "0.6,0.5",
    ]);
    // A bridge that serves agents only: a viewer over there is told why it sees nothing.
    let closed = host.endpoint_here();
    let (agents_only, _, _) = serving_bridge(&s, &["--listen", &closed]);
    let http = format!("{}:0", host.there);
    let refused = Proc::spawn_in(
        &host.ns,
        &["view", "--session", &s, "--zenoh", &closed, "--connect-timeout", "2", "--http", &http],
    )
    .wait(Duration::from_secs(30));
    assert!(!refused.status.success());
    assert!(text(&refused.stderr).contains("--observers world"), "{}", text(&refused.stderr));
    // One that serves the world to observers: the viewer over there shows the run as the
    // hub's own observer here sees it.
    let open = host.endpoint_here();
    let (serving, _, said) = serving_bridge(&s, &["--listen", &open, "--observers", "world"]);
    assert!(said.contains("the world to observers"), "{said}");
    let mut view = Proc::spawn_in(&host.ns, &["view", "--session", &s, "--zenoh", &open, "--http", &http]);
    let url = view.announced("open http://", Duration::from_secs(30));
    let addr: std::net::SocketAddr = url.trim_end_matches('/').parse().expect("the viewer's address");
    let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("the remote viewer's stream");
    let mut local = super::common::wait_for_tick(&s, 1, Duration::from_secs(30));
    let start = std::time::Instant::now();
    let mut seen: Vec<(u64, f32)> = Vec::new();
    while seen.len() < 20 {
        assert!(start.elapsed() < Duration::from_secs(30), "frames with two chairs: {seen:?}");
        let tungstenite::Message::Binary(b) = ws.read().expect("a message") else { continue };
        let f = viewer::frame::decode(&b).expect("a valid frame");
        if f.robots.len() == 2 {
            seen.push((f.tick, f.robots[0].pose[0]));
        }
    }
    // The chairs drive, tick by tick, where the hub's truth has them.
    assert!(seen.windows(2).all(|w| w[1].0 > w[0].0), "{seen:?}");
    assert!(seen[19].1 > seen[0].1, "chair 1 drives: {seen:?}");
    let (h, robots) = local.world().expect("the truth here");
    assert!(h.tick >= seen[19].0, "the remote frames are of ticks the hub has run");
    assert!((f64::from(seen[19].1) - robots[0].x_m).abs() < 1.0, "{seen:?} vs {}", robots[0].x_m);
    drop(local);
    drop(ws);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    for p in [hub, agent, agents_only, serving, view] {
        let out = p.wait(Duration::from_secs(30));
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_recorder_on_another_host_writes_the_hubs_own_world_frames_and_says_they_cannot_be_replayed() {
    let host = Host::new();
    let s = session("zenoh-record");
    let dir = work_dir("record");
    let (here, there) = (dir.join("hub.mcap"), dir.join("remote.mcap"));
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let hub = Proc::spawn(
        &["hub", "--session", &s, "--lockstep", "--ticks", "300", "--wait-agents", "1"]
            .into_iter()
            .chain(["--record", &path(&here)])
            .collect::<Vec<_>>(),
    );
    let ep = host.endpoint_here();
    let (bridge, _, _) = serving_bridge(&s, &["--listen", &ep, "--observers", "world"]);
    let mut recorder = Proc::spawn_in(
        &host.ns,
        &["record", "--session", &s, "--zenoh", &ep, "--out", &path(&there), "--connect-timeout", "20"],
    );
    recorder.announced("recording session", Duration::from_secs(30));
    // The hub waits for this agent, so the recorder is in before the first step.
    let agent = Proc::spawn_in(
        &host.ns,
        &["agent", "wheelchair", "--session", &s, "--robots", "2", "--powers", "0.6,0.5", "--zenoh", &ep],
    );
    for p in [agent, hub, bridge] {
        let o = p.wait(Duration::from_secs(120));
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let o = recorder.wait(Duration::from_secs(30));
    let said = text(&o.stdout);
    assert!(o.status.success(), "{said}{}", text(&o.stderr));
    assert!(
        said.contains("301 world frames") && said.contains("0 missed") && said.contains("the run finished"),
        "{said}"
    );
    let (a, b) = (
        recorder::WorldTrack::open(&here).expect("the hub's recording"),
        recorder::WorldTrack::open(&there).expect("the remote recording"),
    );
    // Every tick's robots, bit for bit. Tick 0 alone may differ: the hub writes a tick's
    // world at its first publication (before the chairs came), the recorder the first it saw.
    assert_eq!(a.frames.len(), b.frames.len());
    assert_eq!(a.frames[1..], b.frames[1..]);
    let lab = |p: &Path| recorder::Recording::open(p).expect("a run start").start.lab;
    assert_eq!(lab(&there), lab(&here));
    // It plots as a hub's recording does; a replay is refused, and says why.
    let svg = dir.join("remote.svg");
    let o = Proc::spawn(&["plot", &path(&there), "--out", &path(&svg)]).wait(Duration::from_secs(60));
    assert!(o.status.success() && svg.exists(), "{}", text(&o.stderr));
    let o = Proc::spawn(&["replay", &path(&there)]).wait(Duration::from_secs(60));
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("recorded by an observer"), "{}", text(&o.stderr));
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn with_the_documented_user_password_files_only_a_listed_agent_gets_in() {
    // docs/zenoh.md's example files, as they are: run from the repository's root, as it says.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = session("zenoh-auth");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "100", "--wait-agents", "1"]);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let auth = ["--zenoh-config", "docs/zenoh/bridge-auth.json5"];
    let mut bridge = Proc::spawn_at(
        root,
        &[&["zenoh", "--session", &s, "--listen", &endpoint, "--connect-timeout", "20"][..], &auth].concat(),
    );
    bridge.announced("served under", Duration::from_secs(20));
    // Without credentials no link opens: the agent gives up at its timeout and says why.
    let stranger =
        Proc::spawn(&["agent", "wheelchair", "--session", &s, "--zenoh", &endpoint, "--connect-timeout", "2"])
            .wait(Duration::from_secs(30));
    assert!(!stranger.status.success());
    assert!(text(&stranger.stderr).contains(&format!("connect to {endpoint}")), "{}", text(&stranger.stderr));
    // With the documented agent file it joins, drives, and the run ends as usual.
    let listed = Proc::spawn_at(
        root,
        &[
            "agent",
            "wheelchair",
            "--session",
            &s,
            "--zenoh",
            &endpoint,
            "--connect-timeout",
            "20",
            "--zenoh-config",
            "docs/zenoh/agent-auth.json5",
        ],
    )
    .wait(Duration::from_secs(60));
    assert!(listed.status.success(), "{}", text(&listed.stderr));
    let h = hub.wait(Duration::from_secs(60));
    assert!(h.status.success(), "{}", text(&h.stderr));
    assert!(text(&h.stdout).contains("tick 100 "), "{}", text(&h.stdout));
    assert!(bridge.wait(Duration::from_secs(20)).status.success());
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_restarted_bridge_takes_its_remote_agents_back_and_they_drive_on() {
    let host = Host::new();
    let s = session("zenoh-bridge-restart");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "10000000",
        "--wait-agents",
        "1",
        "--deadline-ms",
        "300",
    ]);
    let listen = host.endpoint_here();
    let (mut first, _, _) = serving_bridge(&s, &["--listen", &listen]);
    let mut agent = Proc::spawn_in(
        &host.ns,
        &["agent", "wheelchair", "--session", &s, "--zenoh", &listen, "--connect-timeout", "20", "--name", "chair1"],
    );
    let agent_said = agent.stderr_lines();
    agent_said.said("drives robots ", Duration::from_secs(30));
    let mut observer = super::common::wait_for_tick(&s, 20, Duration::from_secs(30));
    first.kill9();
    let (killed_at, _) = tick_and_x(&mut observer, 1);
    // The hub holds the chair as a dead agent's (frozen) while no bridge serves it.
    let (_, before) = tick_and_x(&mut observer, 1);
    // The same bridge started again: a new run of it, which knows no agent. The agent sees it
    // come, says hello again and takes its chair back by name, and drives on.
    let (second, _, _) = serving_bridge(&s, &["--listen", &listen]);
    let start = std::time::Instant::now();
    loop {
        let (t, x) = tick_and_x(&mut observer, 1);
        if t > killed_at && x > before + 0.5 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the agent never drove again: at {x} (stood at {before}); it said: {}",
            agent_said.so_far().join("\n")
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    let h = hub.wait(Duration::from_secs(30));
    assert!(h.status.success(), "{}", text(&h.stderr));
    // Two bridges were the hub's agents, the first of them died; one robot throughout.
    assert!(text(&h.stdout).contains("agents: 2 connected, 1 died"), "{}", text(&h.stdout));
    assert_eq!(text(&h.stdout).matches("robot ").count(), 1, "{}", text(&h.stdout));
    let a = agent.wait(Duration::from_secs(30));
    assert!(a.status.success(), "{}", agent_said.to_end(Duration::from_secs(5)).join("\n"));
    assert!(second.wait(Duration::from_secs(20)).status.success());
    assert_no_shared_memory_left(&s);
}

#[test]
fn in_real_time_a_link_pulled_for_two_seconds_rests_the_chair_and_the_clock_goes_on() {
    let s = session("zenoh-link-pulled-rt");
    let host = Host::new();
    // Real time at 20 ms a tick: the hub never waits for anyone.
    let hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20", "--no-noise"]);
    let listen = host.endpoint_here();
    let (bridge, bridge_said, _) = serving_bridge(&s, &["--listen", &listen]);
    let mut agent = Proc::spawn_in(
        &host.ns,
        &["agent", "wheelchair", "--session", &s, "--zenoh", &listen, "--connect-timeout", "20", "--powers", "0.4,0.4"],
    );
    let agent_said = agent.stderr_lines();
    agent_said.said("drives robots ", Duration::from_secs(30));
    let mut observer = super::common::wait_for_tick(&s, 10, Duration::from_secs(30));
    // Driving before the cut.
    let (t0, x0) = tick_and_x(&mut observer, 1);
    let x_driving = x_at(&mut observer, 1, t0 + 25);
    assert!(x_driving > x0, "the chair drives: {x0} → {x_driving}");
    ip(&["link", "set", &host.link, "down"]);
    let cut = std::time::Instant::now();
    let (cut_at, _) = tick_and_x(&mut observer, 1);
    // The bridge rests the silent agent's chair after half a second; by 1.5 s it stands.
    while cut.elapsed() < Duration::from_millis(1500) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let (_, resting) = tick_and_x(&mut observer, 1);
    while cut.elapsed() < Duration::from_millis(2000) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let (up_at, still) = tick_and_x(&mut observer, 1);
    ip(&["link", "set", &host.link, "up"]);
    assert!((still - resting).abs() < 1e-3, "a chair whose agent is silent stands: {resting} → {still}");
    // The clock went on meanwhile (2 s at 20 ms a tick is 100 ticks; a loaded machine runs
    // fewer, but never stops).
    assert!(up_at >= cut_at + 25, "the hub's clock went on without the agent: tick {cut_at} → {up_at}");
    // Back on the link, the same agent drives it again.
    let start = std::time::Instant::now();
    loop {
        let (_, x) = tick_and_x(&mut observer, 1);
        if x > still + 0.2 {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "the agent never drove again: still at {x}");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(observer);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("the hub answers").status, 0);
    assert!(hub.wait(Duration::from_secs(30)).status.success());
    let a = agent.wait(Duration::from_secs(30));
    assert!(a.status.success(), "{}", agent_said.to_end(Duration::from_secs(5)).join("\n"));
    assert!(bridge.wait(Duration::from_secs(20)).status.success());
    let said = bridge_said.to_end(Duration::from_secs(5)).join("\n");
    assert!(said.contains("rest until it speaks"), "{said}");
    assert_no_shared_memory_left(&s);
}

#[test]
fn with_the_documented_tls_files_only_an_agent_holding_the_labs_certificate_gets_in() {
    // docs/zenoh.md's example: certificates made by docs/zenoh/make-certs.sh, the two documented
    // configuration files as they are, each process started where `certs/` is.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = work_dir("tls");
    let made = Command::new("bash")
        .arg(root.join("docs/zenoh/make-certs.sh"))
        .arg(dir.join("certs"))
        .output()
        .expect("bash runs");
    assert!(made.status.success(), "make-certs.sh: {}", text(&made.stderr));
    let s = session("zenoh-tls");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "100", "--wait-agents", "1"]);
    let endpoint = format!("tls/localhost:{}", free_port());
    let config = |name: &str| root.join("docs/zenoh").join(name).to_str().expect("utf-8").to_owned();
    let bridge_cfg = config("bridge-tls.json5");
    let mut bridge = Proc::spawn_at(
        &dir,
        &["zenoh", "--session", &s, "--listen", &endpoint, "--connect-timeout", "20", "--zenoh-config", &bridge_cfg],
    );
    bridge.announced("served under", Duration::from_secs(20));
    // An agent that trusts the lab's authority but holds no certificate of it is kept out
    // (mutual TLS): it gives up at its timeout and says why.
    std::fs::write(
        dir.join("no-client-cert.json5"),
        r#"{ transport: { link: { tls: { root_ca_certificate: "certs/ca.pem" } } } }"#,
    )
    .expect("written");
    let agent = |cfg: &str, timeout: &str| {
        Proc::spawn_at(
            &dir,
            &[
                "agent",
                "wheelchair",
                "--session",
                &s,
                "--zenoh",
                &endpoint,
                "--connect-timeout",
                timeout,
                "--zenoh-config",
                cfg,
            ],
        )
        .wait(Duration::from_secs(60))
    };
    let stranger = agent("no-client-cert.json5", "2");
    assert!(!stranger.status.success());
    assert!(text(&stranger.stderr).contains(&format!("connect to {endpoint}")), "{}", text(&stranger.stderr));
    // The documented agent file: it checks the bridge, shows its own certificate, drives.
    let listed = agent(&config("agent-tls.json5"), "20");
    assert!(listed.status.success(), "{}", text(&listed.stderr));
    let h = hub.wait(Duration::from_secs(60));
    assert!(h.status.success(), "{}", text(&h.stderr));
    assert!(text(&h.stdout).contains("tick 100 "), "{}", text(&h.stdout));
    assert!(bridge.wait(Duration::from_secs(20)).status.success());
    let _ = std::fs::remove_dir_all(&dir);
    assert_no_shared_memory_left(&s);
}

#[test]
fn an_episode_that_reached_its_time_limit_still_answers_its_end_with_its_summary() {
    // An episode host here, an environment's queries from this test, a lab sent along.
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut host = Proc::spawn(&["env-host", "--listen", &endpoint]);
    host.announced("episodes served under", Duration::from_secs(20));
    let episodes =
        agent_sdk::remote::EpisodeHost::connect(&agent_sdk::remote::Remote::new(&endpoint), Duration::from_secs(20))
            .expect("the host answers");
    let lab = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("hub/world/maps/liacc-lab.xml")).expect("lab");
    let s = episodes.start(&["--ticks".into(), "40".into()], Some(lab)).expect("an episode starts");
    // The host keeps the sent lab while the episode runs, and removes it when it has reaped it.
    let lab_file = std::env::temp_dir().join(format!("iwsim-episodes-{}", host.pid())).join(format!("{s}.xml"));
    assert!(lab_file.exists(), "{} while the episode runs", lab_file.display());
    // An agent drives the episode to its time limit and leaves.
    let agent = Proc::spawn(&[
        "agent",
        "wheelchair",
        "--session",
        &s,
        "--zenoh",
        &endpoint,
        "--connect-timeout",
        "20",
        "--pose",
        "10,6.1,0",
    ])
    .wait(Duration::from_secs(60));
    assert!(agent.status.success(), "{}", text(&agent.stderr));
    let start = std::time::Instant::now();
    while lab_file.exists() {
        assert!(start.elapsed() < Duration::from_secs(30), "the ended episode was never reaped");
        std::thread::sleep(Duration::from_millis(20));
    }
    // Ended long before the environment asks: its summary is still there, once.
    let summary = run_records::outcome::HubOutcome::from_stdout(&episodes.end(&s).expect("the host answers"))
        .expect("the hub's summary");
    assert_eq!(summary.ticks, 40);
    let again = episodes.end(&s).expect_err("an episode ends once");
    assert!(again.to_string().contains("no episode"), "{again}");
    drop(episodes);
    host.signal("TERM");
    assert!(host.wait(Duration::from_secs(30)).status.success());
    assert_no_shared_memory_left(&s);
}
