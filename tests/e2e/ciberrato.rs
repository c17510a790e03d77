//! Stock Ciber-Rato clients' view of iwsim (issue 14): stand-in clients over real UDP sockets
//! on 127.0.0.1 that behave as robsample, pClient and the Qt Viewer do, against a hub and the
//! bridge as real processes. What Ciber-Rato does is in shared/research/ciberrato.md: while
//! the run waits for Start, Measures (Time 0) go to every robot and `<Robot>` datagrams to
//! every viewer each cycle; a silent robot is never removed and keeps its powers.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use super::common::{Lines, Proc, hub_and_logged_bridge as hub_and_bridge, session, text};

/// Waits for the hub and the bridge to exit cleanly; returns the hub's stdout and the
/// bridge's closing line (its counters).
pub(super) fn ended(hub: Proc, bridge: Proc, lines: &Lines) -> (String, String) {
    let h = hub.wait(Duration::from_secs(30));
    assert!(h.status.success(), "hub: {}", text(&h.stderr));
    let b = bridge.wait(Duration::from_secs(10));
    let said = lines.to_end(Duration::from_secs(10));
    assert!(b.status.success(), "the bridge failed: {said:?}");
    let last = said.into_iter().rfind(|l| l.contains("run over")).unwrap_or_default();
    (text(&h.stdout), last)
}

/// Stops the run as a user does and waits for both processes to exit.
fn stop(s: &str, hub: Proc, bridge: Proc, lines: &Lines) -> String {
    assert_eq!(agent_sdk::control(s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    ended(hub, bridge, lines).1
}

/// A stand-in Ciber-Rato client: one socket, the registration reply's port for later traffic.
pub(super) struct StandIn {
    sock: UdpSocket,
    server: Option<SocketAddr>,
}

impl StandIn {
    pub(super) fn new() -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").expect("bind");
        sock.set_read_timeout(Some(Duration::from_secs(5))).expect("timeout");
        Self { sock, server: None }
    }

    /// The next datagram within `timeout`, without its closing NUL; remembers the port the
    /// first one came from (the client's own port on the bridge, as libRobSock does).
    pub(super) fn recv_within(&mut self, timeout: Duration) -> Option<String> {
        let mut buf = [0u8; 65536];
        self.sock.set_read_timeout(Some(timeout.max(Duration::from_millis(1)))).ok()?;
        let (n, from) = self.sock.recv_from(&mut buf).ok()?;
        assert!(buf[..n].ends_with(b"\n\0"), "every datagram ends with a newline and a NUL");
        self.server.get_or_insert(from);
        Some(String::from_utf8_lossy(&buf[..n - 1]).into_owned())
    }

    /// Registers and returns the reply (a client that hears nothing in 5 s gives up).
    pub(super) fn register(&mut self, reg: SocketAddr, xml: &str) -> String {
        self.server = None;
        self.sock.send_to(xml.as_bytes(), reg).expect("send");
        self.recv_within(Duration::from_secs(5)).expect("a reply within 5 s")
    }

    pub(super) fn send(&self, xml: &str) {
        self.sock.send_to(xml.as_bytes(), self.server.expect("registered")).expect("send");
    }

    /// The next datagram whose root is `root`; like robsample, gives up after 2 s of silence.
    pub(super) fn next(&mut self, root: &str) -> String {
        loop {
            let d = self.recv_within(Duration::from_secs(2)).unwrap_or_else(|| panic!("no datagram for 2 s"));
            if d.starts_with(&format!("<{root} ")) {
                return d;
            }
        }
    }
}

pub(super) fn attr<'a>(xml: &'a str, element: &str, name: &str) -> Option<&'a str> {
    let el = &xml[xml.find(&format!("<{element} "))?..];
    let key = format!(" {name}=\"");
    let rest = &el[el.find(&key)? + key.len()..];
    Some(&rest[..rest.find('"')?])
}

pub(super) fn num(xml: &str, element: &str, name: &str) -> Option<f64> {
    attr(xml, element, name)?.parse().ok()
}

#[test]
fn three_clients_registered_before_start_all_get_measures_and_a_viewer_sees_their_robots() {
    let s = session("cr-waiting");
    // Ciber-Rato's 50 ms cycle; the run waits for a Start, as Ciber-Rato's does.
    let (hub, bridge, reg, lines) = hub_and_bridge(&s, &["--cycle-ms", "50", "--start-on-command", "--no-noise"], &[]);
    let mut robots: Vec<StandIn> = (1..=3).map(|_| StandIn::new()).collect();
    for (k, r) in robots.iter_mut().enumerate() {
        let reply = r.register(reg, &format!(r#"<Robot Name="rob{}" Id="{}"/>"#, k + 1, k + 1));
        assert!(reply.starts_with("<Reply Status=\"Ok\">"), "{reply}");
    }
    let mut viewer = StandIn::new();
    assert!(viewer.register(reg, "<View/>\n\0").starts_with("<Reply Status=\"Ok\">"));

    // For 2 s (when robsample would quit without Measures), read everything that comes.
    let mut measures = [0usize; 3];
    let mut seen: std::collections::BTreeMap<String, usize> = Default::default();
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(2) {
        for (k, r) in robots.iter_mut().enumerate() {
            while let Some(m) = r.recv_within(Duration::from_millis(1)) {
                assert!(m.starts_with("<Measures Time=\"0\">"), "nothing moves before Start: {m}");
                assert!(m.contains("<Buttons Start=\"Off\" Stop=\"On\"/>"), "{m}");
                measures[k] += 1;
            }
        }
        while let Some(v) = viewer.recv_within(Duration::from_millis(1)) {
            if v.starts_with("<Robot ") {
                assert_eq!(attr(&v, "Robot", "Time"), Some("0"), "{v}");
                assert_eq!(attr(&v, "Robot", "State"), Some("Stopped"), "{v}");
                *seen.entry(attr(&v, "Robot", "Name").expect("Name").to_owned()).or_default() += 1;
            }
        }
    }
    for (k, n) in measures.iter().enumerate() {
        assert!(*n >= 10, "robot {} got {n} Measures in 2 s before Start ({measures:?})", k + 1);
    }
    for name in ["rob1", "rob2", "rob3"] {
        let n = seen.get(name).copied().unwrap_or(0);
        assert!(n >= 10, "the viewer saw {name} {n} times in 2 s before Start ({seen:?})");
    }

    // Started, every robot's clock runs.
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Start, 0).expect("hub answers").status, 0);
    for r in &mut robots {
        loop {
            let m = r.next("Measures");
            if num(&m, "Measures", "Time").expect("Time") >= 1.0 {
                assert!(m.contains("<Buttons Start=\"On\" Stop=\"Off\"/>"), "{m}");
                break;
            }
        }
    }
    let counters = stop(&s, hub, bridge, &lines);
    assert!(counters.contains("(0 malformed, 0 foreign, 0 refused, 0 timed out"), "{counters}");
}

#[test]
fn a_silent_robot_keeps_its_robot_and_its_powers_for_60_s_of_lock_step() {
    let s = session("cr-silent");
    // 600 ticks of 100 ms: a minute of simulated time.
    let (hub, bridge, reg, lines) = hub_and_bridge(
        &s,
        &["--lockstep", "--wait-agents", "1", "--ticks", "600", "--cycle-ms", "100", "--no-noise"],
        &[],
    );
    let mut viewer = StandIn::new();
    assert!(viewer.register(reg, "<View/>").starts_with("<Reply Status=\"Ok\">"));
    let mut robot = StandIn::new();
    assert!(robot.register(reg, r#"<Robot Name="quiet" Id="1"/>"#).starts_with("<Reply Status=\"Ok\">"));
    // It answers its first Measures with a slow spin, then never says anything again.
    assert!(robot.next("Measures").starts_with("<Measures Time=\"0\">"));
    robot.send(r#"<Actions LeftMotor="-0.05" RightMotor="0.05"/>"#);

    let mut headings: Vec<(u64, f64)> = Vec::new();
    let start = Instant::now();
    while let Some(v) = viewer.recv_within(Duration::from_secs(5)) {
        if v.starts_with("<Robot ") {
            assert_eq!(attr(&v, "Robot", "Name"), Some("quiet"), "{v}");
            let t = num(&v, "Robot", "Time").expect("Time") as u64;
            headings.push((t, num(&v, "Position", "Dir").expect("Dir")));
            if t >= 600 {
                break;
            }
        }
        assert!(start.elapsed() < Duration::from_secs(60), "600 lock-step ticks took over a minute");
    }
    let (hub_out, counters) = ended(hub, bridge, &lines);
    assert!(hub_out.contains("tick 600 "), "{hub_out}");
    assert!(hub_out.contains("robot 1: "), "the silent robot is still there at the end: {hub_out}");
    assert!(counters.contains("0 timed out"), "{counters}");
    // Still turning in its last seconds, on the powers it sent at tick 0.
    let late: Vec<f64> = headings.iter().filter(|(t, _)| *t >= 500).map(|(_, d)| *d).collect();
    assert!(late.len() >= 50, "only {} viewer datagrams after tick 500", late.len());
    let turning = late.windows(2).filter(|w| (w[1] - w[0]).abs() > 1e-6).count();
    assert!(turning >= late.len() / 2, "the robot stopped turning: {late:?}");
}

#[test]
fn actions_with_a_repeated_attribute_change_nothing_and_are_counted() {
    let s = session("cr-repeat");
    let (hub, bridge, reg, lines) = hub_and_bridge(&s, &["--cycle-ms", "50", "--no-noise"], &[]);
    let mut robot = StandIn::new();
    let reply = robot.register(reg, r#"<Robot Name="r" Id="1"/>"#);
    assert!(reply.starts_with("<Reply Status=\"Ok\">"), "{reply}");
    // Full power, said twice alike: malformed, so the robot stays where the grid put it.
    const REPEATS: usize = 20;
    for _ in 0..REPEATS {
        robot.next("Measures");
        robot.send(r#"<Actions LeftMotor="0.15" LeftMotor="0.15" RightMotor="0.15"/>"#);
    }
    for _ in 0..5 {
        robot.next("Measures");
    }
    let mut viewer = StandIn::new();
    viewer.register(reg, "<View/>");
    let still = viewer.next("Robot");
    assert_eq!(num(&still, "Position", "X"), Some(10.0), "a repeated attribute drove the robot: {still}");
    // The same powers said once drive it.
    for _ in 0..10 {
        robot.next("Measures");
        robot.send(r#"<Actions LeftMotor="0.15" RightMotor="0.15"/>"#);
    }
    let moved = loop {
        let v = viewer.next("Robot");
        if num(&v, "Position", "X").expect("X") > 10.0 {
            break v;
        }
    };
    assert!(moved.contains("Name=\"r\""));
    let counters = stop(&s, hub, bridge, &lines);
    assert!(counters.contains(&format!("({REPEATS} malformed, 0 foreign")), "{counters}");
}

#[test]
fn a_registration_with_a_malformed_id_is_refused_at_once() {
    let s = session("cr-badid");
    let (hub, bridge, reg, lines) = hub_and_bridge(&s, &["--cycle-ms", "50"], &[]);
    for dg in [r#"<Robot Name="a" Id="abc"/>"#, r#"<Robot Name="b" Id="-1"/>"#, r#"<RobotBeacon Id="1.5" Height="1"/>"#]
    {
        let c = UdpSocket::bind("127.0.0.1:0").expect("bind");
        c.set_read_timeout(Some(Duration::from_secs(2))).expect("timeout");
        c.send_to(dg.as_bytes(), reg).expect("send");
        let mut buf = [0u8; 256];
        let (n, from) = c.recv_from(&mut buf).unwrap_or_else(|_| panic!("{dg}: no answer within 2 s"));
        assert_eq!(&buf[..n], b"<Reply Status=\"Refused\"></Reply>\n\0", "{dg}");
        assert_ne!(from, reg, "the refusal comes from a port of its own, as the simulator's");
    }
    // A well-formed one is still served.
    let mut ok = StandIn::new();
    let reply = ok.register(reg, r#"<Robot Name="ok" Id="0"/>"#);
    assert!(reply.starts_with("<Reply Status=\"Ok\">"), "{reply}");
    assert!(ok.next("Measures").starts_with("<Measures Time="));
    let counters = stop(&s, hub, bridge, &lines);
    assert!(counters.contains("(3 malformed, 0 foreign, 0 refused"), "{counters}");
}

#[test]
fn long_lab_and_robot_names_reach_viewers_whole() {
    let dir = std::env::temp_dir().join(format!("iwsim-cr-lab-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let lab = dir.join("long-name-lab.xml");
    // 200 bytes (they were cut to 31 before names left the per-tick snapshot).
    let name = format!("A lab whose name is long: {}", "ü".repeat(87));
    assert_eq!(name.len(), 200);
    std::fs::write(&lab, format!("<Lab Name=\"{name}\" Width=\"28\" Height=\"14\">\n</Lab>\n")).expect("lab file");
    let grid = dir.join("grid.xml");
    std::fs::write(&grid, "<Grid><Position X=\"5\" Y=\"3.5\" Dir=\"0\"/></Grid>\n").expect("grid");
    let s = session("cr-labname");
    let (hub, bridge, reg, lines) = hub_and_bridge(
        &s,
        &["--lab", lab.to_str().expect("utf-8"), "--grid", grid.to_str().expect("utf-8"), "--start-on-command"],
        &[],
    );
    let robot_name = format!("Team {} robot", "é".repeat(100));
    let mut robot = StandIn::new();
    let reply = robot.register(reg, &format!("<Robot Name=\"{robot_name}\" Id=\"1\"/>"));
    assert!(reply.starts_with("<Reply Status=\"Ok\">"), "{reply}");
    let mut viewer = StandIn::new();
    assert!(viewer.register(reg, "<View/>").starts_with("<Reply Status=\"Ok\">"));
    viewer.send("<LabReq/>");
    let served = viewer.next("Lab");
    assert_eq!(attr(&served, "Lab", "Name"), Some(name.as_str()), "{served}");
    // Every cycle before the start, each robot as viewers see it, named in full.
    let seen = viewer.next("Robot");
    assert_eq!(attr(&seen, "Robot", "Name"), Some(robot_name.as_str()), "{seen}");
    stop(&s, hub, bridge, &lines);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_plain_robot_against_a_wall_escapes_by_spinning_as_robsample_does() {
    // A lab with one wall ahead of the start and a line on the floor under the robot's way (a
    // wall of height 0, which it drives over and its IR does not see), and a client that
    // drives as robsample does:
    // straight on until the wall, then spin until the front IR sensor reads clear, then on.
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-cr-spin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (lab, grid) = (dir.join("lab.xml"), dir.join("grid.xml"));
    std::fs::write(
        &lab,
        "<Lab Name=\"spin\" Width=\"14\" Height=\"7\">\n<Wall Height=\"1\"><Corner X=\"8\" Y=\"0\"/><Corner X=\"9\" Y=\"0\"/>\
         <Corner X=\"9\" Y=\"7\"/><Corner X=\"8\" Y=\"7\"/></Wall>\n\
         <Wall Height=\"0\"><Corner X=\"0\" Y=\"3.4\"/><Corner X=\"8\" Y=\"3.4\"/><Corner X=\"8\" Y=\"3.6\"/>\
         <Corner X=\"0\" Y=\"3.6\"/></Wall>\n</Lab>\n",
    )
    .expect("lab");
    std::fs::write(&grid, "<Grid><Position X=\"5\" Y=\"3.5\" Dir=\"0\"/></Grid>\n").expect("grid");
    let s = session("cr-spin");
    let (lab_s, grid_s) = (lab.to_str().expect("utf-8"), grid.to_str().expect("utf-8"));
    let (hub, bridge, reg, lines) = hub_and_bridge(
        &s,
        &["--lab", lab_s, "--grid", grid_s, "--lockstep", "--wait-agents", "1", "--cycle-ms", "50", "--no-noise"],
        &[],
    );
    let mut robot = StandIn::new();
    assert!(robot.register(reg, r#"<Robot Name="spinner" Id="1"/>"#).starts_with("<Reply Status=\"Ok\">"));
    let (mut hit_wall, mut spun, mut escaped) = (None, 0, false);
    for k in 0..400 {
        let m = robot.next("Measures");
        if k == 0 {
            // The rear sensor (rim x = 4.5) sees the west border 4.5 m off: 1/4.5 → 0.2, as the
            // real simulator's IR, which has no range limit, reads it (a 3 m range floored it at 0.3).
            let rear = m
                .split("<IRSensor ")
                .find(|e| e.starts_with("Id=\"3\""))
                .and_then(|e| num(&format!("<IRSensor {e}"), "IRSensor", "Value"));
            assert_eq!(rear, Some(0.2), "{m}");
            // The three middle elements of the line sensor, 0.438 ahead, lie on the 0.2 m line.
            assert!(m.contains("\t\t<LineSensor Value=\"0011100\" />\n"), "{m}");
        }
        let collision = m.contains("Collision=\"Yes\"");
        let front = m
            .split("<IRSensor ")
            .find(|e| e.starts_with("Id=\"0\""))
            .and_then(|e| num(&format!("<IRSensor {e}"), "IRSensor", "Value"))
            .expect("IR sensor 0");
        let powers = match hit_wall {
            None if collision => {
                hit_wall = Some(front);
                (-0.15, 0.15)
            }
            None => (0.15, 0.15),
            // Spin until the front sensor sees more than 2 m of free space (IR < 0.5), then go.
            Some(_) if front > 0.5 && !escaped => {
                spun += 1;
                (-0.15, 0.15)
            }
            Some(_) => {
                escaped = true;
                (0.15, 0.15)
            }
        };
        robot.send(&format!("<Actions LeftMotor=\"{}\" RightMotor=\"{}\"/>", powers.0, powers.1));
        if escaped && !collision && m.contains("Time=\"") && spun > 0 {
            break;
        }
    }
    assert!(hit_wall.is_some(), "the robot never reached the wall");
    assert!(spun > 0 && escaped, "it spun {spun} ticks against the wall and escaped: {escaped}");
    // Driving away: twenty more ticks take it well clear of the wall.
    for _ in 0..20 {
        let m = robot.next("Measures");
        assert!(!m.contains("Collision=\"Yes\""), "{m}");
        robot.send(r#"<Actions LeftMotor="0.15" RightMotor="0.15"/>"#);
    }
    let out = stop(&s, hub, bridge, &lines);
    assert!(out.contains("run over"), "{out}");
    let _ = std::fs::remove_dir_all(dir);
}
