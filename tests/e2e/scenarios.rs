//! The thesis's experiments as a user runs them (`iwsim run builtin:NAME --lockstep`), the
//! door agent's states across processes, and `iwsim plot` on a real run's log.

use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_sdk::log::LogTable;
use agent_sdk::{Agent, Wait};
use ipc_types::{ActionBlock, REG_HAS_POSE, RobotKind, RobotRegistration};
use observer::Observer;
use run_records::summary::{RobotSummary, RunSummary};

use super::common::{Proc, assert_no_shared_memory_left, robot_named, session, text, truth};

fn out_dir(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!("iwsim-e2e-{tag}-{}", std::process::id()))
}

/// Runs `iwsim ARGS` to the end; returns (success, stdout, stderr).
fn iwsim(args: &[&str], timeout: Duration) -> (bool, String, String) {
    let out = Proc::spawn(args).wait(timeout);
    (out.status.success(), text(&out.stdout), text(&out.stderr))
}

fn summary(dir: &Path) -> RunSummary {
    RunSummary::read(&dir.join("summary.json")).unwrap_or_else(|e| panic!("{e}"))
}

fn robot<'a>(summary: &'a RunSummary, name: &str) -> &'a RobotSummary {
    summary.robots.iter().find(|r| r.name == name).unwrap_or_else(|| panic!("{name} in {summary:?}"))
}

#[test]
fn builtin_dynamics_reports_the_thesis_top_speed_and_rise_time() {
    let dir = out_dir("dynamics");
    let (ok, out, err) = iwsim(
        &["run", "builtin:dynamics", "--lockstep", "--headless", "--out", dir.to_str().expect("utf-8")],
        Duration::from_secs(60),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("expected outcome: PASS"), "{out}");
    let s = summary(&dir);
    let c = robot(&s, "chair1");
    let top = c.top_speed_mps;
    assert!((top - 0.49).abs() <= 0.0049, "top speed {top} within 1 % of 0.49");
    assert_eq!(c.rise_time_s, 1.2, "{c:?}");
    assert_eq!(c.collisions, 0);
    // The log has one line per tick with the units in the header: ticks 0 to 99 answered, and
    // tick 100, where the 10 s run ends.
    let log = std::fs::read_to_string(dir.join("chair1.csv")).expect("log");
    assert!(log.starts_with("tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m"), "{log}");
    assert_eq!(log.lines().count(), 1 + 101);
    assert!(log.lines().last().is_some_and(|l| l.starts_with("100,10.000,")), "{log}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn builtin_door_lets_the_chair_through_for_every_seed() {
    let dir = out_dir("door");
    let (ok, out, err) = iwsim(
        &["run", "builtin:door", "--lockstep", "--seeds", "1..3", "--out", dir.to_str().expect("utf-8")],
        Duration::from_secs(120),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("success rate 3/3 (100 %)") && out.contains("collisions 0 in all"), "{out}");
    for seed in 1..=3 {
        let s = summary(&dir.join(format!("seed-{seed}")));
        assert!(s.passed && s.failures.is_empty(), "{s:?}");
        assert_eq!(robot(&s, "chair1").checkpoints_reached, 1);
        // Shut again at the end: the leaf back across the doorway.
        let h = robot(&s, "door1").final_pose[2];
        assert!((h - 90.0).abs() < 1.5, "door heading {h}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn six_chairs_with_crossing_goals_on_the_ward_all_arrive_on_three_seeds() {
    // builtin:ward as it is: six navigator processes with goals placed by the seed, their
    // ways crossing in the 2 m corridor and its 1 m doorways, lock-step, 300 s. Judged from
    // each run's recording: every chair arrives, nothing touches, no deadlock.
    let dir = out_dir("ward-six");
    let d = dir.to_str().expect("utf-8");
    let args = ["run", "builtin:ward", "--lockstep", "--headless", "--seeds", "1..3", "--out", d];
    let (ok, out, err) = iwsim(&args, Duration::from_secs(600));
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("success rate 3/3 (100 %)") && out.contains("collisions 0 in all"), "{out}");
    for seed in 1..=3 {
        let s = summary(&dir.join(format!("seed-{seed}")));
        let t = s.traffic.as_ref().expect("six chairs on routes: the traffic is measured");
        assert_eq!((t.chairs, t.arrived, t.deadlocks), (6, 6, 0), "seed {seed}: {t:?}");
        assert_eq!((t.contacts_chair, t.contacts_wall, t.contacts_obstacle), (0, 0, 0), "seed {seed}: {t:?}");
        for r in &s.robots {
            assert!(r.min_clearance_chair_m.is_some_and(|m| m > 0.0), "seed {seed}: {r:?}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn chairs_placed_on_the_ward_by_the_seed_each_reach_their_own_goal() {
    // `--chairs 2` on the ward: two navigators with goals of their own, placed by seed 1; the
    // judge reads each chair's route from the placement (its goal), the same for the same seed.
    let dir = out_dir("ward-crowd");
    let d = dir.to_str().expect("utf-8");
    let args = ["run", "builtin:ward", "--chairs", "2", "--lockstep", "--headless", "--seed", "1", "--out", d];
    let (ok, out, err) = iwsim(&args, Duration::from_secs(120));
    assert!(ok, "{out}\n{err}");
    let s = summary(&dir);
    assert!(s.passed && s.failures.is_empty(), "{s:?}");
    assert_eq!(s.robots.len(), 2, "{s:?}");
    // Each chair's checkpoints: its start, then its goal, which is its route.
    assert_eq!(s.checkpoints.len(), 4);
    for (k, name) in ["chair1", "chair2"].into_iter().enumerate() {
        let r = robot(&s, name);
        assert_eq!((r.route.clone(), r.checkpoints_reached, r.collisions), (vec![2 * k + 2], 1, 0), "{r:?}");
        let goal = &s.checkpoints[2 * k + 1];
        let end = r.final_pose;
        assert!((end[0] - goal.x).hypot(end[1] - goal.y) <= goal.radius, "{name} ended at {end:?}, goal {goal:?}");
        // The traffic measures, from the record: arrived, never touching, kept apart.
        assert!(r.arrived && (r.contacts_chair, r.contacts_wall, r.contacts_obstacle) == (0, 0, 0), "{r:?}");
        assert!(r.min_clearance_chair_m.is_some_and(|m| m > 0.0), "{r:?}");
        assert!(r.min_clearance_wall_m.is_some_and(|m| m > 0.0), "{r:?}");
    }
    let t = s.traffic.as_ref().expect("two chairs on routes: the traffic is measured");
    let last = s.robots.iter().filter_map(|r| r.time_s).fold(0.0, f64::max);
    assert_eq!((t.chairs, t.arrived, t.success_rate, t.deadlocks), (2, 2, 1.0, 0), "{t:?}");
    assert!(t.makespan_s.is_some_and(|m| (m - last).abs() < 0.06), "{t:?} (last arrival {last})");
    assert!(out.contains("traffic: 2/2 arrived (100 %)"), "{out}");
    let (ok, _, err) = iwsim(&["run", "builtin:ward", "--chairs", "0", "--headless"], Duration::from_secs(10));
    assert!(!ok && err.contains("--chairs"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_same_seed_in_lock_step_gives_the_same_run() {
    // The door (a door agent and a scripted chair) and the corridor swap (two navigators
    // that talk to each other, so message order counts too).
    for (scenario, logs) in [("door", &["chair1.csv"][..]), ("corridor-swap", &["chair1.csv", "chair2.csv"][..])] {
        let (a, b) = (out_dir(&format!("same-{scenario}-a")), out_dir(&format!("same-{scenario}-b")));
        for d in [&a, &b] {
            let (ok, out, err) = iwsim(
                &[
                    "run",
                    &format!("builtin:{scenario}"),
                    "--lockstep",
                    "--headless",
                    "--seed",
                    "7",
                    "--out",
                    d.to_str().expect("utf-8"),
                ],
                Duration::from_secs(120),
            );
            assert!(ok, "{out}\n{err}");
        }
        let (sa, sb) = (summary(&a), summary(&b));
        assert_eq!(sa.state_hash, sb.state_hash, "{scenario}");
        for log in logs {
            assert_eq!(
                std::fs::read(a.join(log)).expect("log a"),
                std::fs::read(b.join(log)).expect("log b"),
                "{scenario}: identical {log}"
            );
        }
        let _ = std::fs::remove_dir_all(a);
        let _ = std::fs::remove_dir_all(b);
    }
}

#[test]
fn one_seed_gives_one_state_hash_on_one_thread_or_two() {
    // The hub's step on two threads (spread over them from the first robot on) ends where one
    // thread does: every robot's noise is its own, whoever steps it first. And whether the
    // hub spins for the agents' answers (by default, with fewer agents than cores) or sleeps
    // changes when it steps, never what.
    for (scenario, logs) in [("slalom", &["chair1.csv"][..]), ("corridor-swap", &["chair1.csv", "chair2.csv"][..])] {
        let dirs: Vec<PathBuf> = ["one", "two"].iter().map(|t| out_dir(&format!("threads-{scenario}-{t}"))).collect();
        for (d, threads) in dirs
            .iter()
            .zip([&["--threads", "1"][..], &["--threads", "2", "--parallel-min-robots", "0", "--answer-spin-us", "0"]])
        {
            let name = format!("builtin:{scenario}");
            let mut args =
                vec!["run", &name, "--lockstep", "--headless", "--seed", "3", "--out", d.to_str().expect("utf-8")];
            args.extend_from_slice(threads);
            let (ok, out, err) = iwsim(&args, Duration::from_secs(180));
            assert!(ok, "{out}\n{err}");
        }
        let (one, two) = (summary(&dirs[0]), summary(&dirs[1]));
        assert_eq!(one.state_hash, two.state_hash, "{scenario}");
        assert!(one.ticks > 100, "{scenario}: the run went on ({} ticks)", one.ticks);
        for log in logs {
            assert_eq!(
                std::fs::read(dirs[0].join(log)).expect("log on one thread"),
                std::fs::read(dirs[1].join(log)).expect("log on two threads"),
                "{scenario}: identical {log}"
            );
        }
        for d in dirs {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}

#[test]
fn a_bad_scenario_file_is_refused_with_its_line() {
    let dir = out_dir("badscen");
    std::fs::create_dir_all(&dir).expect("dir");
    let f = dir.join("bad.toml");
    std::fs::write(&f, "name = \"bad\"\nseconds = 10\n[[agents]]\nkind = \"navigator\"\noptions = { pose = [1, 2, }\n")
        .expect("write");
    let (ok, _, err) = iwsim(&["run", f.to_str().expect("utf-8"), "--headless"], Duration::from_secs(10));
    assert!(!ok);
    assert!(err.contains("bad.toml") && err.contains("line 5"), "{err}");
    let (ok, _, err) = iwsim(&["run", "builtin:nope"], Duration::from_secs(10));
    assert!(!ok && err.contains("no built-in scenario \"nope\"") && err.contains("slalom"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

/// Reads the door agent's stderr and returns its state changes in order.
fn door_states(stderr: &str) -> Vec<String> {
    stderr
        .lines()
        .filter_map(|l| l.strip_prefix("door door1: "))
        .map(|l| l.split(" at t").next().unwrap_or_default().to_owned())
        .collect()
}

#[test]
fn the_door_opens_on_request_stops_on_contact_retries_and_closes() {
    // A hub in lock-step, the door agent, and this test as an agent with a "real" robot it
    // places by pose: far away, it asks the door to open by message; then it stands in the
    // closing leaf's way; then it leaves.
    let s = session("doorstates");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--no-noise",
        "--ticks",
        "400",
        "--wait-agents",
        "2",
        "--real",
        "visitor",
    ]);
    let door = Proc::spawn(&[
        "agent",
        "door",
        "--session",
        &s,
        "--pose",
        "9.445,5.46,90",
        "--open",
        "90",
        "--trigger",
        "1.0",
        "--quiet",
        "1.0",
        "--retry",
        "1.0",
    ]);
    let mut me = Agent::connect_within(&s, "test-visitor", Duration::from_secs(20)).expect("hub up");
    // The test is the referee: it watches the door's true heading as an observer, beside the
    // robot it drives as an agent.
    let mut referee = Observer::connect_within(&s, "test-referee", Duration::from_secs(20)).expect("hub up");
    let mut reg = RobotRegistration::new("visitor");
    reg.kind = RobotKind::Real as u32;
    reg.flags |= REG_HAS_POSE;
    // Out of the door's 1 m trigger range, 1.6 m from its hinge.
    let far = (11.0, 6.2);
    reg.pose = [far.0, far.1, 0.0];
    (reg.width_m, reg.height_m, reg.com) = (0.6, 0.5, 0.5);
    // A brisk walker: the hub takes a Real robot's poses only as fast as its body can move.
    (reg.max_speed_mps, reg.accel_curve) = (3.0, 0.5);
    let id = me.register(&reg).expect("registered");
    me.ready().expect("ready");
    // In the sweep of the closing leaf (the quarter disc west of the hinge and north of the
    // open leaf, which lies along y 5.46 from x 8.45 to 9.44).
    let in_the_way = (8.9, 6.2);
    let mut at = far;
    let mut phase = 0;
    let mut was_open = false;
    let mut in_way_since = 0;
    while let Some(tick) = me.wait_tick(Wait::Blocking).expect("hub alive") {
        let t = tick.tick;
        let robots = referee.world().expect("world").1;
        let door_heading = robot_named(&mut referee, &robots, "door1")
            .map(|r| r.heading_deg)
            // The newest snapshot this subscriber holds may predate the door's registration.
            .unwrap_or(90.0);
        let open = (door_heading.abs() - 180.0).abs() < 2.0;
        was_open |= open;
        // Once the door has opened and starts to close, step into the leaf's sweep.
        if phase == 0 && was_open && !open {
            phase = 1;
            in_way_since = t;
        }
        if phase == 1 && t > in_way_since + 60 {
            phase = 2;
        }
        // Walk there at 0.4 m a tick (4 m/s for 0.1 s ticks is within 3 m/s and its slack).
        let goal = if phase == 1 { in_the_way } else { far };
        let (dx, dy) = (goal.0 - at.0, goal.1 - at.1);
        let k = (0.4 / dx.hypot(dy).max(1e-9)).min(1.0);
        at = (at.0 + k * dx, at.1 + k * dy);
        let mut act = ActionBlock::pose(id, at.0, at.1, 0.0);
        if t == 5 {
            assert!(act.with_say(b"door open door1"), "message fits");
        }
        me.send(t, &[act]).expect("sent");
    }
    me.close();
    let d = door.wait(Duration::from_secs(20));
    assert!(d.status.success(), "{}", text(&d.stderr));
    let states = door_states(&text(&d.stderr));
    // Opened by the message alone (nothing near), closed into the visitor, stopped, re-opened
    // after the pause, and shut once the visitor left.
    assert!(states.len() >= 7, "{states:?}");
    assert_eq!(&states[..5], ["opening", "open", "closing", "blocked", "opening"], "{states:?}");
    assert_eq!(&states[states.len() - 2..], ["closing", "closed"], "{states:?}");
    let h = hub.wait(Duration::from_secs(20));
    assert!(h.status.success(), "{}", text(&h.stderr));
}

#[test]
fn plot_draws_a_runs_trajectory_as_svg() {
    let dir = out_dir("plot");
    let (ok, out, err) = iwsim(
        &["run", "builtin:door", "--lockstep", "--headless", "--out", dir.to_str().expect("utf-8")],
        Duration::from_secs(60),
    );
    assert!(ok, "{out}\n{err}");
    let recording = dir.join("run.mcap");
    let svg_path = dir.join("chair1.svg");
    let (ok, out, err) = iwsim(
        &["plot", recording.to_str().expect("utf-8"), "--robot", "chair1", "--out", svg_path.to_str().expect("utf-8")],
        Duration::from_secs(30),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("chair1.svg"), "prints the path written: {out}");
    let svg = std::fs::read_to_string(&svg_path).expect("svg written");
    let Outline { root, depth, polylines, texts } = svg_outline(&svg);
    assert_eq!((root.as_deref(), depth), (Some("svg"), 0), "well-formed XML with an <svg> root");
    for want in ["run.mcap: chair1", "x (m)", "y (m)", "speed (m/s)", "1"] {
        assert!(texts.iter().any(|t| t == want), "text {want:?} missing from {texts:?}");
    }
    assert!(texts.iter().any(|t| t.starts_with("lab IW_LIACC")), "the run's lab: {texts:?}");

    // The trajectory: a polyline with a point per recorded frame of chair1, each at chair1's
    // true place. Equal scales on both axes, so its first and last points give the pixels of
    // every metre; every point then maps back into the lab, onto the recorded pose.
    let track = recorder::WorldTrack::open(&recording).expect("the recording reads");
    let truth: Vec<(f64, f64)> = track
        .frames
        .iter()
        .flat_map(|f| f.robots.iter().filter(|r| r.name == "chair1").map(|r| (r.x_m, r.y_m)))
        .collect();
    assert!(truth.len() > 100, "chair1 in {} frames", truth.len());
    let trajectory = polylines.iter().find(|p| p.len() == truth.len()).unwrap_or_else(|| {
        panic!("a {}-point trajectory among polylines of {:?} points", truth.len(), lengths(&polylines))
    });
    let (first, last) = (truth[0], truth[truth.len() - 1]);
    let (p0, p1) = (trajectory[0], trajectory[trajectory.len() - 1]);
    assert!((first.0 - last.0).abs() > 5.0, "chair1 drove west through the door: {first:?} to {last:?}");
    let sx = (p1.0 - p0.0) / (last.0 - first.0);
    assert!(sx > 10.0, "x to the right, {sx} px/m");
    for (k, (&(px, py), &(x, y))) in trajectory.iter().zip(&truth).enumerate() {
        let (mx, my) = (first.0 + (px - p0.0) / sx, first.1 - (py - p0.1) / sx);
        assert!(
            (0.0..=44.0).contains(&mx) && (0.0..=17.75).contains(&my),
            "point {k} at {mx},{my} m is outside the lab"
        );
        assert!((mx - x).hypot(my - y) * sx <= 3.0, "point {k} drawn at {mx},{my} m, recorded at {x},{y}");
    }
    // The speed over time: a point per interval.
    assert!(polylines.iter().any(|p| p.len() == truth.len() - 1), "a speed line: {:?}", lengths(&polylines));

    // Every robot of the run by default: the chair and the door.
    let all = dir.join("run.svg");
    let (ok, out, err) = iwsim(&["plot", recording.to_str().expect("utf-8")], Duration::from_secs(30));
    assert!(ok, "{out}\n{err}");
    let texts = svg_outline(&std::fs::read_to_string(&all).expect("run.svg beside the recording")).texts;
    for want in ["run.mcap", "chair1", "door1", "Who stood still when", "stopped for good (arrived, or stuck)"] {
        assert!(texts.iter().any(|t| t == want), "text {want:?} missing from {texts:?}");
    }
    // Several robots: a timeline of who stood still when, with the seconds stood in all.
    let total = texts.iter().find_map(|t| t.strip_prefix("stood still ≥ 1 s (")?.strip_suffix(" s in all)"));
    assert!(total.is_some_and(|n| n.parse::<f64>().is_ok()), "the waiting timeline's total: {texts:?}");

    // The chair's CSV log: the run has no GPS, so it holds no trajectory, and says where one is.
    let log = dir.join("chair1.csv");
    let (ok, out, err) = iwsim(
        &["plot", log.to_str().expect("utf-8"), "--out", svg_path.to_str().expect("utf-8")],
        Duration::from_secs(30),
    );
    assert!(!ok, "plotting a log without positions fails: {out}");
    let want = format!(
        "{} has no positions (the run has no GPS: its x_m, y_m columns are NaN); draw the run's recording instead: iwsim plot {}",
        log.display(),
        recording.display()
    );
    assert!(err.contains(&want), "{err}");
    let _ = std::fs::remove_dir_all(dir);

    /// What the checks read from an SVG.
    struct Outline {
        /// The root element's name.
        root: Option<String>,
        /// Nesting depth at the end: 0 when every element closed.
        depth: i32,
        /// Each polyline's points, pixels.
        polylines: Vec<Vec<(f64, f64)>>,
        /// Each text's words.
        texts: Vec<String>,
    }

    /// Reads an SVG's outline; panics on malformed XML.
    fn svg_outline(svg: &str) -> Outline {
        let mut reader = quick_xml::Reader::from_str(svg);
        let mut depth = 0i32;
        let mut root = None;
        let mut polylines = Vec::new();
        let mut texts = Vec::new();
        loop {
            match reader.read_event().expect("well-formed SVG") {
                quick_xml::events::Event::Start(e) => {
                    root.get_or_insert_with(|| e.name().into_inner().to_owned());
                    depth += 1;
                }
                quick_xml::events::Event::Empty(e) => {
                    if e.name().into_inner() == "polyline"
                        && let Some(Ok(a)) =
                            e.attributes().find(|a| a.as_ref().is_ok_and(|a| a.key.into_inner() == "points"))
                    {
                        let points = a
                            .value
                            .split_whitespace()
                            .map(|p| {
                                let (x, y) = p.split_once(',').expect("x,y");
                                (x.parse().expect("x"), y.parse().expect("y"))
                            })
                            .collect();
                        polylines.push(points);
                    }
                }
                quick_xml::events::Event::Text(t) => {
                    let text = t.xml10_content().trim().to_owned();
                    if !text.is_empty() {
                        texts.push(text);
                    }
                }
                quick_xml::events::Event::End(_) => depth -= 1,
                quick_xml::events::Event::Eof => break,
                _ => {}
            }
        }
        Outline { root, depth, polylines, texts }
    }

    fn lengths(polylines: &[Vec<(f64, f64)>]) -> Vec<usize> {
        polylines.iter().map(Vec::len).collect()
    }
}

#[test]
fn builtin_slalom_reaches_checkpoint_2_without_contact_for_three_seeds_with_noise() {
    let dir = out_dir("slalom");
    let (ok, out, err) = iwsim(
        &["run", "builtin:slalom", "--lockstep", "--seeds", "1..3", "--out", dir.to_str().expect("utf-8")],
        Duration::from_secs(300),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("success rate 3/3 (100 %)") && out.contains("collisions 0 in all"), "{out}");
    for seed in 1..=3 {
        let s = summary(&dir.join(format!("seed-{seed}")));
        let c = robot(&s, "chair1");
        assert_eq!((c.checkpoints_reached, c.collisions), (1, 0), "{c:?}");
        // It went round obstacle A below it and B above it: between x 17 and 17.6 it was
        // under y 6.1, between 19.4 and 20 above 5.9 (the recording has every tick).
        let track = trajectory(&dir.join(format!("seed-{seed}")), "chair1");
        assert!(track.iter().any(|r| (17.0..17.6).contains(&r[1])), "seed {seed}: it passed A");
        assert!(track.iter().filter(|r| (17.0..17.6).contains(&r[1])).all(|r| r[2] < 6.1), "seed {seed}: below A");
        assert!(track.iter().filter(|r| (19.4..20.0).contains(&r[1])).all(|r| r[2] > 5.9), "seed {seed}: above B");
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A robot's true track in a run, from its recording: rows of (tick, x, y).
fn trajectory(run: &Path, name: &str) -> Vec<[f64; 3]> {
    truth(&run.join("run.mcap")).remove(name).unwrap_or_default().into_iter().map(|r| [r[0], r[1], r[2]]).collect()
}

#[test]
fn builtin_corridor_swap_both_chairs_pass_each_other_without_contact_for_two_seeds() {
    let dir = out_dir("corridor-swap");
    let (ok, out, err) = iwsim(
        &["run", "builtin:corridor-swap", "--lockstep", "--seeds", "1..2", "--out", dir.to_str().expect("utf-8")],
        Duration::from_secs(300),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("success rate 2/2 (100 %)") && out.contains("collisions 0 in all"), "{out}");
    for seed in 1..=2 {
        let run = dir.join(format!("seed-{seed}"));
        let s = summary(&run);
        for name in ["chair1", "chair2"] {
            let c = robot(&s, name);
            assert_eq!((c.checkpoints_reached, c.collisions), (1, 0), "{c:?}");
        }
        // They went by each other side by side: chair2, which yields (its name sorts last),
        // had pulled over to its right (north) and stood still while chair1 went by south
        // of it, with the two chairs' 0.65 m widths and a gap between their centre lines.
        let (one, two) = (trajectory(&run, "chair1"), trajectory(&run, "chair2"));
        let beside = one
            .iter()
            .zip(&two)
            .position(|(a, b)| a[0] == b[0] && a[1] >= b[1])
            .unwrap_or_else(|| panic!("seed {seed}: chair1 never got past chair2"));
        let (a, b) = (one[beside], two[beside]);
        assert!(b[2] - a[2] > 0.7, "seed {seed}: side by side at tick {}: chair1 {a:?}, chair2 {b:?}", a[0]);
        let still = &two[beside.saturating_sub(20)..(beside + 20).min(two.len())];
        let moved = still.iter().map(|r| (r[1] - b[1]).hypot(r[2] - b[2])).fold(0.0, f64::max);
        assert!(moved < 0.01, "seed {seed}: chair2 moved {moved} m while chair1 went by");
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn every_agents_log_ends_with_the_runs_final_tick_under_a_name_no_other_robot_shares() {
    // A door, two scripted chairs and a navigator in one lock-step run of 5 ticks, each agent
    // its own process: every log holds ticks 0 to 4, answered with the agent's powers, then
    // tick 5, the run's end, which nobody answers (zero powers) but which the log still records.
    let s = session("final-tick");
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-final-tick-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let log_dir = dir.to_str().expect("utf-8 temp dir");
    let hub = Proc::spawn(&["hub", "--session", &s, "--lockstep", "--ticks", "5", "--wait-agents", "3", "--json"]);
    let door =
        Proc::spawn(&["agent", "door", "--session", &s, "--name", "front door", "--pose", "12,6,0", "--log", log_dir]);
    let chairs = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "2", "--log", log_dir]);
    let nav_args = ["--name", "nav 1", "--pose", "20,6.1,0", "--checkpoint", "22,6.1", "--log", log_dir];
    let nav = Proc::spawn(&[&["agent", "navigator", "--session", &s][..], &nav_args[..]].concat());
    let out = hub.wait(Duration::from_secs(30));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(door.wait(Duration::from_secs(20)).status.success(), "the door agent ends with the run");
    assert!(chairs.wait(Duration::from_secs(20)).status.success(), "the wheelchair agent ends with the run");
    // The navigator has not arrived in half a second, which it reports with exit code 1.
    assert_eq!(nav.wait(Duration::from_secs(20)).status.code(), Some(1), "the navigator ends with the run");
    // The door's name has a space: its file escapes it rather than turning it into a `_`
    // that a robot named `front_door` would share.
    let logs =
        [("front%20door.csv", None), ("chair1.csv", Some(0.5)), ("chair2.csv", Some(0.5)), ("nav%201.csv", None)];
    for (file, scripted) in logs {
        let log = LogTable::read(&dir.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(robot_log::robot_name_of(&dir.join(file)), file.trim_end_matches(".csv").replace("%20", " "));
        let col = |c: &str| log.column(c).expect("a column");
        let ticks: Vec<f64> = log.rows.iter().map(|r| r[col("tick")]).collect();
        assert_eq!(ticks, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0], "{file}");
        let last = &log.rows[5];
        assert_eq!([last[col("power_left")], last[col("power_right")]], [0.0, 0.0], "{file}: the end is unanswered");
        assert!((last[col("time_s")] - 0.5).abs() < 1e-9, "{file}: the final tick's own time");
        if let Some(p) = scripted {
            assert_eq!(log.rows[4][col("power_left")], p, "{file}: answered ticks carry the script's powers");
        }
    }
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}
