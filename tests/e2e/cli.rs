//! `iwsim map`, `bench world` and `demo` run as a user runs them: real processes, real files.

use std::path::PathBuf;
use std::process::{Command, Output};

pub fn iwsim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_iwsim")).args(args).output().expect("iwsim runs")
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write temp file");
    path
}

#[test]
fn map_check_summarises_every_built_in_lab() {
    for (name, walls) in [("liacc", "walls: 23"), ("thesis", "walls: 2"), ("maze", "walls: ")] {
        let out = iwsim(&["map", "check", &format!("builtin:{name}")]);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        assert!(text.contains(walls), "{name}: {text}");
    }
    let thesis = String::from_utf8_lossy(&iwsim(&["map", "check", "builtin:thesis"]).stdout).into_owned();
    assert!(
        thesis.contains("28 m x 14 m") && thesis.contains("beacons: 1") && thesis.contains("targets: 1"),
        "{thesis}"
    );
}

#[test]
fn run_help_names_every_built_in_scenario() {
    let out = iwsim(&["run", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // clap folds the text; the names are read from the unfolded words.
    let words = text.split_whitespace().collect::<Vec<_>>().join(" ");
    let listed = words.split("Built in:").nth(1).and_then(|t| t.split("Usage:").next()).unwrap_or_default();
    let mut listed: Vec<&str> = listed.split(',').map(|n| n.trim().trim_end_matches('.')).collect();
    let mut builtins: Vec<&str> = runner::scenario::BUILTINS.iter().map(|(name, _)| *name).collect();
    listed.sort_unstable();
    builtins.sort_unstable();
    assert_eq!(listed, builtins, "{text}");
    assert!(words.contains("judged from the hub's recording"), "{text}");
}

#[test]
fn map_check_names_the_line_and_column_of_a_bad_corner() {
    let path = temp_file(
        "bad-corner.xml",
        "<Lab Name=\"bad\" Width=\"10\" Height=\"5\">\n  <Wall Height=\"1\">\n    <Corner X=\"1\" Y=\"1\"/>\n    <Corner X=\"12\" Y=\"1\"/>\n    <Corner X=\"2\" Y=\"2\"/>\n  </Wall>\n</Lab>\n",
    );
    let out = iwsim(&["map", "check", path.to_str().expect("utf-8 path")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains(":4:5:"), "{err}");
    assert!(err.to_lowercase().contains("outside"), "{err}");
}

#[test]
fn map_check_reports_an_unclosed_tag_without_panicking() {
    let path = temp_file("unclosed.xml", "<Lab Width=\"10\" Height=\"5\">\n  <Wall>\n    <Corner X=\"1\" Y=\"1\"/>\n");
    let out = iwsim(&["map", "check", path.to_str().expect("utf-8 path")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(":2:3:") && err.contains("Wall"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn map_check_reads_grid_and_parameter_files() {
    let grid = temp_file(
        "grid.xml",
        "<Grid>\n<Position X=\"3\" Y=\"11\" Dir=\"90\"/>\n<Position X=\"5\" Y=\"7\"/>\n</Grid>\n",
    );
    let out = iwsim(&["map", "check", grid.to_str().expect("utf-8 path")]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("grid, 2 start poses"));
    let params = temp_file("params.xml", "<Parameters CycleTime=\"50\" GPS=\"On\" MotorsNoise=\"0\"/>\n");
    let out = iwsim(&["map", "check", params.to_str().expect("utf-8 path")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("cycle 50 ms") && text.contains("gps on"), "{text}");
}

#[test]
fn map_check_refuses_an_unknown_root_and_a_missing_file() {
    let path = temp_file("hello.xml", "<Hello/>\n");
    let out = iwsim(&["map", "check", path.to_str().expect("utf-8 path")]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains(":1:1:"));
    let out = iwsim(&["map", "check", "/nonexistent/lab.xml"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/lab.xml"));
}

#[test]
fn bench_world_prints_the_documented_json_keys() {
    let out = iwsim(&["bench", "world", "--robots", "30", "--ticks", "20", "--warmup", "5", "--runs", "2", "--json"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for key in [
        "\"robots\":30",
        "\"ticks\":20",
        "\"runs\":2",
        "\"ticks_per_s\":",
        "\"us_per_robot_tick\":",
        "\"same_state_hash\":true",
        "\"variants\":[{\"threads\":1,",
        "\"median\":",
        "\"state_hash\":\"",
    ] {
        assert!(text.contains(key), "{key} missing from {text}");
    }
}

#[test]
fn a_10000_chair_bench_world_ends_in_one_state_on_one_thread_or_two() {
    // 1,000 ticks of 10,000 noisy chairs on tiled LIACC floors, stepped on one thread and on
    // two: the command itself compares the state hashes and fails if they differ.
    let out = iwsim(&[
        "bench",
        "world",
        "--robots",
        "10000",
        "--ticks",
        "1000",
        "--warmup",
        "0",
        "--threads",
        "1,2",
        "--runs",
        "1",
        "--json",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("\"same_state_hash\":true"), "{text}");
    assert!(text.contains("\"threads\":1,") && text.contains("\"threads\":2,"), "{text}");
}

#[test]
fn the_demo_runs_headless_in_lock_step_and_passes() {
    let dir = std::env::temp_dir().join(format!("iwsim-demo-{}", std::process::id()));
    let out = iwsim(&["demo", "--headless", "--lockstep", "--out", dir.to_str().expect("utf-8 path")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("expected outcome: PASS"), "{text}");
    assert!(text.contains("top speed 0.490 m/s") && text.contains("rise time 1.2 s"), "{text}");
    for robot in ["chair1", "chair2", "door1"] {
        let log = std::fs::read_to_string(dir.join(format!("{robot}.csv"))).expect("log written");
        let mut lines = log.lines();
        assert!(
            lines
                .next()
                .expect("header")
                .starts_with("tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m")
        );
        // One line per tick of the 75 s demo (ticks 0..749); the navigator also logs the
        // final state after the last step.
        let ticks: Vec<u64> = lines.map(|l| l.split(',').next().and_then(|t| t.parse().ok()).expect("tick")).collect();
        assert!(ticks.len() == 750 || ticks.len() == 751, "{robot}: {} lines", ticks.len());
        assert!(ticks.iter().enumerate().all(|(k, &t)| t == k as u64), "{robot}: a line per tick, in order");
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// README's main command as a user runs it: real time, where the hub does not wait for the
/// navigator (a search that outlasts the 100 ms cycle leaves the chair on its last command).
/// The lock-step test above does not see that: a change once passed it while this failed.
#[test]
fn the_demo_as_readme_runs_it_in_real_time_passes() {
    let dir = std::env::temp_dir().join(format!("iwsim-demo-real-time-{}", std::process::id()));
    let out = iwsim(&["demo", "--headless", "--out", dir.to_str().expect("utf-8 path")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("real time") || String::from_utf8_lossy(&out.stderr).contains("real time"), "{text}");
    assert!(text.contains("expected outcome: PASS"), "{text}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bench_lockstep_runs_every_transport_under_the_real_load_beside_ipc_only_and_states_the_hub_memory() {
    let bench = Command::new(env!("CARGO_BIN_EXE_iwsim"))
        .args(["bench", "lockstep", "--agents", "2", "--robots-per-agent", "3", "--ticks", "30"])
        .args(["--transport", "shm,udp,zenoh", "--runs", "1", "--json"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("iwsim runs");
    let pid = bench.id();
    let out = bench.wait_with_output().expect("the bench ends");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    for variant in ["shm", "udp", "zenoh", "shm_real", "udp_real", "zenoh_real"] {
        let rate = j[format!("{variant}_ticks_per_s")].as_f64().unwrap_or(0.0);
        assert!(rate > 0.0, "{variant}: no rate in {text}");
        let rss = j[format!("{variant}_hub_peak_rss_mib")].as_f64().unwrap_or(0.0);
        // The hub maps iceoryx2 services for 10,000 robots; whatever it costs, it is stated.
        assert!(rss > 1.0, "{variant}: no hub memory in {text}");
    }
    // The real load's robots stand within each other's sensor range, and the agents (over
    // UDP: the clients parsing Measures) read every robot's every sensor each tick.
    assert!(j["real_neighbours_in_range"].as_f64().unwrap_or(0.0) > 2.0, "{text}");
    // Transports side by side, as ratios of one invocation.
    for key in ["ratio_shm_over_udp", "ratio_zenoh_over_udp", "ratio_shm_over_zenoh"] {
        assert!(j[key].as_f64().is_some_and(|r| r > 0.0), "{key} in {text}");
    }
    for variant in ["shm_real", "udp_real", "zenoh_real"] {
        let readings = j[format!("{variant}_readings")].as_u64().unwrap_or(0);
        let near = j[format!("{variant}_readings_near")].as_u64().unwrap_or(0);
        // Every robot is in from the first tick (over UDP the bridge waits for all six:
        // `iwsim udp --wait-robots`).
        assert!(readings >= 30 * 6 * 8, "{variant}: {readings} readings for 6 robots x 8 sensors x 30 ticks");
        assert!(near > 0 && near < readings, "{variant}: {near} of {readings} readings saw a neighbour");
    }
    // Every run's hub removed its session's shared memory.
    let prefix = format!("iwsim_bench-ls-{pid}-");
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
}

#[test]
fn bench_traffic_runs_navigators_on_the_ward_and_states_rates_and_cpu_per_tick() {
    let out = iwsim(&["bench", "traffic", "--chairs", "2", "--runs", "1", "--seconds", "10", "--json"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    assert!(j["cpu"].as_str().is_some_and(|c| c.contains("cores")), "the CPU is stated: {text}");
    let size = &j["sizes"][0];
    assert_eq!((size["chairs"].as_u64(), size["chairs_in_runs"].as_u64()), (Some(2), Some(2)), "{text}");
    for key in ["ticks_per_s", "hub_cpu_us_per_tick", "navigator_cpu_us_per_tick"] {
        assert!(size[key]["median"].as_f64().is_some_and(|v| v > 0.0), "{key} in {text}");
    }
}
