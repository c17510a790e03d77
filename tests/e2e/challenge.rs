//! Ciber-Rato's challenges as the hub scores them (issue 31): a scripted client over the UDP
//! bridge drives one robot through a course in lock-step, with noise off, and reads its
//! `<Score>` from its Measures each tick; the hub's final table (its JSON outcome) must agree.
//! Each expected value is derived in the test from the rules (world::challenge's docs, the
//! real simulator's) and from the positions the client's own GPS reports.

use std::path::PathBuf;
use std::time::Duration;

use run_records::outcome::HubOutcome;

use super::ciberrato::{StandIn, attr, ended, num};
use super::common::{Proc, hub_and_logged_bridge as hub_and_bridge, session, text};

/// A course's files: lab, grid and parameters, in a directory of their own.
struct Course {
    dir: PathBuf,
    files: [String; 3],
}

impl Course {
    fn new(tag: &str, lab: &str, grid: &str, params: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("iwsim-e2e-challenge-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let files = [("lab.xml", lab), ("grid.xml", grid), ("params.xml", params)].map(|(name, text)| {
            let path = dir.join(name);
            std::fs::write(&path, text).expect("write");
            path.to_str().expect("utf-8").to_owned()
        });
        Self { dir, files }
    }

    /// The hub's arguments for this course: lock-step, noise off, `scoring`, its JSON outcome.
    fn hub_args<'a>(&'a self, scoring: &'a str) -> Vec<&'a str> {
        let [lab, grid, params] = &self.files;
        vec![
            "--lab",
            lab,
            "--grid",
            grid,
            "--param",
            params,
            "--scoring",
            scoring,
            "--lockstep",
            "--wait-agents",
            "1",
            "--no-noise",
            "--json",
        ]
    }
}

impl Drop for Course {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// What one Measures says.
#[derive(Debug, Clone, PartialEq)]
struct Seen {
    time: u64,
    x: f64,
    y: f64,
    /// Compass, degrees (integer, noise off: the true heading).
    compass: f64,
    score: i64,
    arrival: u64,
    returning: u64,
    collisions: u32,
    visited: String,
    collision: bool,
    end_led: bool,
    buttons: (bool, bool),
}

fn seen(m: &str) -> Seen {
    let n = |e, a| num(m, e, a).unwrap_or_else(|| panic!("no {e} {a} in {m}"));
    Seen {
        time: n("Measures", "Time") as u64,
        x: n("GPS", "X"),
        y: n("GPS", "Y"),
        compass: n("Sensors", "Compass"),
        score: n("Score", "Score") as i64,
        arrival: n("Score", "ArrivalTime") as u64,
        returning: n("Score", "ReturningTime") as u64,
        collisions: n("Score", "Collisions") as u32,
        visited: attr(m, "Score", "VisitedMask").expect("VisitedMask").to_owned(),
        collision: attr(m, "Sensors", "Collision") == Some("Yes"),
        end_led: attr(m, "Leds", "EndLed") == Some("On"),
        buttons: (attr(m, "Buttons", "Start") == Some("On"), attr(m, "Buttons", "Stop") == Some("On")),
    }
}

const NONE: u8 = 0;
const END: u8 = 1;
const RETURNING: u8 = 2;
const VISITING: u8 = 4;

/// A robot client that answers each Measures with one Actions.
struct Driver {
    robot: StandIn,
    now: Seen,
}

impl Driver {
    fn register(reg: std::net::SocketAddr, name: &str) -> Self {
        let mut robot = StandIn::new();
        let reply = robot.register(reg, &format!("<Robot Name=\"{name}\" Id=\"1\"/>"));
        assert!(reply.contains("ScoreSensor=\"On\""), "{reply}");
        let now = seen(&robot.next("Measures"));
        Self { robot, now }
    }

    /// Answers the Measures in hand and reads the next.
    fn act(&mut self, left: f64, right: f64, leds: u8) -> &Seen {
        let on = |bit| if leds & bit != 0 { "On" } else { "Off" };
        self.robot.send(&format!(
            "<Actions LeftMotor=\"{left}\" RightMotor=\"{right}\" EndLed=\"{}\" ReturningLed=\"{}\" VisitingLed=\"{}\"/>",
            on(END),
            on(RETURNING),
            on(VISITING)
        ));
        self.now = seen(&self.robot.next("Measures"));
        &self.now
    }

    /// Powers off until the robot stands still (the motors' filter halves each tick).
    fn settle(&mut self, leds: u8) {
        loop {
            let (x, y) = (self.now.x, self.now.y);
            let s = self.act(0.0, 0.0, leds);
            if (s.x, s.y) == (x, y) {
                return;
            }
        }
    }
}

/// The client leaves, the user stops the run, and both processes end: the hub's stdout.
fn stop_run(
    d: Driver,
    sess: &str,
    hub: super::common::Proc,
    bridge: super::common::Proc,
    lines: &super::common::Lines,
) -> String {
    drop(d);
    assert_eq!(agent_sdk::control(sess, ipc_types::Command::Stop, 0).map(|r| r.status).ok(), Some(0));
    ended(hub, bridge, lines).0
}

/// The hub's final table entry of robot 1, from its JSON outcome.
fn final_entry(stdout: &str) -> run_records::outcome::ScoreAtEnd {
    let out = HubOutcome::from_stdout(stdout).expect("the hub's JSON line");
    out.scores.into_iter().find(|s| s.id == 1).expect("robot 1 in the final table")
}

#[test]
fn a_competitive_course_visits_returns_and_finishes_with_the_scores_the_rules_give() {
    // One target of radius 1 at (9, 3); the start at (3, 3) facing it. Open floor: the way
    // home is the straight line, d = x − 3 at y = 3.
    let course = Course::new(
        "competitive",
        "<Lab Name=\"course\" Width=\"14\" Height=\"6\"><Target X=\"9\" Y=\"3\" Radius=\"1\"/></Lab>\n",
        "<Grid><Position X=\"3\" Y=\"3\" Dir=\"0\"/></Grid>\n",
        "<Parameters GPS=\"On\" ScoreSensor=\"On\" CycleTime=\"50\" SimTime=\"300\"/>\n",
    );
    let s = session("challenge-0");
    let record = course.dir.join("run.mcap");
    let mut args = course.hub_args("0");
    args.extend(["--record", record.to_str().expect("utf-8")]);
    let (hub, bridge, reg, lines) = hub_and_bridge(&s, &args, &[]);
    let mut d = Driver::register(reg, "visitor");
    // Before the first step the score is 0, as in the real simulator; from it on, 100 + 100
    // per target.
    if d.now.time == 0 {
        assert_eq!(d.now.score, 0);
    }
    while d.act(0.15, 0.15, NONE).x < 8.55 {
        assert_eq!((d.now.score, d.now.visited.as_str()), (200, "0"), "{:?}", d.now);
        // Until the first visit the arrival time follows the clock.
        assert_eq!(d.now.arrival, d.now.time);
    }
    d.settle(NONE);
    // At rest in the target: its centre within 1 − 0.5 of (9, 3).
    assert!((d.now.x - 9.0).abs() <= 0.5, "{:?}", d.now);
    // The visit takes 100 off (P = 200 − 100) and, with the LED on, shows 100 + P = 200; the
    // arrival time stops at the tick before.
    let s = d.act(0.0, 0.0, VISITING).clone();
    assert_eq!((s.score, s.visited.as_str(), s.arrival), (200, "1", s.time - 1), "{s:?}");
    assert_eq!(d.act(0.0, 0.0, NONE).score, 100);
    // ReturningLed over the target with every target visited: P = 0, plus ⌊100 d / d₀⌋ = 100.
    let s = d.act(0.0, 0.0, RETURNING).clone();
    assert_eq!((s.score, s.returning), (100, 0), "{s:?}");
    let (t0, x0) = (s.time, s.x);
    // Backing home: the score is the share of the way still to go; the returning time counts.
    while d.act(-0.15, -0.15, NONE).x > 3.3 {
        let s = &d.now;
        let share = 100.0 * (s.x - 3.0) / (x0 - 3.0);
        assert!((s.score as f64 - share).abs() <= 3.0, "{s:?}: {share}");
        assert_eq!(s.returning, s.time - t0);
    }
    d.settle(NONE);
    let s = d.act(0.0, 0.0, END).clone();
    let share = 100.0 * (s.x - 3.0) / (x0 - 3.0);
    assert!((s.score as f64 - share).abs() <= 3.0 && s.score < 10, "{s:?}: {share}");
    // Finished: it stands still whatever it asks, and its score holds.
    for _ in 0..5 {
        let now = d.act(0.15, 0.15, END).clone();
        assert_eq!((now.x, now.y, now.score, now.returning), (s.x, s.y, s.score, s.returning), "{now:?}");
    }
    // The run ends at SimTime; the bridge goes on as the real simulator does: Measures every
    // cycle, Time frozen, both Buttons off, the LEDs echoed, until the client leaves.
    while d.now.buttons != (false, false) {
        d.act(0.0, 0.0, END);
    }
    assert_eq!(d.now.time, 300);
    for _ in 0..3 {
        let after = seen(&d.robot.next("Measures"));
        assert_eq!((after.time, after.buttons, after.end_led, after.score), (300, (false, false), true, s.score));
    }
    // The client leaves (stops talking): the bridge exits 2 s later, the hub already has.
    let (stdout, _) = ended(hub, bridge, &lines);
    let e = final_entry(&stdout);
    assert_eq!(
        (e.name.as_str(), e.state.as_str(), e.score, e.visited.as_str(), e.returning_ticks),
        ("visitor", "Finished", s.score, "1", s.returning)
    );
    // The recording keeps the table, and a replay of it scores the run again, identically.
    let rec = recorder::read::Recording::open(&record).expect("the recording");
    let table = rec.metadata.get(recorder::CHALLENGE_METADATA).expect("the challenge table");
    assert_eq!(table.get("scoring").map(String::as_str), Some("0"));
    assert_eq!(table.get("robot 00001"), Some(&e.json()));
    let out =
        Proc::spawn(&["replay", record.to_str().expect("utf-8"), "--check", "--json"]).wait(Duration::from_secs(60));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let replayed = HubOutcome::from_stdout(&text(&out.stdout)).expect("the replay's outcome");
    assert_eq!((replayed.scoring, replayed.scores), (0, vec![e]));
}

#[test]
fn a_control_lap_pays_ten_a_cell_until_the_end_led_leaves_the_penalties() {
    // An 8 × 6 lab with a block over its two middle 2 m cells: the loop rings it, 10 cells
    // from the start cell (0, 0) east, north, west and south again (world::challenge's test
    // traces the same loop).
    let course = Course::new(
        "control",
        "<Lab Name=\"ring\" Width=\"8\" Height=\"6\"><Wall Height=\"1\"><Corner X=\"2.1\" Y=\"2.1\"/>\
         <Corner X=\"5.9\" Y=\"2.1\"/><Corner X=\"5.9\" Y=\"3.9\"/><Corner X=\"2.1\" Y=\"3.9\"/></Wall></Lab>\n",
        "<Grid><Position X=\"1\" Y=\"1\" Dir=\"0\"/></Grid>\n",
        "<Parameters GPS=\"On\" ScoreSensor=\"On\" CycleTime=\"50\" CollisionWallPenalty=\"5\"/>\n",
    );
    let sess = session("challenge-1");
    let (hub, bridge, reg, lines) = hub_and_bridge(&sess, &course.hub_args("1"), &[]);
    let mut d = Driver::register(reg, "lapper");
    // Round the ring through the cells' centres, steering by GPS and compass.
    let cell = |x: f64, y: f64| ((x / 2.0) as i64, (y / 2.0) as i64);
    let ring = [(1, 0), (2, 0), (3, 0), (3, 1), (3, 2), (2, 2), (1, 2), (0, 2), (0, 1), (0, 0)];
    let mut earned = 0i64;
    drive_round(&mut d, &[(7.0, 1.0), (7.0, 5.0), (1.0, 5.0), (1.0, 1.0)], |before, now| {
        // Each entry into the loop's next cell pays 10, and nothing else pays.
        let c = cell(now.x, now.y);
        let due = ring[earned as usize % ring.len()] == c && cell(before.x, before.y) != c;
        assert_eq!(now.score, before.score + 10 * i64::from(due), "{now:?} in {c:?}");
        earned += i64::from(due);
        assert!(!now.collision, "{now:?}");
    });
    // One lap: ten cells in order, 100.
    assert_eq!((earned, d.now.score), (10, 100));
    // On south from (1, 1), into the border: one contact event however long it lasts, −5
    // (the robot stays in the start cell: nothing more to earn).
    let mut pushes = 0;
    while pushes < 5 {
        d.act(0.15, 0.15, NONE);
        pushes += d.now.collision as u32;
    }
    assert_eq!((d.now.score, d.now.collisions), (95, 1), "{:?}", d.now);
    // EndLed: the lap points go, the penalties stay.
    let s = d.act(0.0, 0.0, END).clone();
    assert_eq!(s.score, -5, "{s:?}");
    let stdout = stop_run(d, &sess, hub, bridge, &lines);
    let e = final_entry(&stdout);
    assert_eq!((e.state.as_str(), e.score, e.collisions), ("Finished", -5, 1));
}

#[test]
fn mapping_and_planning_charge_each_contact_once_and_finish_on_the_end_led() {
    // Modes 2 and 3 score as the competitive mode from 0: a wall contact adds
    // CollisionWallPenalty (3 here) once, however long the robot pushes.
    let course = Course::new(
        "mapping",
        "<Lab Name=\"box\" Width=\"8\" Height=\"6\"><Target X=\"2\" Y=\"3\" Radius=\"1\"/></Lab>\n",
        "<Grid><Position X=\"5\" Y=\"3\" Dir=\"0\"/></Grid>\n",
        "<Parameters GPS=\"On\" ScoreSensor=\"On\" CycleTime=\"50\" CollisionWallPenalty=\"3\"/>\n",
    );
    for mode in ["2", "3"] {
        let sess = session(&format!("challenge-{mode}"));
        let (hub, bridge, reg, lines) = hub_and_bridge(&sess, &course.hub_args(mode), &[]);
        let mut d = Driver::register(reg, "mapper");
        for push in 1..=2 {
            // Into the east border (x = 8, the rim 0.5 ahead of the centre) for five ticks.
            let mut contact = 0;
            while contact < 5 {
                contact += d.act(0.15, 0.15, NONE).collision as u32;
            }
            assert_eq!((d.now.score, d.now.collisions), (3 * push, push as u32), "mode {mode}: {:?}", d.now);
            // Off the wall again.
            while d.now.x > 6.5 {
                d.act(-0.15, -0.15, NONE);
            }
            assert_eq!(d.now.score, 3 * push, "{:?}", d.now);
        }
        // Nothing visited (no VisitingLed) and no returning: EndLed alone finishes it.
        let s = d.act(0.0, 0.0, END).clone();
        assert_eq!((s.score, s.visited.as_str(), s.arrival), (6, "0", s.time), "{s:?}");
        let stdout = stop_run(d, &sess, hub, bridge, &lines);
        let e = final_entry(&stdout);
        assert_eq!((e.state.as_str(), e.score, e.collisions), ("Finished", 6, 2), "mode {mode}");
    }
}

#[test]
fn line_mapping_pays_ten_for_each_tick_away_from_every_line() {
    // A line (a wall of height 0) across the lab at y = 2.9–3.1; the robot starts on it facing
    // north and drives off it. Modes 5 and 6 pay 10 for each tick its centre is more than
    // 0.5 m from every line and wall (the border too): here min(y − 3.1, 6 − y, x, 10 − x).
    let course = Course::new(
        "lines",
        "<Lab Name=\"lines\" Width=\"10\" Height=\"6\"><Wall Height=\"0\"><Corner X=\"0\" Y=\"2.9\"/>\
         <Corner X=\"10\" Y=\"2.9\"/><Corner X=\"10\" Y=\"3.1\"/><Corner X=\"0\" Y=\"3.1\"/></Wall></Lab>\n",
        "<Grid><Position X=\"4\" Y=\"3\" Dir=\"90\"/></Grid>\n",
        "<Parameters GPS=\"On\" ScoreSensor=\"On\" CycleTime=\"50\"/>\n",
    );
    for mode in ["5", "6"] {
        let sess = session(&format!("challenge-{mode}"));
        let (hub, bridge, reg, lines) = hub_and_bridge(&sess, &course.hub_args(mode), &[]);
        let mut d = Driver::register(reg, "liner");
        assert_eq!(d.now.score, 0);
        let clear = |x: f64, y: f64| (y - 3.1).abs().min((y - 2.9).abs()).min(6.0 - y).min(x).min(10.0 - x) > 0.5;
        let mut expected = 0;
        let mut paid = 0;
        while d.now.y < 5.0 {
            d.act(0.05, 0.05, NONE);
            expected += 10 * i64::from(clear(d.now.x, d.now.y));
            assert_eq!(d.now.score, expected, "mode {mode}: {:?}", d.now);
            paid += i64::from(clear(d.now.x, d.now.y));
        }
        assert!(paid > 5, "only {paid} ticks off the line");
        let s = d.act(0.0, 0.0, END).clone();
        // The tick EndLed lands on still pays if the robot is clear; the score is then final.
        expected += 10 * i64::from(clear(s.x, s.y));
        assert_eq!(s.score, expected, "{s:?}");
        let stdout = stop_run(d, &sess, hub, bridge, &lines);
        assert_eq!(final_entry(&stdout).score, expected, "mode {mode}");
    }
}

/// Drives round `waypoints` by GPS and compass (turning on the spot when far off course);
/// after each tick calls `tick` with the Measures before and after.
fn drive_round(d: &mut Driver, waypoints: &[(f64, f64)], mut tick: impl FnMut(&Seen, &Seen)) {
    let mut next = 0;
    for _ in 0..3000 {
        let (wx, wy) = waypoints[next];
        let (x, y) = (d.now.x, d.now.y);
        if (x - wx).hypot(y - wy) < 0.3 {
            next += 1;
            if next == waypoints.len() {
                return;
            }
            continue;
        }
        let want = (wy - y).atan2(wx - x);
        let err = (want - d.now.compass.to_radians() + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        // Not a round speed: the robot's positions then never land within the GPS's 6 digits
        // of a cell's edge, where the client could not tell which side it is on.
        let v = 0.0937;
        let (l, r) =
            if err.abs() > 0.3 { (-0.05 * err.signum(), 0.05 * err.signum()) } else { (v - v * err, v + v * err) };
        let before = d.now.clone();
        d.act(l, r, NONE);
        tick(&before, &d.now);
    }
    panic!("the course was not driven: {:?}", d.now);
}

#[test]
fn line_control_laps_pay_each_next_cell_and_charge_each_tick_off_the_lines() {
    // A rectangle of 0.2 m lines round (1, 1)–(5, 4). Mode 4's loop is its 14 whole-metre
    // points, mode 7's its 28 half-metre points; a lap earns 10 for each, and each tick the
    // robot is off the loop costs 10 (mode 4: its whole-metre cell is none of the loop's;
    // mode 7: no loop point within 0.25 m on both axes), worked out here from its GPS.
    let course = Course::new(
        "line-control",
        "<Lab Name=\"ring\" Width=\"7\" Height=\"6\">\
         <Wall Height=\"0\"><Corner X=\"0.9\" Y=\"0.9\"/><Corner X=\"5.1\" Y=\"0.9\"/><Corner X=\"5.1\" Y=\"1.1\"/><Corner X=\"0.9\" Y=\"1.1\"/></Wall>\
         <Wall Height=\"0\"><Corner X=\"0.9\" Y=\"3.9\"/><Corner X=\"5.1\" Y=\"3.9\"/><Corner X=\"5.1\" Y=\"4.1\"/><Corner X=\"0.9\" Y=\"4.1\"/></Wall>\
         <Wall Height=\"0\"><Corner X=\"0.9\" Y=\"0.9\"/><Corner X=\"1.1\" Y=\"0.9\"/><Corner X=\"1.1\" Y=\"4.1\"/><Corner X=\"0.9\" Y=\"4.1\"/></Wall>\
         <Wall Height=\"0\"><Corner X=\"4.9\" Y=\"0.9\"/><Corner X=\"5.1\" Y=\"0.9\"/><Corner X=\"5.1\" Y=\"4.1\"/><Corner X=\"4.9\" Y=\"4.1\"/></Wall>\
         </Lab>\n",
        "<Grid><Position X=\"1\" Y=\"1\" Dir=\"0\"/></Grid>\n",
        "<Parameters GPS=\"On\" ScoreSensor=\"On\" CycleTime=\"50\"/>\n",
    );
    // The loop's points in metres, `step` apart, round the rectangle.
    let ring = |step: f64| {
        let n = |a: f64, b: f64| ((b - a) / step).round() as i64;
        let mut pts = Vec::new();
        pts.extend((0..n(1.0, 5.0)).map(|k| (1.0 + k as f64 * step, 1.0)));
        pts.extend((0..n(1.0, 4.0)).map(|k| (5.0, 1.0 + k as f64 * step)));
        pts.extend((0..n(1.0, 5.0)).map(|k| (5.0 - k as f64 * step, 4.0)));
        pts.extend((0..n(1.0, 4.0)).map(|k| (1.0, 4.0 - k as f64 * step)));
        pts
    };
    for (mode, step) in [("4", 1.0), ("7", 0.5)] {
        let pts = ring(step);
        let n = pts.len();
        assert_eq!(n, if mode == "4" { 14 } else { 28 });
        // Mode 4: the robot is at loop point k when its whole-metre cell (x + 0.5 and y + 0.5
        // truncated) is k's. Mode 7: near k when within 0.5 m of it on both axes (so the next
        // point can already be near: its pay then comes a tick early). The corner rule of
        // mode 7 never applies here: no two points either side of one touch.
        let at = |k: usize, x: f64, y: f64| {
            let (px, py) = pts[k];
            if mode == "4" {
                ((x + 0.5).trunc(), (y + 0.5).trunc()) == (px, py)
            } else {
                (px - x).abs() < 0.5 && (py - y).abs() < 0.5
            }
        };
        let sess = session(&format!("challenge-{mode}"));
        let (hub, bridge, reg, lines) = hub_and_bridge(&sess, &course.hub_args(mode), &[]);
        let mut d = Driver::register(reg, "follower");
        let (mut next, mut expected, mut paid, mut off_ticks) = (1usize, 0i64, 0usize, 0usize);
        drive_round(&mut d, &[(5.0, 1.0), (5.0, 4.0), (1.0, 4.0), (1.0, 1.0)], |_, now| {
            if at(next, now.x, now.y) {
                next = (next + 1) % n;
                expected += 10;
                paid += 1;
            }
            if !(0..n).any(|k| at(k, now.x, now.y)) {
                expected -= 10;
                off_ticks += 1;
            }
            assert_eq!(now.score, expected, "mode {mode}: {now:?}");
        });
        // The whole lap was paid, point by point.
        assert!(paid >= n, "mode {mode}: {paid} of {n} points paid, {off_ticks} ticks off the loop");
        let s = d.act(0.0, 0.0, END).clone();
        assert_eq!(s.score, 0, "{s:?}");
        let stdout = stop_run(d, &sess, hub, bridge, &lines);
        assert_eq!(final_entry(&stdout).state, "Finished", "mode {mode}");
    }
}
