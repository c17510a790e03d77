//! The shared-memory hub across real processes: each test runs `iwsim hub` and agents as
//! separate processes in a session of its own, so tests run in parallel without crossing.

use std::time::{Duration, Instant};

use super::common::{Proc, assert_no_shared_memory_left, session, text, truth, wait_for_tick};

use agent_sdk::{Agent, AgentError, Wait, control};
use ipc_types::{Command as Cmd, REG_HAS_POSE, ROBOT_FROZEN, Refusal, RobotRegistration};
use run_records::outcome::{HubOutcome, StateHash};
use world::map::{NoiseParams, Params, builtin};
use world::{Action, RobotSpec, World};

#[test]
fn an_agent_drives_and_the_hubs_pose_matches_the_world_model() {
    let s = session("pose");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "40",
        "--wait-agents",
        "1",
        "--no-noise",
        "--json",
    ]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--pose", "10,6.1,0", "--powers", "1,0.6"]);
    let out = hub.wait(Duration::from_secs(30));
    let json = text(&out.stdout);
    assert!(out.status.success(), "{json}{}", text(&out.stderr));
    assert!(agent.wait(Duration::from_secs(10)).status.success());
    let outcome = HubOutcome::from_stdout(&json).expect("the hub's JSON line");

    // The same robot and actions stepped in this process.
    let map = builtin::map("liacc").expect("built in");
    let mut world = World::new(&map.lab, Params { noise: NoiseParams::NONE, ..Params::default() }, 1).expect("valid");
    let r = world.add_robot(RobotSpec::at(10.0, 6.1, 0.0).named("chair1")).expect("free");
    for _ in 0..40 {
        world.step(&[Action::motors(r, 1.0, 0.6)], 0.1);
    }
    let pose = world.robot(r).expect("alive").pose;
    assert_eq!(outcome.ticks, 40);
    assert_eq!((outcome.robots.len(), outcome.robots[0].x_m, outcome.robots[0].y_m), (1, pose.x, pose.y), "{json}");
    assert_eq!(outcome.state_hash, StateHash(world.state_hash()));
    // Compared by eye across runs and machines: 16 hex digits, as a string.
    assert!(json.contains(&format!("\"state_hash\":\"{:016x}\"", world.state_hash())), "{json}");
}

fn lockstep_hash(seed: u64) -> String {
    let s = session("det");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "60",
        "--wait-agents",
        "2",
        "--seed",
        &seed.to_string(),
        "--json",
    ]);
    let a = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "2", "--id", "1", "--powers", "0.8,0.5"]);
    let b = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "2", "--id", "3", "--powers", "0.3,0.9"]);
    let out = hub.wait(Duration::from_secs(30));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(a.wait(Duration::from_secs(10)).status.success());
    assert!(b.wait(Duration::from_secs(10)).status.success());
    let outcome = HubOutcome::from_stdout(&text(&out.stdout)).expect("the hub's JSON line");
    assert_eq!(outcome.ticks, 60);
    outcome.state_hash.to_string()
}

#[test]
fn lockstep_runs_across_processes_are_deterministic_per_seed() {
    let first = lockstep_hash(7);
    let second = lockstep_hash(7);
    let other = lockstep_hash(8);
    assert_eq!(first, second, "same seed, same final state");
    assert_ne!(first, other, "another seed, other noise");
}

#[test]
fn a_killed_agent_is_frozen_and_flagged_and_the_run_goes_on() {
    let s = session("kill-agent");
    let hub =
        Proc::spawn(&["hub", "--session", &s, "--lockstep", "--wait-agents", "2", "--deadline-ms", "20000", "--json"]);
    let a = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--id", "1", "--powers", "0.5,0.5"]);
    let mut b = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--id", "2", "--powers", "0.5,0.5"]);
    let mut observer = wait_for_tick(&s, 20, Duration::from_secs(20));
    b.kill9();
    let (at_kill, _) = observer.world().expect("snapshot");
    // With a 20 s deadline, a hub that waited for the dead agent would stall for 20 s a tick:
    // it must notice the death and go on at once.
    let start = Instant::now();
    loop {
        let (h, robots) = observer.world().expect("snapshot");
        if h.tick >= at_kill.tick + 200 {
            let frozen = robots.iter().find(|r| r.id == 2).expect("robot 2 stays in the world");
            assert_ne!(frozen.flags & ROBOT_FROZEN, 0, "robot 2 is flagged frozen");
            assert_eq!(robots.iter().find(|r| r.id == 1).expect("robot 1").flags & ROBOT_FROZEN, 0);
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "the run stalled at tick {} after the kill", h.tick);
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(observer);
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(10));
    let json = text(&out.stdout);
    assert!(out.status.success(), "{json}{}", text(&out.stderr));
    assert_eq!(HubOutcome::from_stdout(&json).expect("the hub's JSON line").agents_died, 1);
    assert!(a.wait(Duration::from_secs(10)).status.success());
}

#[test]
fn a_killed_hub_makes_its_agents_exit_with_a_message_within_5_s() {
    let s = session("kill-hub");
    let mut hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20"]);
    let mut agent = Proc::spawn(&["agent", "wheelchair", "--session", &s]);
    let observer = wait_for_tick(&s, 5, Duration::from_secs(20));
    drop(observer);
    hub.kill9();
    let killed = Instant::now();
    let out = {
        let a = std::mem::replace(&mut agent, Proc(None));
        a.wait(Duration::from_secs(10))
    };
    assert!(killed.elapsed() < Duration::from_secs(5), "agent took {:?}", killed.elapsed());
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("has exited"), "{}", text(&out.stderr));
}

#[test]
fn two_sessions_side_by_side_do_not_interfere() {
    let (s1, s2) = (session("side1"), session("side2"));
    let args = |s: &str| {
        vec![
            "hub".to_owned(),
            "--session".into(),
            s.into(),
            "--lockstep".into(),
            "--ticks".into(),
            "30".into(),
            "--wait-agents".into(),
            "1".into(),
            "--no-noise".into(),
            "--json".into(),
        ]
    };
    let a1: Vec<String> = args(&s1);
    let a2: Vec<String> = args(&s2);
    let h1 = Proc::spawn(&a1.iter().map(String::as_str).collect::<Vec<_>>());
    let h2 = Proc::spawn(&a2.iter().map(String::as_str).collect::<Vec<_>>());
    let g1 = Proc::spawn(&["agent", "wheelchair", "--session", &s1, "--pose", "10,6.1,0", "--powers", "1,1"]);
    let g2 = Proc::spawn(&["agent", "wheelchair", "--session", &s2, "--pose", "10,6.1,0", "--powers", "-1,-1"]);
    let (o1, o2) = (h1.wait(Duration::from_secs(30)), h2.wait(Duration::from_secs(30)));
    let (j1, j2) = (text(&o1.stdout), text(&o2.stdout));
    let outcome = |j: &str| HubOutcome::from_stdout(j).unwrap_or_else(|e| panic!("{e}: {j}"));
    let (o1, o2) = (outcome(&j1), outcome(&j2));
    assert_eq!((o1.agents_seen, o2.agents_seen), (1, 1));
    let (x1, x2) = (o1.robots[0].x_m, o2.robots[0].x_m);
    assert!(x1 > 10.5 && x2 < 9.9 || x2 < 10.0, "forward in one, backward in the other: {x1} {x2}");
    assert!(x1 > 10.5, "{j1}");
    assert!(g1.wait(Duration::from_secs(10)).status.success());
    assert!(g2.wait(Duration::from_secs(10)).status.success());
}

#[test]
fn registration_refusals_come_back_as_typed_errors() {
    let s = session("refuse");
    let hub = Proc::spawn(&["hub", "--session", &s, "--start-on-command", "--max-robots", "2"]);
    let mut agent = Agent::connect_within(&s, "refusals", Duration::from_secs(20)).expect("hub comes up");
    let mut reg = RobotRegistration::new("one");
    reg.requested_id = 1;
    assert_eq!(agent.register(&reg).expect("accepted"), 1);
    match agent.register(&reg) {
        Err(AgentError::Refused { reason: Refusal::DuplicateId, .. }) => {}
        other => panic!("expected a duplicate-id refusal, got {other:?}"),
    }
    let mut bad = RobotRegistration::new("bad");
    bad.com = 1.5;
    match agent.register(&bad) {
        Err(AgentError::Refused { reason: Refusal::BadParameters, detail }) => {
            assert!(detail.contains("com"), "{detail}")
        }
        other => panic!("expected a bad-parameters refusal, got {other:?}"),
    }
    let mut far = RobotRegistration::new("far");
    far.requested_id = 50;
    match agent.register(&far) {
        Err(AgentError::Refused { reason: Refusal::NoSuchSlot, .. }) => {}
        other => panic!("expected a no-such-slot refusal, got {other:?}"),
    }
    far.flags = REG_HAS_POSE;
    far.pose = [20.0, 6.1, 0.0];
    assert_eq!(agent.register(&far).expect("a pose makes any id fine"), 50);
    match agent.register(&RobotRegistration::new("third")) {
        Err(AgentError::Refused { reason: Refusal::Capacity, .. }) => {}
        other => panic!("expected a capacity refusal, got {other:?}"),
    }
    let answer = control(&s, Cmd::Stop, 0).expect("hub answers");
    assert_eq!(answer.status, 0);
    drop(agent);
    assert!(hub.wait(Duration::from_secs(10)).status.success());
}

#[test]
fn registering_many_robots_republishes_the_world_once_not_once_per_robot() {
    // Enough that one republication per robot would stand out by far.
    const N: usize = 600;
    let s = session("many");
    let hub = Proc::spawn(&["hub", "--session", &s, "--start-on-command", "--json"]);
    let mut agent = Agent::connect_within(&s, "many", Duration::from_secs(20)).expect("hub comes up");
    let observer = observer::Observer::connect_within(&s, "many-observer", Duration::from_secs(20)).expect("attach");
    for i in 0..N {
        let pose = [1.0 + (i % 50) as f64 * 0.3, 1.0 + (i / 50) as f64 * 0.2, 0.0];
        agent.register(&RobotRegistration::new("r").disc(0.2).at(Some(pose))).expect("accepted");
    }
    // Without a Ready (or a tick), the registrations still reach the agent and observers once
    // they settle: the hub republishes tick 0 and rings it. Should it never do so, a watchdog
    // stops the hub after 10 s, which ends the agent's wait with an error.
    let (settled, watch) = std::sync::mpsc::channel::<()>();
    let watched = s.clone();
    let watchdog = std::thread::spawn(move || {
        if watch.recv_timeout(Duration::from_secs(10)).is_err() {
            let _ = control(&watched, Cmd::Stop, 0);
        }
    });
    while agent.sensors().len() < N {
        let tick = agent.wait_tick(Wait::Blocking).expect("the hub republishes once registrations settle");
        // A real-time hub does not wait for answers, and says so.
        assert!(tick.is_none_or(|t| !t.lockstep), "{tick:?}");
    }
    let _ = settled.send(());
    watchdog.join().expect("watchdog");
    let mut observer = observer;
    assert_eq!(observer.with_world(|_, robots| robots.len()).expect("snapshot"), N);
    agent.ready().expect("ready");
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    drop((agent, observer));
    let out = hub.wait(Duration::from_secs(20));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let outcome = HubOutcome::from_stdout(&text(&out.stdout)).expect("the hub's JSON line");
    assert_eq!((outcome.ticks, outcome.robots.len()), (0, N));
    // One republication per registration (the O(N²) set-up) would be at least N (603 with it
    // put back); registrations settle into a few: one, when the agent is never held up for
    // 2 ms between two. On a loaded machine the agent is descheduled for longer now and then
    // (32 pauses among 600 beside two busy loops), each a republication: a quarter of N
    // tells the two apart whatever the load.
    assert!(outcome.snapshots <= (N / 4) as u64, "{} snapshots published for {N} registrations", outcome.snapshots);
}

#[test]
fn a_restarted_hub_with_the_same_session_needs_no_cleanup() {
    let s = session("restart");
    let mut first = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20"]);
    drop(wait_for_tick(&s, 2, Duration::from_secs(20)));
    first.kill9();
    let second = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "5", "--ticks", "5"]);
    let out = second.wait(Duration::from_secs(20));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("tick 5 "), "{}", text(&out.stdout));
}

#[test]
fn sigterm_stops_hub_and_agent_cleanly_and_leaves_no_shared_memory() {
    let s = session("term");
    let mut hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "10"]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s]);
    let observer = wait_for_tick(&s, 3, Duration::from_secs(20));
    observer.close();
    hub.signal("TERM");
    let out = std::mem::replace(&mut hub, Proc(None));
    let out = out.wait(Duration::from_secs(10));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("stopped by a termination signal"));
    let a = agent.wait(Duration::from_secs(10));
    assert!(a.status.success(), "{}", text(&a.stderr));
    assert_no_shared_memory_left(&s);
    let _ = hub.stderr_now();
}

#[test]
fn a_hung_agent_is_stepped_past_at_the_deadline_and_flagged_lagging() {
    let s = session("hung");
    let hub =
        Proc::spawn(&["hub", "--session", &s, "--lockstep", "--wait-agents", "2", "--deadline-ms", "100", "--json"]);
    let a = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--id", "1"]);
    let b = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--id", "2"]);
    let mut observer = wait_for_tick(&s, 10, Duration::from_secs(20));
    // A stopped process is alive (its pidfd stays quiet) but never answers.
    b.signal("STOP");
    let (at_stop, _) = observer.world().expect("snapshot");
    let start = Instant::now();
    loop {
        let (h, robots) = observer.world().expect("snapshot");
        let lagging = robots.iter().find(|r| r.id == 2).is_some_and(|r| r.flags & ipc_types::ROBOT_LAGGING != 0);
        // Ten ticks past the stop: at 100 ms per missed deadline that takes about a second.
        if h.tick >= at_stop.tick + 10 && lagging {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "stuck at tick {} (lagging flag {lagging})", h.tick);
        std::thread::sleep(Duration::from_millis(5));
    }
    b.signal("CONT");
    drop(observer);
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(10));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(HubOutcome::from_stdout(&text(&out.stdout)).expect("the hub's JSON line").agents_died, 0);
    assert!(a.wait(Duration::from_secs(10)).status.success());
    let b_out = b.wait(Duration::from_secs(10));
    assert!(b_out.status.success(), "{}", text(&b_out.stderr));
}

/// The wheelchair agent's `kind = "real"` chair moves itself and pushes its poses, as a
/// physical chair's controller does. With the hub's noise on, the simulated chair's motors
/// are noisy while the real one, on the same script, follows the noiseless model exactly:
/// the hub takes its poses as they are.
#[test]
fn a_real_chair_pushes_its_own_poses_and_the_hub_takes_them() {
    let s = session("realchair");
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-realchair-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let config = dir.join("chairs.toml");
    let chair = |name: &str, kind: &str, x: f64| {
        format!(
            "[[chairs]]\nname = \"{name}\"\nkind = \"{kind}\"\npose = [{x}, 6.0, 0]\nbody = [0.6, 0.5, 0.5]\n\
             max_speed = 0.5\naccel_curve = 0.7\npowers = [0.7, 0.8]\n"
        )
    };
    std::fs::write(&config, chair("sim", "simulated", 12.0) + &chair("real", "real", 16.0)).expect("config written");
    let recording = dir.join("run.mcap");
    let rec = recording.to_str().expect("utf-8");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "40",
        "--wait-agents",
        "1",
        "--seed",
        "5",
        "--record",
        rec,
        "--real",
        "real",
    ]);
    let agent = Proc::spawn(&[
        "agent",
        "wheelchair",
        "--session",
        &s,
        "--config",
        config.to_str().expect("utf-8"),
        "--log",
        dir.to_str().expect("utf-8"),
    ]);
    let out = hub.wait(Duration::from_secs(30));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let a = agent.wait(Duration::from_secs(10));
    assert!(a.status.success(), "{}", text(&a.stderr));
    // Where the chairs truly were, tick by tick: the hub's record.
    let truth = truth(&recording);
    let track = |name: &str| truth[name].iter().map(|r| [r[1], r[2], r[3]]).collect::<Vec<_>>();
    let (sim, real) = (track("sim"), track("real"));
    assert!(sim.len() >= 40 && real.len() >= 40, "{} and {} rows", sim.len(), real.len());
    // The same chair and script, noiseless, in this process: row k of the track is the pose
    // after k ticks.
    let map = builtin::map("liacc").expect("built in");
    let mut world = World::new(&map.lab, Params { noise: NoiseParams::NONE, ..Params::default() }, 1).expect("valid");
    let r = world.add_robot(RobotSpec::at(16.0, 6.0, 0.0).body(0.6, 0.5, 0.5).motors(0.5, 0.7)).expect("free");
    let mut model = Vec::new();
    for _ in 0..real.len() {
        let p = world.robot(r).expect("alive").pose;
        model.push([p.x, p.y, p.heading_deg()]);
        world.step(&[Action::motors(r, 0.7, 0.8)], 0.1);
    }
    // It turned left as it went: the script is not trivially straight.
    let last = model[model.len() - 1];
    assert!(last[0] - 16.0 > 1.0 && last[1] - 6.0 > 0.05 && last[2] > 5.0, "{last:?}");
    // The agent computes with the hub's own formulas: equal to within rounding.
    for (k, (m, q)) in model.iter().zip(&real).enumerate() {
        let d = [q[0] - m[0], q[1] - m[1], q[2] - m[2]];
        assert!(d[0].abs() <= 1e-9 && d[1].abs() <= 1e-9 && d[2].abs() <= 1e-7, "tick {k}: model {m:?}, real {q:?}");
    }
    // The simulated chair's noisy motors took it elsewhere.
    let (p, m) = (sim[sim.len() - 1], last);
    let off = ((p[0] - 12.0) - (m[0] - 16.0)).hypot(p[1] - m[1]);
    assert!(off > 0.002, "the simulated chair ended {off} m from the noiseless path");
    let _ = std::fs::remove_dir_all(dir);
}
