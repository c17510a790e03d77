//! The hub's record of a run: every run recorded, replayed bit for bit (`iwsim replay
//! --check`), an altered recording caught at the tick it was altered, a hub killed mid-run
//! leaving a readable file, and the file proven by the third-party Python `mcap` reader.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use recorder::journal::Event;
use recorder::{Recorder, RecorderOptions, Recording};
use run_records::outcome::HubOutcome;
use run_records::summary::RunSummary;

use super::common::{Proc, assert_no_shared_memory_left, session, text};

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("iwsim-e2e-replay-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `iwsim replay FILE --check --json`: (exit code, the replay's outcome, stderr).
fn replay_check(file: &Path) -> (Option<i32>, Option<HubOutcome>, String) {
    let out =
        Proc::spawn(&["replay", file.to_str().expect("utf-8"), "--check", "--json"]).wait(Duration::from_secs(120));
    (out.status.code(), HubOutcome::from_stdout(&text(&out.stdout)).ok(), text(&out.stderr))
}

/// Runs a scenario, then replays its recording with --check: every tick's hash equal, and
/// the replay ends on the run's own final state hash.
fn recorded_run_replays_exactly(scenario: &str, extra: &[&str]) {
    let dir = out_dir(&scenario.replace([':', '/', '.'], "-"));
    let mut args = vec!["run", scenario, "--headless", "--out", dir.to_str().expect("utf-8")];
    args.extend_from_slice(extra);
    let run = Proc::spawn(&args).wait(Duration::from_secs(180));
    let summary = RunSummary::read(&dir.join("summary.json")).unwrap_or_else(|e| panic!("{e}\n{}", text(&run.stderr)));
    let (code, replayed, stderr) = replay_check(&dir.join("run.mcap"));
    assert_eq!(code, Some(0), "{stderr}");
    let replayed = replayed.expect("the replay's JSON line");
    assert_eq!((replayed.ticks, replayed.state_hash), (summary.ticks, summary.state_hash), "{stderr}");
    assert!(stderr.contains(&format!("every one of the {} ticks matches the recording", summary.ticks)), "{stderr}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_lock_step_slalom_replays_bit_for_bit() {
    recorded_run_replays_exactly("builtin:slalom", &["--lockstep", "--seed", "3"]);
}

#[test]
fn a_lock_step_corridor_swap_replays_bit_for_bit() {
    recorded_run_replays_exactly("builtin:corridor-swap", &["--lockstep", "--seed", "7"]);
}

#[test]
fn a_real_time_door_run_replays_bit_for_bit() {
    // The door scenario in real time (ticks on the clock, agents answering when they can),
    // cut to 8 simulated seconds so the test takes 8 s: the door opens for the chair in that
    // time. The actions are recorded as the hub applied them, so timing does not matter.
    let dir = out_dir("door-rt");
    std::fs::create_dir_all(&dir).expect("dir");
    let toml = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("runner/scenarios/door.toml"))
        .expect("the door scenario");
    assert!(toml.contains("seconds = 60"), "the door scenario changed: update this test");
    let scenario = dir.join("door-short.toml");
    std::fs::write(&scenario, toml.replace("seconds = 60", "seconds = 8")).expect("scenario written");
    recorded_run_replays_exactly(scenario.to_str().expect("utf-8"), &[]);
    let _ = std::fs::remove_dir_all(dir);
}

/// Copies `from` to `to` with `change` applied to its replay events.
fn rewrite(from: &Path, to: &Path, change: impl FnOnce(&mut Vec<Event>)) {
    let rec = Recording::open(from).expect("a recording");
    let mut events = rec.events.clone();
    change(&mut events);
    let mut out = Recorder::create(to, &rec.start, RecorderOptions::default()).expect("created");
    for e in &events {
        out.event(e);
    }
    out.finish().expect("written");
}

#[test]
fn an_altered_action_fails_the_check_at_its_tick() {
    let dir = out_dir("altered");
    let run = Proc::spawn(&[
        "run",
        "builtin:slalom",
        "--lockstep",
        "--seed",
        "3",
        "--headless",
        "--out",
        dir.to_str().expect("utf-8"),
    ])
    .wait(Duration::from_secs(120));
    assert!(run.status.success(), "{}", text(&run.stderr));
    let altered = dir.join("altered.mcap");
    let mut at = None;
    rewrite(&dir.join("run.mcap"), &altered, |events| {
        // The chair's powers at tick 300, a hair off.
        for e in events.iter_mut() {
            if let Event::Step { tick: 300, actions, .. } = e {
                let a = actions.iter_mut().find(|a| a.motors.is_some()).expect("the chair drives at tick 300");
                let m = a.motors.as_mut().expect("motors");
                m[0] += 1e-6;
                at = Some(301);
            }
        }
    });
    assert_eq!(at, Some(301), "tick 300 was changed");
    // The unaltered copy passes (the copying itself changes nothing)…
    let same = dir.join("same.mcap");
    rewrite(&dir.join("run.mcap"), &same, |_| {});
    assert_eq!(replay_check(&same).0, Some(0));
    // … and the altered one fails, naming the first tick whose state differs.
    let (code, _, stderr) = replay_check(&altered);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("tick 301: state hash"), "{stderr}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_hub_killed_mid_run_leaves_a_recording_that_replays_to_its_last_chunk() {
    let s = session("kill9rec");
    let dir = out_dir("kill9");
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("run.mcap");
    let mut hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lockstep",
        "--wait-agents",
        "1",
        "--record",
        file.to_str().expect("utf-8"),
    ]);
    let agent = Proc::spawn(&["agent", "wheelchair", "--session", &s, "--robots", "4", "--powers=0.3,0.25"]);
    // Chunks close every simulated second: wait for a few to reach the disk.
    let start = Instant::now();
    while std::fs::metadata(&file).map_or(0, |m| m.len()) < 600_000 {
        assert!(start.elapsed() < Duration::from_secs(60), "the recording did not grow");
        std::thread::sleep(Duration::from_millis(20));
    }
    hub.kill9();
    let a = agent.wait(Duration::from_secs(10));
    assert!(!text(&a.stderr).is_empty(), "the agent said why it stopped");
    // Replayed, it goes as far as the file does, and says what was lost.
    let out = Proc::spawn(&["replay", file.to_str().expect("utf-8")]).wait(Duration::from_secs(60));
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stderr.contains("are lost"), "says what was lost: {stderr}");
    let ticks: u64 = stdout
        .split("replayed ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(ticks >= 10, "replayed {ticks} ticks: {stdout}");
    // Checked, it fails (issue 27: it used to pass): what it holds matches, but the run cannot
    // be checked to its end; it says how far it got.
    let out = Proc::spawn(&["replay", file.to_str().expect("utf-8"), "--check"]).wait(Duration::from_secs(60));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&format!("the {ticks} ticks the recording holds match, but it is cut short")), "{stderr}");
    assert_no_shared_memory_left(&s);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_python_mcap_reader_decodes_a_runs_recording_and_agrees_with_its_summary() {
    let dir = out_dir("python");
    let run = Proc::spawn(&[
        "run",
        "builtin:corridor-swap",
        "--lockstep",
        "--seed",
        "2",
        "--headless",
        "--out",
        dir.to_str().expect("utf-8"),
    ])
    .wait(Duration::from_secs(120));
    assert!(run.status.success(), "{}", text(&run.stderr));
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let out = std::process::Command::new(&python)
        .arg(test_support::python::checker_script())
        .arg(dir.join("run.mcap"))
        .arg("--summary")
        .arg(dir.join("summary.json"))
        .output()
        .expect("python runs");
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(stdout.contains("robots: 2\n") && stdout.contains("summary: 2 final poses match"), "{stdout}");
    let _ = std::fs::remove_dir_all(dir);
}
