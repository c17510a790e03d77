//! Mixed reality as a user runs it (thesis Table 7.3's real and augmented rows): `iwsim run`
//! with a physical chair — the chair emulator in a room of its own, behind the serial adapter
//! — lock-step with the emulator's clock stepped by the adapter, judged in both worlds; the
//! proof that merging real and virtual readings matters; and a Ctrl-C that takes the chair's
//! processes with the rest.

use std::path::{Path, PathBuf};
use std::time::Duration;

use run_records::summary::RunSummary;
use runner::chair::ChairSummary;

use super::common::{Proc, assert_no_shared_memory_left, processes_with_argument, session, text, wait_for_tick};

/// A fresh directory for one test.
fn out_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-chairs-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// The run's summary and its chair.
fn summaries(dir: &Path) -> (RunSummary, ChairSummary) {
    let path = dir.join("summary.json");
    let run = RunSummary::read(&path).unwrap_or_else(|e| panic!("{e}"));
    let chair = runner::chair::read_chair_summary(&path)
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_else(|| panic!("no \"chair\" in {}", path.display()));
    (run, chair)
}

/// Asserts that no process of the run is left: none with the session or the output folder
/// (where the emulator's link and truth are) among its arguments.
fn assert_no_process_left(session: &str, dir: &Path) {
    for prefix in [session.to_owned(), dir.display().to_string()] {
        let left = processes_with_argument(&prefix);
        assert!(left.is_empty(), "processes of the run left: {left:?}");
    }
}

/// Runs `scenario` (lock-step, headless, seed `seed`) with `extra` options to its end;
/// returns whether it passed, its stdout and stderr, and the summaries.
fn run_to_the_end(
    tag: &str,
    scenario: &str,
    seed: &str,
    extra: &[&str],
) -> (bool, String, String, RunSummary, ChairSummary) {
    let dir = out_dir(tag);
    let name = session(tag);
    let mut args = vec!["run", scenario, "--lockstep", "--headless", "--seed", seed, "--session", &name, "--out"];
    args.push(dir.to_str().expect("utf-8"));
    args.extend(extra);
    let output = Proc::spawn(&args).wait(Duration::from_secs(120));
    let (out, err) = (text(&output.stdout), text(&output.stderr));
    assert!(dir.join("summary.json").exists(), "no summary\n{out}\n{err}");
    let (run, chair) = summaries(&dir);
    assert_no_process_left(&name, &dir);
    assert_no_shared_memory_left(&name);
    assert!(!dir.join(runner::chair::LINK).exists(), "the emulator removes its link when it stops");
    let _ = std::fs::remove_dir_all(&dir);
    (output.status.success(), out, err, run, chair)
}

/// The chair reached checkpoint 2 in the hub's world (the pose its adapter pushes) and the truth agrees.
fn assert_arrived(run: &RunSummary, chair: &ChairSummary) {
    let r = run.robots.iter().find(|r| r.name == "chair1").unwrap_or_else(|| panic!("chair1 in {run:?}"));
    assert_eq!((r.checkpoints_reached, r.checkpoints_total), (1, 1), "{r:?}");
    assert!(chair.truth_steps > 0, "{chair:?}");
    // The odometry drifts (slip, a weaker motor), but not by metres over a 10 m slalom.
    let d = chair.distance_to_checkpoint_m.expect("a true final pose");
    assert!(d < 1.5, "the real chair ends {d} m from checkpoint 2: {chair:?}");
}

// Lock-step with a stepped emulator, a seed's run is the same every time (its state hash
// too), so these are regression tests on single seeds; docs/agents.md gives the success rate over
// seeds 1–10.
#[test]
fn slalom_real_passes_with_no_contact_in_either_world() {
    let (ok, out, err, run, chair) = run_to_the_end("real", "builtin:slalom-real", "3", &[]);
    assert!(ok && run.passed, "{out}\n{err}\n{run:?}");
    assert_eq!((chair.robot.as_str(), chair.mode.as_str(), chair.stepped), ("chair1", "real", true));
    assert_eq!((chair.contacts_sim, chair.contacts_room), (0, 0), "{chair:?}");
    assert_arrived(&run, &chair);
    assert!(out.contains("contacts (sim)") && out.contains("contacts (room)"), "{out}");
    assert!(out.contains("chair1 in the emulator's room (real sensors, stepped): 0 contacts"), "{out}");
}

#[test]
fn slalom_augmented_passes_with_no_contact_in_either_world_because_the_pose_is_map_matched() {
    let (ok, out, err, run, chair) = run_to_the_end("augmented", "builtin:slalom-augmented", "2", &[]);
    assert!(ok && run.passed, "{out}\n{err}\n{run:?}");
    assert_eq!(chair.mode, "augmented");
    assert_eq!((chair.contacts_sim, chair.contacts_room), (0, 0), "{chair:?}");
    assert_arrived(&run, &chair);
    let matched = chair.pose_error_m.expect("the hub's and the true final pose");
    assert!(matched < 0.03, "the hub's pose ends {matched} m from the truth: {chair:?}");
    // The same seed on raw odometry: the hub's frame, where virtual A and B stand, drifts
    // from the room's, and the chair's corner meets a real wall beside a virtual box.
    let (ok, out, err, run, raw) =
        run_to_the_end("augmented-raw", "builtin:slalom-augmented", "2", &["--chair-odometry-only"]);
    // Odometry alone ends 0.14 m off (7x the map-matched error), and the stepped emulator
    // makes this the same run on a loaded machine (the adapter waits for each step's sample
    // and truth as long as it waits for the step).
    let drifted = raw.pose_error_m.expect("the hub's and the true final pose");
    assert!(drifted > matched, "odometry alone {drifted} m off, map-matched {matched} m: {raw:?}");
    assert!(raw.contacts_room > 0 && !ok && !run.passed, "{raw:?}\n{out}\n{err}");
}

#[test]
fn without_the_merge_the_chair_hits_the_box_only_its_room_has() {
    // Box C stands only in the emulator's room: a chair that reads only the simulator's
    // sensors cannot see it.
    let (ok, out, err, run, chair) =
        run_to_the_end("virtual", "builtin:slalom-augmented", "3", &["--chair-mode", "virtual"]);
    assert_eq!(chair.mode, "virtual", "--chair-mode reaches the adapter");
    assert!(chair.contacts_room > 0, "the blind chair touched nothing in the room: {chair:?}\n{out}\n{err}");
    assert!(!ok && !run.passed, "{out}");
    assert!(
        run.failures.iter().any(|f| f.starts_with("chair1: ") && f.contains("contacts in the emulator's room")),
        "{:?}",
        run.failures
    );
}

#[test]
fn sigint_to_a_run_with_a_chair_stops_the_emulator_and_the_adapter_too() {
    let dir = out_dir("sigint");
    let name = session("chairs-sigint");
    let run = Proc::spawn(&[
        "run",
        "builtin:slalom-real",
        "--lockstep",
        "--headless",
        "--session",
        &name,
        "--out",
        dir.to_str().expect("utf-8"),
    ]);
    // Mid-run: the chair drives (the world has stepped), its processes are up.
    let observer = wait_for_tick(&name, 20, Duration::from_secs(60));
    observer.close();
    let link = dir.join(runner::chair::LINK);
    assert!(link.symlink_metadata().is_ok(), "the emulator's port is linked at {}", link.display());
    assert!(!processes_with_argument(&dir.display().to_string()).is_empty(), "the emulator is found");
    run.signal("INT");
    let output = run.wait(Duration::from_secs(30));
    let (out, err) = (text(&output.stdout), text(&output.stderr));
    assert_eq!(output.status.code(), Some(130), "{out}\n{err}");
    assert!(err.contains("the chair emulator and its adapter"), "{err}");
    assert!(out.contains("FAIL: interrupted by SIGINT"), "{out}");
    let (summary, chair) = summaries(&dir);
    assert!(!summary.passed, "{summary:?}");
    assert!(chair.truth_steps > 0, "the partial summary still reads the room's truth: {chair:?}");
    assert_no_process_left(&name, &dir);
    assert_no_shared_memory_left(&name);
    assert!(link.symlink_metadata().is_err(), "the emulator removed its link");
    let _ = std::fs::remove_dir_all(&dir);
}
