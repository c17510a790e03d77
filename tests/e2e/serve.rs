//! `iwsim replay FILE --serve`: a recorded run played as a live session. Observers see the
//! recorded world tick for tick, bit for bit; run control pauses, steps, resumes and stops it;
//! robots are refused; the UDP bridge serves it to Ciber-Rato viewers; every process ends
//! cleanly and leaves nothing in /dev/shm.

use std::collections::BTreeMap;
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use agent_sdk::AgentError;
use ipc_types::{Command, Refusal, RobotRegistration, RobotState, RunState, WorldHeader};
use observer::Observer;
use run_records::outcome::HubOutcome;

use super::common::{Proc, assert_no_shared_memory_left, robot_names, session, text, truth};

const WAIT: Duration = Duration::from_secs(30);

/// Records a 100-tick lock-step run of two wheelchairs to a file of its own.
fn record_run(tag: &str) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-serve-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("run.mcap");
    let s = session(&format!("serve-rec-{tag}"));
    let f = file.to_str().expect("utf-8");
    let hub =
        Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "100", "--wait-agents", "1", "--record", f]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "2", "--powers=0.5,0.4"]);
    let h = hub.wait(WAIT);
    assert!(h.status.success(), "hub: {}", text(&h.stderr));
    let a = agent.wait(WAIT);
    assert!(a.status.success(), "agent: {}", text(&a.stderr));
    assert_no_shared_memory_left(&s);
    (dir, file)
}

/// Where each robot truly was at `tick` by name: `[x, y, heading°]` from the recording.
fn truth_at(truth: &BTreeMap<String, Vec<[f64; 4]>>, name: &str, tick: u64) -> [f64; 3] {
    let row = truth[name].iter().find(|r| r[0] == tick as f64).unwrap_or_else(|| panic!("{name} at tick {tick}"));
    [row[1], row[2], row[3]]
}

/// Asserts a snapshot's robots stand exactly where the recording has them.
/// The robots are named from the info the replay publishes beside the world.
fn assert_matches_truth(
    o: &mut Observer,
    truth: &BTreeMap<String, Vec<[f64; 4]>>,
    h: &WorldHeader,
    robots: &[RobotState],
) {
    assert_eq!(robots.len(), truth.len(), "tick {}: every recorded robot", h.tick);
    for (r, name) in robots.iter().zip(robot_names(o, robots)) {
        assert_eq!([r.x_m, r.y_m, r.heading_deg], truth_at(truth, &name, h.tick), "{name} at tick {}", h.tick);
    }
}

/// The next snapshot newer than `after` (or in another run state), within `WAIT`.
fn next_world(o: &mut Observer, after: &WorldHeader) -> (WorldHeader, Vec<RobotState>) {
    let start = Instant::now();
    loop {
        if let Some((h, robots)) = o.try_world().expect("the replay serves")
            && (h.tick != after.tick || h.run_state != after.run_state)
        {
            return (h, robots);
        }
        assert!(start.elapsed() < WAIT, "no snapshot after tick {} within {WAIT:?}", after.tick);
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn control(s: &str, command: Command) -> ipc_types::ControlResponse {
    let r = agent_sdk::control(s, command, 0).expect("the replay answers");
    assert_eq!(r.status, 0, "{command:?}");
    r
}

#[test]
fn a_served_replay_shows_the_recorded_run_bit_for_bit_obeys_commands_and_takes_no_robots() {
    let (dir, file) = record_run("bits");
    let f = file.to_str().expect("utf-8");
    let truth = truth(&file);
    assert_eq!(truth.len(), 2, "two chairs recorded");
    let end = Proc::spawn(&["replay", f, "--json"]).wait(WAIT);
    assert!(end.status.success(), "{}", text(&end.stderr));
    let end = HubOutcome::from_stdout(&text(&end.stdout)).expect("the replay's JSON line");
    assert_eq!(end.ticks, 100);

    let s = session("serve");
    let mut replay = Proc::spawn(&["replay", f, "--serve", "--session", &s, "--speed", "20", "--start-on-command"]);
    let stderr = replay.stderr_lines();
    let mut o = Observer::connect_within(&s, "serve-test", WAIT).expect("the replay comes up");

    // The observers' map is the recorded lab.
    let map = o.map().expect("the map");
    assert_eq!((map.name.as_str(), map.header.wall_count), ("IW_LIACC", 23));

    // Waiting at tick 0, the chairs where the recording starts.
    let (h, robots) = o.world().expect("the kept snapshot");
    assert_eq!((h.tick, h.run_state), (0, RunState::Waiting as u32));
    assert_matches_truth(&mut o, &truth, &h, &robots);

    // A session served by a replay is refused to another, as to a second hub.
    let twice = Proc::spawn(&["replay", f, "--serve", "--session", &s]).wait(WAIT);
    assert!(!twice.status.success());
    assert!(text(&twice.stderr).contains("already serves session"), "{}", text(&twice.stderr));

    // An agent may attach, but a recorded world takes no robots.
    let mut agent = agent_sdk::Agent::connect_within(&s, "intruder", WAIT).expect("hello answered");
    match agent.register(&RobotRegistration::new("intruder")) {
        Err(AgentError::Refused { reason, detail }) => {
            assert_eq!((reason, detail.as_str()), (Refusal::RunStarted, "a replay takes no robots"));
        }
        other => panic!("a robot registration was not refused: {other:?}"),
    }
    agent.close();

    // One step at a time while waiting, then paused.
    assert_eq!(control(&s, Command::Step).run_state, RunState::Waiting as u32);
    let (h, robots) = next_world(&mut o, &h);
    assert_eq!(h.tick, 1);
    assert_matches_truth(&mut o, &truth, &h, &robots);

    // Resumed: every snapshot seen matches the recording at its tick, to the end.
    control(&s, Command::Start);
    let mut last = h;
    let mut seen = 1;
    let (h, robots) = loop {
        let (h, robots) = next_world(&mut o, &last);
        assert_matches_truth(&mut o, &truth, &h, &robots);
        seen += 1;
        if h.run_state == RunState::Finished as u32 {
            break (h, robots);
        }
        last = h;
    };
    assert_eq!(h.tick, 100);
    assert!(seen > 2, "the run was played, not jumped to its end");
    let at_end: Vec<[f64; 4]> = robots.iter().map(|r| [r.id as f64, r.x_m, r.y_m, r.heading_deg]).collect();
    let replayed: Vec<[f64; 4]> = end.robots.iter().map(|r| [r.id as f64, r.x_m, r.y_m, r.heading_deg]).collect();
    assert_eq!(at_end, replayed, "the last snapshot is `iwsim replay --json`'s end, bit for bit");
    assert_eq!(h.state_hash, end.state_hash.0);
    o.close();

    let out = replay.wait(WAIT);
    let err = stderr.to_end(Duration::from_secs(10));
    assert!(out.status.success(), "{err:?}");
    assert!(text(&out.stdout).contains("served 100 ticks"), "{}", text(&out.stdout));
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_looping_replay_reaches_udp_viewers_through_the_bridge_and_a_stop_ends_everything() {
    let (dir, file) = record_run("udp");
    let names: Vec<String> = truth(&file).into_keys().collect();
    let s = session("serve-udp");
    let replay = Proc::spawn(&[
        "replay",
        file.to_str().expect("utf-8"),
        "--serve",
        "--session",
        &s,
        "--speed",
        "5",
        "--loop",
        "--start-on-command",
    ]);
    let mut bridge = Proc::spawn(&["udp", "--session", &s, "--port", "0"]);
    let reg: SocketAddr =
        bridge.announced("registrations on ", WAIT).parse().expect("the bridge says where it listens");

    let viewer = UdpSocket::bind("127.0.0.1:0").expect("bind");
    viewer.set_read_timeout(Some(Duration::from_secs(5))).expect("timeout");
    viewer.send_to(b"<View/>", reg).expect("send");
    let reply = receive(&viewer);
    assert!(reply.starts_with("<Reply Status=\"Ok\">"), "{reply}");
    control(&s, Command::Start);
    // A <Robot> per recorded chair per tick, named as recorded.
    let start = Instant::now();
    let mut named = std::collections::BTreeSet::new();
    while named.len() < names.len() {
        assert!(start.elapsed() < WAIT, "viewer saw only {named:?} of {names:?}");
        let d = receive(&viewer);
        if let Some(name) = d.strip_prefix("<Robot Name=\"").and_then(|r| r.split('"').next()) {
            assert!(names.iter().any(|n| n == name), "{name} is not a recorded chair: {d}");
            named.insert(name.to_owned());
        }
    }

    control(&s, Command::Stop);
    let r = replay.wait(WAIT);
    assert!(r.status.success(), "replay: {}", text(&r.stderr));
    let b = bridge.wait(WAIT);
    assert!(b.status.success(), "bridge: {}", text(&b.stderr));
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}

/// The next datagram (within 5 s), without its closing newline and NUL.
fn receive(sock: &UdpSocket) -> String {
    let mut buf = [0u8; 65536];
    let (n, _) = sock.recv_from(&mut buf).expect("a datagram within 5 s");
    String::from_utf8_lossy(&buf[..n]).trim_end_matches(['\0', '\n']).to_owned()
}

#[test]
fn a_speed_of_zero_is_refused_in_one_line() {
    let out = Proc::spawn(&["replay", "missing.mcap", "--serve", "--speed", "0"]).wait(WAIT);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    let first = err.lines().next().unwrap_or_default();
    assert!(first.contains("--speed") && first.contains("above 0"), "{err}");
}

#[test]
fn sigint_ends_a_served_replay_cleanly() {
    let (dir, file) = record_run("sigint");
    let s = session("serve-int");
    let replay = Proc::spawn(&["replay", file.to_str().expect("utf-8"), "--serve", "--session", &s, "--loop"]);
    let mut o = Observer::connect_within(&s, "serve-int", WAIT).expect("the replay comes up");
    let (h, _) = o.world().expect("a snapshot");
    next_world(&mut o, &h); // playing
    o.close();
    replay.signal("INT");
    let out = replay.wait(WAIT);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("stopped by a termination signal"), "{}", text(&out.stdout));
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}
