//! ROS 2 through `iwsim ros2`, checked from the ROS side by a node made of third-party parts
//! only (tests/ros2/rmw_node.py: the official Zenoh binding and PyPI `rosbags`, from
//! rmw_zenoh's documented wire format), judged from the hub's own recording.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use super::common::{Lines, Proc, assert_no_shared_memory_left, free_port, session, text};

fn work_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-ros2-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("work dir");
    dir
}

/// A Zenoh router on a free local port, as rmw_zenoh's nodes meet through one; its endpoint.
fn router() -> (Proc, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut r = Proc::spawn(&["zenoh-router", "--listen", &endpoint]);
    let said = Lines::read(r.0.as_mut().and_then(|c| c.stderr.take()).expect("stderr"));
    said.said("routing on", Duration::from_secs(30));
    (r, endpoint)
}

fn python_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros2").join(name)
}

/// `key value…` lines of a script's output: the values after `key`.
fn values<'a>(said: &'a str, key: &str) -> Vec<&'a str> {
    said.lines()
        .find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
        .unwrap_or_else(|| panic!("{key} in\n{said}"))
        .split_whitespace()
        .collect()
}

/// One run of `round_trip.py` (with `node_args` after the endpoint) against `iwsim ros2`
/// serving chair1 at (4, 4, 0) on builtin:thesis, noise off, for `ticks` ticks (`lockstep`
/// or real time), recorded to `recording`; what the node and the bridge said, once all ended.
fn round_trip_run(
    s: &str,
    recording: &Path,
    lockstep: bool,
    ticks: u64,
    bridge_args: &[&str],
    node_args: &[&str],
) -> (String, String) {
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let (router, endpoint) = router();
    let ticks = ticks.to_string();
    let mut hub_args = vec!["hub", "--session", s, "--lab", "builtin:thesis", "--ticks", &ticks];
    if lockstep {
        hub_args.push("--lockstep");
    }
    hub_args.extend(["--wait-agents", "1", "--no-noise", "--record", recording.to_str().expect("utf-8")]);
    let hub = Proc::spawn(&hub_args);
    let mut args =
        vec!["ros2", "--session", s, "--chair", "chair1=4,4,0", "--connect", &endpoint, "--connect-timeout", "30"];
    args.extend(bridge_args);
    let bridge = Proc::spawn(&args);
    let node = Command::new(&python)
        .arg(python_script("round_trip.py"))
        .arg(&endpoint)
        .args(node_args)
        .output()
        .expect("python runs");
    let said = text(&node.stdout);
    assert!(node.status.success(), "{said}\n{}", text(&node.stderr));
    let h = hub.wait(Duration::from_secs(60));
    assert!(h.status.success(), "{}", text(&h.stderr));
    let b = bridge.wait(Duration::from_secs(30));
    let bridge_said = text(&b.stdout) + &text(&b.stderr);
    assert!(b.status.success(), "{bridge_said}");
    router.signal("INT");
    router.wait(Duration::from_secs(20));
    (said, bridge_said)
}

#[test]
fn a_ros_2_node_made_of_zenoh_and_rosbags_reads_every_topic_and_drives_the_chair_on_the_commanded_arc() {
    let s = session("ros2-round-trip");
    let dir = work_dir("round-trip");
    let recording = dir.join("run.mcap");
    let ticks = 100;
    let (said, bridge_said) = round_trip_run(&s, &recording, true, ticks, &[], &["chair1", "0.3", "0.3"]);
    // The node's junk on cmd_vel was counted and dropped; the run went on (below).
    assert!(bridge_said.contains("1 cmd_vel samples were not a geometry_msgs/msg/Twist"), "{bridge_said}");

    // Transient-local /map: the lab's walls on 5 cm cells (builtin:thesis is 28 m x 14 m),
    // and the chair's static frames with the start pose as map -> odom.
    assert_eq!(values(&said, "map"), ["560", "280", "0.050", "map"], "{said}");
    let occupied: usize = values(&said, "map_occupied")[0].parse().expect("a count");
    // Two walls: 2 m x 9 m and an L of 8 m2, 26 m2 in all: 10,400 cells of 5 cm.
    assert!((8_000..11_000).contains(&occupied), "{said}");
    let frames = values(&said, "tf_static");
    for f in ["base_link>prox0", "base_link>prox7", "map>odom"] {
        assert!(frames.contains(&f), "{f} in {frames:?}");
    }
    // Lock-step: /clock, odom and scan once per tick, every one decoded by rosbags, every
    // sample with rmw_zenoh's attachment; the command answered every tick.
    let clock: u64 = values(&said, "clock")[0].parse().expect("a count");
    assert_eq!(clock, ticks + 1, "{said}");
    assert_eq!(values(&said, "odom")[..3], [clock.to_string().as_str(), "odom", "base_link"], "{said}");
    assert_eq!(values(&said, "scan")[..3], [clock.to_string().as_str(), "base_link", "360"], "{said}");
    assert_eq!(values(&said, "bad_attachments"), ["0"], "{said}");

    // The hub's record: the true track of a chair told 0.3 m/s and 0.3 rad/s is an arc of
    // radius 1 m about (4, 5), tangent to its start heading. The motor filter ramps both
    // wheels alike, so the curvature holds from the first tick: every point is on the circle.
    let run = plot::track::RecordedRun::read(&recording, &["chair1".to_owned()]).unwrap_or_else(|e| panic!("{e}"));
    let (_, track) = &run.robots[0];
    let samples = &track.samples;
    assert!(samples.len() as u64 >= ticks, "{} samples", samples.len());
    for (i, p) in samples.iter().enumerate() {
        let r = (p.x_m - 4.0).hypot(p.y_m - 5.0);
        assert!((r - 1.0).abs() < 0.02, "sample {i} at ({}, {}) is {r} m from (4, 5)", p.x_m, p.y_m);
    }
    let (first, last) = (&samples[0], &samples[samples.len() - 1]);
    // 10 s at 0.3 rad/s, less the filter's ramp: well over a third of a turn.
    let turned = (last.heading_deg - first.heading_deg).rem_euclid(360.0);
    assert!(turned > 120.0, "the chair turned {turned} degrees");
    // The odometry the node read ends where the truth does (no noise in this run), in the
    // odom frame whose origin is the start pose.
    let odom = values(&said, "odom_pose");
    let (ox, oy): (f64, f64) = (odom[0].parse().expect("x"), odom[1].parse().expect("y"));
    let (tx, ty) = (last.x_m - 4.0, last.y_m - 4.0);
    assert!((ox - tx).abs() < 0.05 && (oy - ty).abs() < 0.05, "odom ({ox}, {oy}) against the truth ({tx}, {ty})");
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_controller_that_falls_silent_is_stopped_by_the_zero_velocity_timeout_in_real_time() {
    let s = session("ros2-timeout");
    let dir = work_dir("timeout");
    let recording = dir.join("run.mcap");
    // Real time, 8 s: the node drives 0.3 m/s straight for 15 clocks, then hangs.
    let (said, _) =
        round_trip_run(&s, &recording, false, 80, &["--cmd-vel-timeout", "0.5"], &["chair1", "0.3", "0", "15"]);

    // The node's last command answered the clock at `last` (simulated seconds).
    let sent = values(&said, "cmd_vel");
    assert_eq!(sent[0], "15", "{said}");
    let last: f64 = sent[1].parse().expect("a stamp");
    // The truth, from the hub's record, at simulated time t (the sample at or after it).
    let run = plot::track::RecordedRun::read(&recording, &["chair1".to_owned()]).unwrap_or_else(|e| panic!("{e}"));
    let samples = &run.robots[0].1.samples;
    let at = |t: f64| {
        let p = samples.iter().find(|p| p.time_s >= t - 1e-9).unwrap_or_else(|| panic!("no sample at {t} s"));
        (p.x_m, p.y_m)
    };
    let dist = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0).hypot(b.1 - a.1);
    // Within the timeout of its last command the chair still drives (at about 0.28 m/s by
    // then: 0.11 m in 0.4 s) ...
    let going = dist(at(last), at(last + 0.4));
    assert!(going > 0.06, "{going} m in the 0.4 s after the last command\n{said}");
    // ... and then the driver stops it: over the run's last 1.5 s (at least 3 s after the
    // last command; on the last command alone it would go 0.4 m) it moves less than 1 cm.
    let end = samples.last().expect("samples").time_s;
    assert!(end - last >= 4.5, "the run ended {end} s, the last command {last} s");
    let resting = dist(at(end - 1.5), at(end));
    assert!(resting < 0.01, "{resting} m in the last 1.5 s: the silent controller's chair did not stop");
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bench_ros2_measures_chairs_driven_over_ros_2_beside_shared_memory() {
    // Small, for the suite: the figures docs/ros2.md quotes come from the default sizes.
    let out = Proc::spawn(&["bench", "ros2", "--chairs", "2", "--ticks", "50", "--runs", "1", "--json"])
        .wait(Duration::from_secs(120));
    let said = text(&out.stdout);
    assert!(out.status.success(), "{said}\n{}", text(&out.stderr));
    let line = said.lines().last().unwrap_or_default();
    let v: serde_json::Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
    let size = &v["sizes"][0];
    assert_eq!(size["chairs"], 2, "{v}");
    for key in ["ros2_ticks_per_s", "shm_ticks_per_s", "ros2_over_shm"] {
        let median = size[key]["median"].as_f64().unwrap_or(0.0);
        assert!(median > 0.0, "{key} in {v}");
    }
    assert!(v["cpu"].as_str().is_some_and(|c| !c.is_empty()), "{v}");
}

/// The thesis slalom (`builtin:slalom`) with its chair served by `iwsim ros2`, for a ROS 2
/// controller to drive: the scenario file a user writes.
fn slalom_over_ros2(endpoint: &str) -> String {
    let slalom = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("runner/scenarios/slalom.toml"))
        .expect("the slalom scenario");
    let (head, tail) = slalom.split_once("[[agents]]").expect("an agent");
    let (_, rest) = tail.split_once("\n\n").expect("the agent's table ends");
    format!(
        "{head}[[agents]]\nkind = \"ros2\"\noptions = {{ chair = [\"chair1=10,6.1,0\"], connect = \"{endpoint}\" }}\n\n{rest}"
    )
}

#[test]
fn a_ros_2_go_to_goal_controller_drives_the_slalom_to_checkpoint_2_without_a_contact() {
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let dir = work_dir("go-to-goal");
    for seed in 1..=5 {
        let (router, endpoint) = router();
        let scenario = dir.join(format!("slalom-ros2-{seed}.toml"));
        std::fs::write(&scenario, slalom_over_ros2(&endpoint)).expect("scenario written");
        let out = dir.join(format!("out{seed}"));
        let run = Proc::spawn(&[
            "run",
            scenario.to_str().expect("utf-8"),
            "--lockstep",
            // A ROS 2 stack may think for seconds (this one's planner, on a loaded machine):
            // the deadline leaves it room, so the run is the same run however busy the
            // machine is (a met deadline changes nothing).
            "--deadline-ms",
            "60000",
            "--headless",
            "--seed",
            &seed.to_string(),
            "--out",
            out.to_str().expect("utf-8"),
        ]);
        // The ROS side: odom, scan, /map and tf_static in, cmd_vel out, on the simulation's clock.
        let node = Command::new(&python)
            .arg(python_script("go_to_goal.py"))
            .args([&endpoint, "chair1", "20.0", "6.1"])
            .output()
            .expect("python runs");
        let said = text(&node.stdout);
        let r = run.wait(Duration::from_secs(300));
        router.signal("INT");
        router.wait(Duration::from_secs(20));
        assert!(node.status.success(), "seed {seed}: {said}\n{}", text(&node.stderr));
        // The deadline asked for is the one the hub kept (its record says so).
        let rec = recorder::Recording::open(out.join("run.mcap")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rec.start.deadline_ms, 60_000, "seed {seed}");
        // Judged from the hub's record: checkpoint 2 reached, no contact of any kind.
        let summary =
            run_records::summary::RunSummary::read(&out.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            r.status.success() && summary.passed,
            "seed {seed}: {:?}\n{}\n{said}",
            summary.failures,
            text(&r.stdout)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
