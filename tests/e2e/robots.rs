//! Robots across processes: the bounds on a robot's body, speed and sensors hold on every way
//! in (the SDK, an agent's options, the UDP bridge), and a killed agent's robot goes back to
//! the agent restarted in its place.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use agent_sdk::{Agent, AgentError, control};
use ipc_types::{Command as Cmd, ROBOT_FROZEN, Refusal, RobotRegistration, RobotState, SensorSpec};
use observer::Observer;
use run_records::outcome::HubOutcome;

use super::common::{Proc, assert_no_shared_memory_left, robot_names, session, text, wait_for_tick};

/// Sends one datagram to `to` and returns the first reply, without its trailing NUL.
fn udp_exchange(sock: &UdpSocket, to: SocketAddr, datagram: &str) -> String {
    sock.send_to(datagram.as_bytes(), to).expect("send");
    let mut buf = [0u8; 65536];
    let (n, _) = sock.recv_from(&mut buf).expect("a reply within 5 s");
    String::from_utf8_lossy(&buf[..n.saturating_sub(1)]).into_owned()
}

#[test]
fn robots_past_the_size_speed_and_range_limits_are_refused_on_every_way_in() {
    let s = session("limits");
    let hub = Proc::spawn(&["hub", "--session", &s]);
    let mut probe = Agent::connect_within(&s, "probe", Duration::from_secs(20)).expect("hub comes up");

    // Through the SDK: a typed refusal naming the field and its range.
    let mut far_sensor = RobotRegistration::new("far-sighted");
    far_sensor.sensors[0] = SensorSpec { x_m: 0.5, y_m: 0.0, angle_deg: 0.0, cone_deg: 60.0, range_m: 25.0 };
    far_sensor.sensor_count = 1;
    for (reg, says) in [
        (
            RobotRegistration::new("huge").body(10_000.0, 1.0, 0.5),
            "width = 10000 is out of range: expected in (0, 5] m",
        ),
        (RobotRegistration::new("wide").body(1.0, 5.5, 0.5), "height = 5.5 is out of range: expected in (0, 5] m"),
        (RobotRegistration::new("fast").motors(6.0, 0.5), "max_speed = 6 is out of range: expected in (0, 5] m/s"),
        (far_sensor, "sensor range = 25 on sensor 0: expected in (0, 20] m"),
    ] {
        match probe.register(&reg) {
            Err(AgentError::Refused { reason: Refusal::BadParameters, detail }) => {
                assert!(detail.contains(says), "{detail:?} should say {says:?}")
            }
            other => panic!("{:?} registered: {other:?}", reg.name.as_str()),
        }
    }
    // At the limits a robot is welcome.
    let largest =
        RobotRegistration::new("largest").id(5).body(5.0, 5.0, 0.5).motors(5.0, 0.5).at(Some([20.0, 6.1, 0.0]));
    assert!(probe.register(&largest).is_ok());

    // Through an agent's options: it exits with the hub's reason.
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--width", "6", "--powers", "0,0"]);
    let out = agent.wait(Duration::from_secs(20));
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("width = 6 is out of range"), "{}", text(&out.stderr));

    // Through the UDP bridge, the `<Robot Width="10000">` of issue 16: refused like any bad robot.
    let mut bridge = Proc::spawn(&["udp", "--session", &s, "--port", "0"]);
    let addr: SocketAddr = bridge.announced("registrations on ", Duration::from_secs(20)).parse().expect("address");
    let client = UdpSocket::bind("127.0.0.1:0").expect("bind");
    client.set_read_timeout(Some(Duration::from_secs(5))).expect("timeout");
    for robot in [r#"<Robot Name="huge" Id="1" Width="10000"/>"#, r#"<Robot Name="fast" Id="1" MaxSpeed="50"/>"#] {
        assert_eq!(udp_exchange(&client, addr, robot), "<Reply Status=\"Refused\"></Reply>\n", "{robot}");
    }
    let ok = udp_exchange(&client, addr, r#"<Robot Name="fits" Id="1" Width="1.2" Height="0.7"/>"#);
    assert!(ok.starts_with("<Reply Status=\"Ok\">"), "{ok}");

    // Only the robots within the limits are in the world (in id order).
    let mut observer = Observer::connect_within(&s, "observer", Duration::from_secs(5)).expect("hub answers");
    let start = Instant::now();
    loop {
        let (_, robots) = observer.world().expect("snapshot");
        let names = robot_names(&mut observer, &robots);
        if names == ["fits", "largest"] {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "robots in the world: {names:?}");
        std::thread::sleep(Duration::from_millis(5));
    }
    observer.close();
    probe.close();

    // The hub's exit and what it printed tell why, should it not answer.
    let stop = control(&s, Cmd::Stop, 0);
    let h = hub.wait(Duration::from_secs(10));
    assert!(matches!(&stop, Ok(r) if r.status == 0), "stop: {stop:?}; hub ({}): {}", h.status, text(&h.stderr));
    assert!(h.status.success(), "{}", text(&h.stderr));
    let b = bridge.wait(Duration::from_secs(10));
    assert!(b.status.success(), "bridge: {}", text(&b.stderr));
    assert_no_shared_memory_left(&s);
}

/// Robot 1 in the latest snapshot once `done` holds for it, polling for up to 20 s.
fn robot_one_when(observer: &mut Observer, what: &str, done: impl Fn(&RobotState, usize) -> bool) -> RobotState {
    let start = Instant::now();
    loop {
        let (h, robots) = observer.world().expect("snapshot");
        if let Some(r) = robots.iter().find(|r| r.id == 1)
            && done(r, robots.len())
        {
            return *r;
        }
        assert!(start.elapsed() < Duration::from_secs(20), "at tick {}, robot 1 never {what}: {robots:?}", h.tick);
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_restarted_agent_takes_back_the_robot_its_killed_predecessor_left_frozen() {
    let s = session("restart");
    let hub =
        Proc::spawn(&["hub", "--session", &s, "--lockstep", "--wait-agents", "1", "--deadline-ms", "20000", "--json"]);
    let chair = |powers: &str| {
        ["agent", "wheelchair", "--session", &s, "--id", "1", "--name", "chair", powers].map(String::from)
    };
    let first_args = chair("--powers=0.5,0.5");
    let mut first = Proc::spawn(&first_args.each_ref().map(String::as_str));
    let mut observer = wait_for_tick(&s, 20, Duration::from_secs(20));
    first.kill9();
    let frozen = robot_one_when(&mut observer, "froze", |r, _| r.flags & ROBOT_FROZEN != 0);

    // Its successor backs the chair up: the hub's motor outputs follow the new agent's powers
    // (whether or not a wall stops the chair), and the lock-step run steps for it.
    let second_args = chair("--powers=-0.5,-0.5");
    let second = Proc::spawn(&second_args.each_ref().map(String::as_str));
    let back = robot_one_when(&mut observer, "obeyed its new agent", |r, n| {
        r.flags & ROBOT_FROZEN == 0 && r.agent_id != frozen.agent_id && r.motor_out.iter().all(|&p| p < -0.25) && n == 1
    });
    assert_eq!(back.id, frozen.id, "the same robot, not a fresh one beside it");
    let (_, robots) = observer.world().expect("snapshot");
    assert_eq!(robot_names(&mut observer, &robots), ["chair1"]);
    observer.close();

    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(10));
    let json = text(&out.stdout);
    assert!(out.status.success(), "{json}{}", text(&out.stderr));
    let outcome = HubOutcome::from_stdout(&json).expect("the hub's JSON line");
    assert_eq!((outcome.agents_died, outcome.robots.len()), (1, 1), "{json}");
    assert!(second.wait(Duration::from_secs(10)).status.success());
    assert_no_shared_memory_left(&s);
}

/// The newest world snapshot, waiting for one past `after`.
fn world_after(observer: &mut Observer, after: u64) -> (u64, Vec<RobotState>) {
    let start = Instant::now();
    loop {
        if let Some((h, robots)) = observer.try_world().expect("world")
            && h.tick > after
        {
            return (h.tick, robots);
        }
        assert!(start.elapsed() < Duration::from_secs(20), "the hub stayed at tick {after}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn a_process_acting_in_another_agents_name_changes_nothing() {
    use ipc_services::{Role, SLICE_ALLOCATION, Session};
    use ipc_types::{ActionBlock, ActionHeader, RegisterKind, RegisterRequest};

    let s = session("spoof");
    let hub =
        Proc::spawn(&["hub", "--session", &s, "--lockstep", "--wait-agents", "1", "--deadline-ms", "20000", "--json"]);
    // The victim: a real agent process holding its chair still.
    let victim = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--id", "1", "--name", "chair", "--powers=0,0"]);
    let mut observer = Observer::connect_within(&s, "spoof-observer", Duration::from_secs(20)).expect("hub comes up");
    let (mut tick, robots) = world_after(&mut observer, 5);
    let before = robots.iter().find(|r| r.id == 1).copied().expect("the victim's chair");
    let victim_agent = before.agent_id;

    // The spoofer (this test's process): its own ports, the victim's agent id.
    let session = Session::new(&s).expect("session");
    let node = session.node("spoofer").expect("node");
    let actions = session.actions(&node, Role::Client).expect("actions service");
    let publisher = actions
        .publisher_builder()
        .initial_max_slice_len(4)
        .allocation_strategy(SLICE_ALLOCATION)
        .create()
        .expect("a publisher");
    let doorbell =
        session.hub_event(&node, Role::Client).expect("doorbell").notifier_builder().create().expect("notifier");
    let register = session.register(&node, Role::Client).expect("register").client_builder().create().expect("client");
    let ask = |kind: RegisterKind| {
        let req = RegisterRequest {
            kind: kind as u32,
            pid: victim.pid(),
            agent_id: victim_agent,
            _reserved: 0,
            actions_publisher: [0, 0],
            robot: RobotRegistration::new("intruder"),
        };
        let pending = register.send_copy(req).expect("sent");
        doorbell.notify().expect("rang");
        let start = Instant::now();
        loop {
            if let Some(r) = pending.receive().expect("receive") {
                return *r.payload();
            }
            assert!(start.elapsed() < Duration::from_secs(10), "the hub did not answer a {kind:?}");
            std::thread::sleep(Duration::from_millis(1));
        }
    };
    // A robot registered and a goodbye said in the victim's name are refused.
    assert_eq!(Refusal::from_u32(ask(RegisterKind::Robot).status), Some(Refusal::NotYours));
    assert_eq!(Refusal::from_u32(ask(RegisterKind::Bye).status), Some(Refusal::NotYours));

    // Full power in the victim's name, 50 times, each for the tick in hand as the victim does.
    for _ in 0..50 {
        let mut sample = publisher.loan_slice_uninit(1).expect("loan");
        *sample.user_header_mut() = ActionHeader { tick, agent_id: victim_agent, count: 1 };
        sample.write_from_slice(&[ActionBlock::motors(1, 1.0, 1.0)]).send().expect("sent");
        doorbell.notify().expect("rang");
        let (now, robots) = world_after(&mut observer, tick);
        let chair = robots.iter().find(|r| r.id == 1).expect("the chair is still there");
        assert_eq!(chair.motor_out, [0.0, 0.0], "tick {now}: the spoofed powers reached the motors");
        assert_eq!((chair.x_m, chair.y_m, chair.heading_deg), (before.x_m, before.y_m, before.heading_deg));
        assert_eq!(chair.agent_id, victim_agent);
        tick = now;
    }
    drop((publisher, doorbell, register, actions, node));

    observer.close();
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(10));
    let json = text(&out.stdout);
    assert!(out.status.success(), "{json}{}", text(&out.stderr));
    let outcome = HubOutcome::from_stdout(&json).expect("the hub's JSON line");
    assert!(outcome.foreign_dropped >= 52, "every spoofed request and action counted: {json}");
    assert_eq!(outcome.robots.len(), 1, "{json}");
    assert!(victim.wait(Duration::from_secs(10)).status.success(), "the victim ran to the end");
    drop(session);
    assert_no_shared_memory_left(&s);
}

#[test]
fn an_agent_gets_the_map_without_the_obstacles_and_an_observer_with_them() {
    let s = session("truthmap");
    let hub = Proc::spawn(&["hub", "--session", &s, "--obstacle", "17,6.1,17.6,6.4", "--obstacle", "19.4,5.5,20,5.9"]);
    let agent = Agent::connect_within(&s, "map-agent", Duration::from_secs(20)).expect("hub comes up");
    let observer = Observer::connect_within(&s, "map-observer", Duration::from_secs(20)).expect("hub comes up");
    let (mine, truth) = (agent.map().expect("the agents' map"), observer.map().expect("the observers' map"));
    assert_eq!(truth.walls.len(), mine.walls.len() + 2, "the observer sees the two obstacles");
    assert!(mine.walls.iter().all(|w| !w.obstacle), "the agent's map has no obstacle");
    assert_eq!(truth.walls.iter().filter(|w| w.obstacle).count(), 2);
    agent.close();
    observer.close();
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    assert!(hub.wait(Duration::from_secs(10)).status.success());
    assert_no_shared_memory_left(&s);
}

#[test]
fn a_real_robot_is_taken_only_under_an_expected_name_and_never_teleported() {
    // Issue 27: a Real robot's agent pushes its pose, so an agent that could register one
    // anywhere and move it anywhere would map the lab with its collision flag. The hub takes a
    // Real robot only under a `--real` name, and refuses (and counts) a pose its body could
    // not have reached.
    let s = session("real-bounds");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--ticks",
        "6",
        "--wait-agents",
        "1",
        "--real",
        "bench",
        "--json",
    ]);
    let mut me = Agent::connect_within(&s, "real-probe", Duration::from_secs(20)).expect("hub comes up");
    let real = |name: &str| {
        let mut reg = RobotRegistration::new(name);
        reg.kind = ipc_types::RobotKind::Real as u32;
        reg.flags |= ipc_types::REG_HAS_POSE;
        reg.pose = [10.0, 6.1, 0.0];
        reg
    };
    match me.register(&real("ghost")) {
        Err(AgentError::Refused { reason: Refusal::NotAllowed, detail }) => {
            assert!(detail.contains("--real NAME") && detail.contains("\"ghost\""), "{detail}")
        }
        other => panic!("a Real robot under an unexpected name was not refused: {other:?}"),
    }
    let id = me.register(&real("bench")).expect("the expected Real robot");
    me.ready().expect("ready");
    let mut observer = Observer::connect_within(&s, "real-observer", Duration::from_secs(20)).expect("observer");
    while let Some(tick) = me.wait_tick(agent_sdk::Wait::Blocking).expect("hub alive") {
        // A lock-step hub says so in every tick (the navigator then searches unbounded).
        assert!(tick.lockstep, "tick {} of a lock-step hub", tick.tick);
        // Every tick, a push 5 m away: across the corridor, through walls.
        me.send(tick.tick, &[ipc_types::ActionBlock::pose(id, 15.0, 6.1, 0.0)]).expect("sent");
    }
    let (_, robots) = observer.world().expect("the last world");
    observer.close();
    me.close();
    let r = robots.iter().find(|r| r.id == id).expect("the bench robot");
    assert_eq!((r.x_m, r.y_m), (10.0, 6.1), "the teleport was taken");
    let out = hub.wait(Duration::from_secs(20));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let outcome = HubOutcome::from_stdout(&text(&out.stdout)).expect("the hub's outcome");
    assert!(outcome.refused_poses >= 5, "refused and counted: {outcome:?}");
    assert_no_shared_memory_left(&s);
}
