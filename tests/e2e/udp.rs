//! The UDP/XML bridge over real sockets on 127.0.0.1: registration, Measures, viewers,
//! foreign datagrams and malformed input, with a hub and the bridge as real processes.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use world::map::{NoiseParams, Params, builtin};
use world::math::Pose;
use world::{Action, RobotSpec, World};

use super::common::{Proc, hub_and_logged_bridge, session, text};

/// Stops the hub the way a user does and checks the hub and the bridge exit cleanly,
/// leaving nothing of the session in /dev/shm.
fn stop(s: &str, hub: Proc, bridge: Proc) {
    assert_eq!(agent_sdk::control(s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    ends_cleanly(s, hub, bridge);
}

/// Checks the hub and the bridge exit cleanly and leave nothing in /dev/shm.
fn ends_cleanly(s: &str, hub: Proc, bridge: Proc) {
    let h = hub.wait(Duration::from_secs(10));
    assert!(h.status.success(), "{}", text(&h.stderr));
    let b = bridge.wait(Duration::from_secs(10));
    assert!(b.status.success(), "bridge: {}", text(&b.stderr));
    let prefix = format!("iwsim_{s}_");
    let left = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .count();
    assert_eq!(left, 0, "files of {s} left in /dev/shm");
}

/// Starts a hub and a bridge on a free port; returns them and the registration address.
fn hub_and_bridge(s: &str, hub_args: &[&str], bridge_args: &[&str]) -> (Proc, Proc, SocketAddr) {
    let (hub, bridge, addr, _) = hub_and_logged_bridge(s, hub_args, bridge_args);
    (hub, bridge, addr)
}

struct Client {
    sock: UdpSocket,
    server: Option<SocketAddr>,
}

impl Client {
    fn new() -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").expect("bind");
        sock.set_read_timeout(Some(Duration::from_secs(5))).expect("timeout");
        Self { sock, server: None }
    }

    fn recv(&mut self) -> String {
        let mut buf = [0u8; 65536];
        let (n, from) = self.sock.recv_from(&mut buf).expect("a datagram within 5 s");
        assert!(buf[..n].ends_with(b"\n\0"), "every datagram ends with a newline and a NUL");
        self.server.get_or_insert(from);
        String::from_utf8_lossy(&buf[..n - 1]).into_owned()
    }

    /// Registers at `reg` and returns the reply; later traffic goes to the reply's port.
    fn register(&mut self, reg: SocketAddr, xml: &str) -> String {
        self.sock.send_to(xml.as_bytes(), reg).expect("send");
        self.server = None;
        self.recv()
    }

    fn send(&self, xml: &str) {
        self.sock.send_to(xml.as_bytes(), self.server.expect("registered")).expect("send");
    }

    /// The next datagram whose root is `root` within `timeout`, if any.
    fn try_next(&mut self, root: &str, timeout: Duration) -> Option<String> {
        let end = Instant::now() + timeout;
        let mut buf = [0u8; 65536];
        while Instant::now() < end {
            self.sock
                .set_read_timeout(Some(end.saturating_duration_since(Instant::now()).max(Duration::from_millis(1))))
                .ok()?;
            let Ok((n, _)) = self.sock.recv_from(&mut buf) else { break };
            let d = String::from_utf8_lossy(&buf[..n.saturating_sub(1)]).into_owned();
            if d.starts_with(&format!("<{root}")) {
                self.sock.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
                return Some(d);
            }
        }
        self.sock.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
        None
    }

    /// The next datagram whose root is `root`.
    fn next(&mut self, root: &str) -> String {
        loop {
            let d = self.recv();
            if d.starts_with(&format!("<{root}")) {
                return d;
            }
        }
    }
}

fn attr(xml: &str, element: &str, name: &str) -> Option<f64> {
    let el = &xml[xml.find(&format!("<{element} "))?..];
    let key = format!(" {name}=\"");
    let rest = &el[el.find(&key)? + key.len()..];
    rest[..rest.find('"')?].parse().ok()
}

#[test]
fn an_intellwheels_robot_drives_and_its_gps_track_follows_the_kinematics_within_a_millimetre() {
    let dir = std::env::temp_dir().join(format!("iwsim-udp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let param = dir.join("gps.xml");
    std::fs::write(&param, "<Parameters GPS=\"On\" KeyTime=\"4000\" CollisionWallPenalty=\"5\"/>\n")
        .expect("param file");
    let s = session("udp-gps");
    let (hub, bridge, reg) = hub_and_bridge(
        &s,
        &["--lockstep", "--wait-agents", "1", "--ticks", "60", "--no-noise", "--param", param.to_str().expect("utf-8")],
        &[],
    );
    let mut c = Client::new();
    let reply = c.register(
        reg,
        r#"<Robot Name="iw" Id="1" Width="1.2" Height="0.7" COM="0.8" X="10" Y="6.1" Dir="0" Type="Simulated" MaxSpeed="0.5" AccelerationCurve="0.6"><IRSensor Id="0" X="0.96" Y="0" Angle="0" Cone="60"/></Robot>"#,
    );
    assert!(reply.starts_with("<Reply Status=\"Ok\">") && reply.contains("GPS=\"On\""), "{reply}");
    // The parameter file's values reach the client; what it leaves out is the real simulator's.
    for want in
        ["KeyTime=\"4000\"", "CollisionWallPenalty=\"5\"", "CollisionRobotPenalty=\"2\"", "ShowActions=\"True\""]
    {
        assert!(reply.contains(want), "{want} missing from {reply}");
    }

    // The same chair stepped here, from the thesis's equations.
    let map = builtin::map("liacc").expect("built in");
    let mut world = World::new(&map.lab, Params { noise: NoiseParams::NONE, ..Params::default() }, 1).expect("valid");
    let r = world
        .add_robot(
            RobotSpec { pose: Pose::from_deg(10.0, 6.1, 0.0), ..RobotSpec::at(0.0, 0.0, 0.0) }
                .body(1.2, 0.7, 0.8)
                .motors(0.5, 0.6),
        )
        .expect("free");
    let mut checked = 0;
    loop {
        let m = c.next("Measures");
        let t = attr(&m, "Measures", "Time").expect("Time") as u64;
        assert_eq!(t, world.tick(), "one Measures per tick, in order");
        let (x, y) = (attr(&m, "GPS", "X").expect("GPS X"), attr(&m, "GPS", "Y").expect("GPS Y"));
        let p = world.robot(r).expect("alive").pose;
        assert!(
            (x - p.x).abs() < 1e-3 && (y - p.y).abs() < 1e-3,
            "tick {t}: GPS ({x}, {y}) vs model ({}, {})",
            p.x,
            p.y
        );
        checked += 1;
        if t == 40 {
            break;
        }
        // 0.15 is full power; 0.1 is two thirds.
        c.send(r#"<Actions LeftMotor="0.15" RightMotor="0.1"/>"#);
        world.step(&[Action::motors(r, 1.0, 0.1 / 0.15)], 0.1);
    }
    assert_eq!(checked, 41);
    assert!(world.robot(r).expect("alive").pose.x > 10.5, "the chair moved");
    // Answer the rest: the hub stops at its 60-tick limit, and so does the bridge.
    loop {
        c.send(r#"<Actions LeftMotor="0" RightMotor="0"/>"#);
        let m = c.next("Measures");
        if attr(&m, "Measures", "Time") == Some(60.0) {
            break;
        }
    }
    ends_cleanly(&s, hub, bridge);
}

#[test]
fn the_hubs_run_time_ends_with_its_last_tick_not_with_the_agents_linger_after_it() {
    // After the run the bridge keeps a stock client's Measures coming until the client has
    // been silent for 2 s, and the hub waits up to 2 s for it to exit. Ticks per second are
    // the hub's ticks over its run_s (every bench divides so): that wait is not the run's.
    let s = session("udp-run-s");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--lockstep", "--wait-agents", "1", "--ticks", "30", "--json"], &[]);
    let mut c = Client::new();
    assert!(c.register(reg, r#"<Robot Name="r" X="10" Y="6.1" Dir="0"/>"#).starts_with("<Reply Status=\"Ok\""));
    let mut first = None;
    let last = loop {
        let m = c.next("Measures");
        let got = Instant::now();
        first.get_or_insert(got);
        if attr(&m, "Measures", "Time") == Some(30.0) {
            break got;
        }
        c.send(r#"<Actions LeftMotor="0.1" RightMotor="0.1"/>"#);
    };
    // The client goes quiet, as one that has left.
    let h = hub.wait(Duration::from_secs(20));
    let ended = Instant::now();
    assert!(h.status.success(), "{}", text(&h.stderr));
    let json = text(&h.stdout).lines().find(|l| l.starts_with('{')).expect("the --json line").to_owned();
    let out: serde_json::Value = serde_json::from_str(&json).expect("the hub's outcome");
    let run_s = out["run_s"].as_f64().expect("run_s");
    let seen = last.duration_since(first.expect("a first tick")).as_secs_f64();
    let after = ended.duration_since(last).as_secs_f64();
    assert!(after >= 1.0, "the hub waited {after:.2} s for the bridge after the run (the case this test is about)");
    assert!(run_s < seen + 0.5, "run_s {run_s:.2} s, but the client saw ticks 0-30 within {seen:.2} s");
    let b = bridge.wait(Duration::from_secs(10));
    assert!(b.status.success(), "bridge: {}", text(&b.stderr));
}

#[test]
fn a_viewer_gets_the_lab_the_grid_and_every_robot_each_tick() {
    let s = session("udp-view");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20"], &[]);
    let mut robot = Client::new();
    assert!(robot.register(reg, r#"<Robot Name="seen" Id="2"/>"#).contains("Status=\"Ok\""));
    let mut v = Client::new();
    assert!(v.register(reg, "<View/>").starts_with("<Reply Status=\"Ok\">"));
    v.send("<LabReq/>");
    let lab = v.next("Lab");
    assert!(lab.starts_with("<Lab Name=\"IW_LIACC\" Height=\"17.75\" Width=\"44\">"), "{lab}");
    assert_eq!(lab.matches("<Wall ").count(), 23);
    v.send("<GridReq/>");
    let grid = v.next("Grid");
    assert!(grid.contains("<Position X=\"10\" Y=\"6.1\" Dir=\"0\"/>"), "{grid}");
    let r = v.next("Robot");
    assert!(
        r.contains("Name=\"seen\" Id=\"2\"")
            && r.contains("Width=\"1\" Height=\"1\" CenterOfMovement=\"0.5\" Type=\"Simulated\""),
        "{r}"
    );
    assert_eq!(attr(&r, "Position", "X"), Some(14.0), "grid slot 2");
    let later = v.next("Robot");
    assert!(attr(&later, "Robot", "Time") > attr(&r, "Robot", "Time"), "a datagram per tick");
    stop(&s, hub, bridge);
}

#[test]
fn viewers_are_let_in_only_where_the_bridge_allows_and_no_client_is_real_unasked() {
    // A viewer sees every robot's true pose: `--viewers off` refuses one even from this
    // machine, and `--viewer-allow` lets a named address in.
    let s = session("udp-noview");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20"], &["--viewers", "off"]);
    let mut v = Client::new();
    assert_eq!(v.register(reg, "<View/>"), "<Reply Status=\"Refused\"></Reply>\n");
    assert!(v.try_next("Robot", Duration::from_millis(300)).is_none(), "a refused viewer is sent nothing");
    // Robots still register; one asking to be Real (its client pushing any pose it likes)
    // is refused by the hub, which expects no Real robot.
    let mut robot = Client::new();
    assert!(robot.register(reg, r#"<Robot Name="plain" Id="1"/>"#).contains("Status=\"Ok\""));
    let mut cheat = Client::new();
    let reply = cheat.register(reg, r#"<Robot Name="ghost" Id="2" Type="Real"/>"#);
    assert!(reply.contains("Status=\"Refused\""), "{reply}");
    stop(&s, hub, bridge);

    let s = session("udp-allowview");
    let (hub, bridge, reg) =
        hub_and_bridge(&s, &["--cycle-ms", "20"], &["--viewers", "off", "--viewer-allow", "127.0.0.1"]);
    let mut v = Client::new();
    assert!(v.register(reg, "<View/>").starts_with("<Reply Status=\"Ok\">"));
    stop(&s, hub, bridge);
}

#[test]
fn a_datagram_from_a_foreign_port_changes_nothing() {
    let s = session("udp-foreign");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20", "--no-noise"], &[]);
    let mut c = Client::new();
    c.register(reg, r#"<Robot Name="still" Id="1"/>"#);
    let first = c.next("Measures");
    let port = c.server.expect("reply port");
    let intruder = UdpSocket::bind("127.0.0.1:0").expect("bind");
    for _ in 0..20 {
        intruder.send_to(br#"<Actions LeftMotor="0.15" RightMotor="0.15"/>"#, port).expect("send");
        // The real client keeps the chair still.
        c.send(r#"<Actions LeftMotor="0" RightMotor="0"/>"#);
        c.next("Measures");
    }
    let v = {
        let mut v = Client::new();
        v.register(reg, "<View/>");
        v.next("Robot")
    };
    assert_eq!(attr(&v, "Position", "X"), Some(10.0), "the intruder's powers were dropped: {v}");
    assert!(first.contains("<IRSensor Id=\"0\""));
    stop(&s, hub, bridge);
}

#[test]
fn malformed_input_is_refused_or_ignored_and_the_bridge_keeps_serving() {
    let s = session("udp-junk");
    let (hub, mut bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20", "--no-noise"], &[]);
    let junk = UdpSocket::bind("127.0.0.1:0").expect("bind");
    junk.set_read_timeout(Some(Duration::from_millis(150))).expect("timeout");
    let big = vec![b'<'; 10 * 1024];
    let registrations: Vec<(&[u8], bool)> = vec![
        // (datagram, whether the simulator answers it with a refusal)
        (b"<Robot Name=\"a\"", false),
        (b"<Hello/>", false),
        (b"<Robot Id=\"-1\"/>", true),
        (b"<Robot Id=\"abc\"/>", true),
        (b"<Robot Width=\"NaN\"/>", false),
        (b"<Robot Width=\"1\" Width=\"2\"/>", false),
        (b"<Robot Type=\"Boat\"/>", false),
        (b"<Robot><Wheel/></Robot>", false),
        (b"<Robot><IRSensor Id=\"0\">", false),
        (&big, false),
        (b"\x00\xff\xfe\x13\x37garbage", false),
        (b"", false),
        (b"hello", false),
        (b"<?xml version=\"1.0\"?>", false),
        (b"<Robot Id=\"99\"/>", true),
        (b"<Robot COM=\"1.5\"/>", true),
        (b"<Robot MaxSpeed=\"-1\"/>", true),
        (b"<Robot Name=\"x\"><IRSensor Id=\"4000000000\"/></Robot>", true),
        (b"<Robot Name=\"x\"><IRSensor Id=\"1\"/><IRSensor Id=\"1\"/></Robot>", true),
    ];
    for (dg, refused) in &registrations {
        junk.send_to(dg, reg).expect("send");
        let mut buf = [0u8; 2048];
        match junk.recv_from(&mut buf) {
            Ok((n, _)) => {
                assert!(*refused, "{:?} got an answer", String::from_utf8_lossy(dg));
                assert_eq!(&buf[..n], b"<Reply Status=\"Refused\"></Reply>\n\0");
            }
            Err(_) => assert!(!refused, "{:?} got no refusal", String::from_utf8_lossy(dg)),
        }
    }
    // A robot that behaves, then junk on its own port.
    let mut c = Client::new();
    assert!(c.register(reg, r#"<Robot Name="ok" Id="1"/>"#).contains("Status=\"Ok\""));
    c.next("Measures");
    for dg in [
        &br#"<Actions LeftMotor="nan"/>"#[..],
        br#"<Actions LeftMotor="inf" RightMotor="0.1"/>"#,
        b"<Actions><Dance/></Actions>",
        b"<Measures/>",
        br#"<Actions LeftMotor="0.1""#,
        br#"<Actions LeftMotor="0.1" LeftMotor="0.2"/>"#,
        &big,
        b"\xde\xad\xbe\xef",
    ] {
        c.sock.send_to(dg, c.server.expect("port")).expect("send");
    }
    // Still served: Measures keep coming and a valid action still drives.
    for _ in 0..10 {
        c.send(r#"<Actions LeftMotor="0.15" RightMotor="0.15"/>"#);
        c.next("Measures");
    }
    let mut v = Client::new();
    v.register(reg, "<View/>");
    let robot = v.next("Robot");
    assert!(attr(&robot, "Position", "X").expect("x") > 10.0, "{robot}");
    let mut again = Client::new();
    assert!(again.register(reg, r#"<Robot Name="late" Id="3"/>"#).contains("Status=\"Ok\""));
    assert!(bridge.0.as_mut().expect("running").try_wait().expect("status").is_none(), "the bridge is still up");
    stop(&s, hub, bridge);
}

#[test]
fn a_silent_robot_client_is_unregistered() {
    let s = session("udp-silent");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20"], &["--client-timeout", "0.3"]);
    let mut c = Client::new();
    c.register(reg, r#"<Robot Name="quiet" Id="1"/>"#);
    let mut v = Client::new();
    v.register(reg, "<View/>");
    assert!(v.next("Robot").contains("Name=\"quiet\""));
    // The robot client says nothing more; soon its robot is gone from the world, and the
    // viewer hears of it no more.
    let start = Instant::now();
    while v.try_next("Robot", Duration::from_millis(200)).is_some_and(|r| r.contains("Name=\"quiet\"")) {
        assert!(start.elapsed() < Duration::from_secs(5), "the silent robot is still reported");
    }
    assert!(v.try_next("Robot", Duration::from_millis(200)).is_none(), "no robot left to report");
    stop(&s, hub, bridge);
}

#[test]
fn measures_keep_coming_while_the_run_is_paused_and_the_client_stays() {
    let s = session("udp-paused");
    let (hub, bridge, reg) =
        hub_and_bridge(&s, &["--cycle-ms", "20", "--start-on-command"], &["--client-timeout", "0.3"]);
    let mut c = Client::new();
    c.register(reg, r#"<Robot Name="patient" Id="1"/>"#);
    // The run waits for a Start: Measures still come every cycle, with Stop pressed, and the
    // client (which answers nothing) is not timed out.
    let start = Instant::now();
    let mut n = 0;
    while start.elapsed() < Duration::from_millis(800) {
        let m = c.next("Measures");
        assert!(m.contains("<Buttons Start=\"Off\" Stop=\"On\"/>"), "{m}");
        n += 1;
    }
    assert!(n >= 10, "only {n} Measures in 0.8 s");
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Start, 0).expect("hub answers").status, 0);
    let running = loop {
        let m = c.next("Measures");
        if m.contains("Start=\"On\"") {
            break m;
        }
    };
    assert!(running.contains("<Measures Time="));
    stop(&s, hub, bridge);
}

#[test]
fn a_viewer_sees_robots_driven_over_shared_memory() {
    let s = session("udp-shmview");
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20"], &[]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--name", "shm", "--pose", "12,6.1,0"]);
    let mut v = Client::new();
    v.register(reg, "<View/>");
    let r = v.next("Robot");
    assert!(r.contains("Name=\"shm1\""), "{r}");
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    // The agent is a process of the session too: the last to leave removes its files, so
    // /dev/shm is looked at once every one of them has exited.
    assert!(agent.wait(Duration::from_secs(10)).status.success());
    ends_cleanly(&s, hub, bridge);
}

#[test]
fn a_flood_of_junk_is_counted_in_full_but_logged_in_a_few_lines() {
    let s = session("udp-flood");
    let (hub, bridge, reg, lines) = hub_and_logged_bridge(&s, &["--cycle-ms", "20", "--no-noise"], &[]);
    // A panel paces the flood: the bridge reads each socket in order, so once the panel's
    // own datagram is answered, every junk datagram sent before it to that socket was read
    // (and none was lost to a full receive buffer).
    let mut panel = Client::new();
    assert!(panel.register(reg, "<Panel/>").contains("Status=\"Ok\""));
    let panel_port = panel.server.expect("reply port");
    let junk = UdpSocket::bind("127.0.0.1:0").expect("bind");
    const BATCHES: usize = 400;
    const AT_REGISTRATION: usize = 50;
    const AT_PANEL: usize = 10;
    for b in 0..BATCHES {
        for k in 0..AT_REGISTRATION {
            junk.send_to(format!("<Robot Id=\"junk-{b}-{k}\"").as_bytes(), reg).expect("send");
        }
        for k in 0..AT_PANEL {
            junk.send_to(format!("<Start {b} {k}").as_bytes(), panel_port).expect("send");
        }
        panel.sock.send_to(b"<Panel/>", reg).expect("send");
        panel.next("Reply");
        panel.send("<LabReq/>");
        panel.next("Lab");
    }
    // The bridge still serves: a robot registers and gets its Measures.
    let mut c = Client::new();
    assert!(c.register(reg, r#"<Robot Name="after" Id="1"/>"#).contains("Status=\"Ok\""));
    assert!(c.next("Measures").contains("<Measures Time="));
    stop(&s, hub, bridge);
    let logged = lines.to_end(Duration::from_secs(10));
    let bytes: usize = logged.iter().map(|l| l.len() + 1).sum();
    assert!(bytes < 64 * 1024, "{bytes} bytes of stderr for a flood, e.g. {:?}", &logged[..logged.len().min(5)]);
    let last = logged.iter().find(|l| l.contains("run over")).expect("the counters are printed");
    let total_junk = BATCHES * AT_REGISTRATION;
    let total_foreign = BATCHES * AT_PANEL;
    assert!(last.contains(&format!("({total_junk} malformed, {total_foreign} foreign, 0 refused")), "{last}");
}

#[test]
fn a_registration_the_hub_has_not_answered_yet_stalls_no_other_client() {
    let s = session("udp-pending");
    // Waiting for a Start, the bridge re-sends each robot's Measures every 20 ms cycle.
    let (hub, bridge, reg) = hub_and_bridge(&s, &["--cycle-ms", "20", "--start-on-command"], &[]);
    let mut a = Client::new();
    assert!(a.register(reg, r#"<Robot Name="first" Id="1"/>"#).contains("Status=\"Ok\""));
    a.next("Measures");
    // A stopped hub answers no registration (a busy one answers late): the second client's
    // registration stays pending while the first client's Measures keep coming.
    hub.signal("STOP");
    let mut b = Client::new();
    b.sock.send_to(br#"<Robot Name="second" Id="2"/>"#, reg).expect("send");
    for k in 0..10 {
        if a.try_next("Measures", Duration::from_secs(1)).is_none() {
            hub.signal("CONT");
            panic!("no Measures for 1 s while a registration was pending (after {k})");
        }
    }
    b.sock.set_nonblocking(true).expect("non-blocking");
    let early = b.sock.recv_from(&mut [0u8; 256]).is_ok();
    b.sock.set_nonblocking(false).expect("blocking");
    hub.signal("CONT");
    assert!(!early, "the stopped hub cannot have answered");
    assert!(b.recv().starts_with("<Reply Status=\"Ok\">"), "answered once the hub goes on");
    // Both drive once the run starts.
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Start, 0).expect("hub answers").status, 0);
    assert!(b.next("Measures").contains("<Measures Time="));
    assert!(a.next("Measures").contains("<Measures Time="));
    stop(&s, hub, bridge);
}
