//! The physical chair of a mixed-reality run, as the runner sees it: the command lines of the
//! chair emulator (`iwsim chair-emulator`, the chair in a room of its own) and of the serial
//! adapter (`iwsim serial`, which registers it in the hub as a Real robot), spelt here and
//! nowhere else; the emulator's ground-truth log read back ([`read_truth`]); and what the
//! summary says of the chair ([`ChairSummary`]), written beside the run's keys in
//! `summary.json` ([`summary_json`]).
//!
//! ```
//! let truth = runner::chair::parse_truth(
//!     "{\"t_ns\":1,\"x\":10.0,\"y\":6.1,\"heading_deg\":0.0,\"contacts\":0}\n\
//!      {\"t_ns\":2,\"event\":\"hello\"}\n\
//!      {\"t_ns\":3,\"x\":10.5,\"y\":6.1,\"heading_deg\":1.5,\"contacts\":2}\n",
//!     "chair-truth.jsonl".as_ref(),
//! )
//! .expect("a ground-truth log");
//! assert_eq!((truth.steps, truth.contacts, truth.final_pose), (2, 2, Some([10.5, 6.1, 1.5])));
//! ```

use std::io::BufRead as _;
use std::path::{Path, PathBuf};

use run_records::summary::RunSummary;
use serde::{Deserialize, Serialize};
use sim_model::PoseDeg;

use crate::scenario::{ChairMode, ChairSpec, Scenario};

/// The symlink to the emulator's pseudo-terminal, in the run's output folder: the adapter
/// opens this path, which stays the same across emulator restarts.
pub const LINK: &str = "chair.pty";
/// The emulator's ground-truth log, in the run's output folder.
pub const TRUTH: &str = "chair-truth.jsonl";
/// The start of the emulator's first stdout line, printed once its port is open.
pub const EMULATOR_BANNER: &str = "chair-emulator: ";

/// `iwsim chair-emulator …`: the chair at `spec.pose` in its room (`lab` plus the scenario's
/// room boxes), seeded with the run's seed, its port linked at `link`, its truth in `truth`.
pub fn emulator_args(spec: &ChairSpec, lab: &str, seed: u64, stepped: bool, link: &Path, truth: &Path) -> Vec<String> {
    let mut args = vec!["chair-emulator".to_owned(), "--lab".to_owned(), lab.to_owned()];
    for b in &spec.room {
        args.extend(["--box".to_owned(), b.to_string()]);
    }
    args.extend([
        "--pose".to_owned(),
        pose(spec.pose),
        "--seed".to_owned(),
        seed.to_string(),
        "--link".to_owned(),
        link.display().to_string(),
        "--truth".to_owned(),
        truth.display().to_string(),
    ]);
    if stepped {
        args.push("--stepped".to_owned());
    }
    args
}

/// `iwsim serial …`: the adapter for the chair behind `link`, registering `spec.robot` in
/// `session` with sensor mode `mode`.
pub fn adapter_args(spec: &ChairSpec, mode: ChairMode, session: &str, stepped: bool, link: &Path) -> Vec<String> {
    let mut args = vec![
        "serial".to_owned(),
        "--device".to_owned(),
        link.display().to_string(),
        "--robot".to_owned(),
        spec.robot.clone(),
        "--mode".to_owned(),
        mode.as_str().to_owned(),
        "--pose".to_owned(),
        pose(spec.pose),
        "--session".to_owned(),
        session.to_owned(),
        // The runner's chair is always its own emulator, with nobody in it: a stop lifts when
        // its causes clear, as a scripted run needs (a real chair waits for `iwsim resume`).
        "--auto-resume".to_owned(),
    ];
    if stepped {
        args.push("--stepped".to_owned());
    }
    if !spec.localise {
        args.push("--odometry-only".to_owned());
    }
    args
}

fn pose([x, y, deg]: PoseDeg) -> String {
    format!("{x},{y},{deg}")
}

/// Whether the adapter steps the emulator's clock: the scenario's choice, else whenever the
/// run is lock-step (a stepped chair is as fast and as deterministic as the hub).
pub fn stepped(spec: &ChairSpec, lockstep: bool) -> bool {
    spec.stepped.unwrap_or(lockstep)
}

/// What the emulator's ground-truth log says of the real chair.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoomTruth {
    /// Physics steps logged.
    pub steps: u64,
    /// Contacts with the room so far, at the last step.
    pub contacts: u64,
    /// The true pose at the last step: x, y metres, heading degrees.
    pub final_pose: Option<PoseDeg>,
    /// Events logged (`motors_zero`, `hello`, …), in order, with how often each came.
    pub events: Vec<(String, u64)>,
}

/// Why the ground-truth log could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TruthReadError {
    /// The file could not be read (the emulator never wrote it, or it went away).
    #[error("{}: {source}", .path.display())]
    Io {
        /// The log.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// A complete line is not a step or an event.
    #[error("{}:{line}: {message}", .path.display())]
    Line {
        /// The log.
        path: PathBuf,
        /// Line number, from 1.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// One line of the log: a physics step (pose and contacts) or an event; other keys (`cmd`,
/// `board_ms`, `reason`, …) are the emulator's and not needed here.
#[derive(Deserialize)]
struct TruthLine {
    #[serde(default)]
    x: Option<f64>,
    #[serde(default)]
    y: Option<f64>,
    #[serde(default)]
    heading_deg: Option<f64>,
    #[serde(default)]
    contacts: Option<u64>,
    #[serde(default)]
    event: Option<String>,
}

/// Reads the emulator's ground-truth log at `path`.
pub fn read_truth(path: &Path) -> Result<RoomTruth, TruthReadError> {
    let io = |source| TruthReadError::Io { path: path.into(), source };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut truth = RoomTruth::default();
    let mut reader = std::io::BufReader::new(file);
    let mut line = String::new();
    let mut number = 0;
    loop {
        line.clear();
        if reader.read_line(&mut line).map_err(io)? == 0 {
            return Ok(truth);
        }
        number += 1;
        // An emulator killed mid-write leaves a last line without its newline: what it had
        // said before stands.
        if !line.ends_with('\n') {
            return Ok(truth);
        }
        take_line(&mut truth, line.trim(), path, number)?;
    }
}

/// Parses a whole ground-truth log held in memory; `path` names it in errors.
pub fn parse_truth(text: &str, path: &Path) -> Result<RoomTruth, TruthReadError> {
    let mut truth = RoomTruth::default();
    for (k, line) in text.split_inclusive('\n').enumerate() {
        if line.ends_with('\n') {
            take_line(&mut truth, line.trim(), path, k + 1)?;
        }
    }
    Ok(truth)
}

fn take_line(truth: &mut RoomTruth, line: &str, path: &Path, number: usize) -> Result<(), TruthReadError> {
    if line.is_empty() {
        return Ok(());
    }
    let bad = |message: String| TruthReadError::Line { path: path.into(), line: number, message };
    let l: TruthLine = serde_json::from_str(line).map_err(|e| bad(format!("not a ground-truth line: {e}")))?;
    if let Some(event) = l.event {
        match truth.events.iter_mut().find(|(e, _)| *e == event) {
            Some((_, n)) => *n += 1,
            None => truth.events.push((event, 1)),
        }
        return Ok(());
    }
    match (l.x, l.y, l.heading_deg) {
        (Some(x), Some(y), Some(h)) if x.is_finite() && y.is_finite() && h.is_finite() => {
            truth.steps += 1;
            truth.final_pose = Some([x, y, h]);
            // The count is the emulator's running total; the largest seen is robust to a
            // line written out of order.
            truth.contacts = truth.contacts.max(l.contacts.unwrap_or(0));
            Ok(())
        }
        _ => Err(bad("a step needs finite x, y and heading_deg, an event needs \"event\"".into())),
    }
}

/// What a run's summary says of its physical chair.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ChairSummary {
    /// The robot it is in the hub.
    pub robot: String,
    /// The adapter's sensor mode in this run.
    pub mode: String,
    /// Whether the adapter stepped the emulator's clock.
    pub stepped: bool,
    /// Contacts in the simulator's world (of the pose the adapter pushes), from the hub's record.
    pub contacts_sim: u64,
    /// Contacts with the emulator's room, from its ground truth.
    pub contacts_room: u64,
    /// The chair's true final pose in the room: x, y metres, heading degrees (written to
    /// 0.1 mm and 0.01°); `null` when the emulator logged no step.
    pub final_pose_room: Option<PoseDeg>,
    /// The checkpoint the distance is measured to: the last of the robot's route, else the
    /// scenario's last (numbered from 1).
    pub checkpoint: Option<usize>,
    /// The true final pose's distance to that checkpoint's centre, metres (to the mm).
    pub distance_to_checkpoint_m: Option<f64>,
    /// How far the chair's final pose in the hub (the pose its adapter pushed: odometry,
    /// map-matched unless `--odometry-only`) is from its true final pose, metres (to the mm).
    #[serde(default)]
    pub pose_error_m: Option<f64>,
    /// Physics steps the emulator logged.
    pub truth_steps: u64,
    /// The ground-truth log's file name, in the run's folder.
    pub truth: String,
}

impl ChairSummary {
    /// The chair of `scenario` in `mode`: its contacts in the simulator (`contacts_sim`) and
    /// what the room's truth says.
    pub fn new(
        scenario: &Scenario,
        spec: &ChairSpec,
        mode: ChairMode,
        stepped: bool,
        contacts_sim: u64,
        hub_final_pose: Option<PoseDeg>,
        truth: &RoomTruth,
    ) -> Self {
        let checkpoint = scenario
            .routes
            .get(&spec.robot)
            .and_then(|r| r.last().copied())
            .or_else(|| (!scenario.checkpoints.is_empty()).then_some(scenario.checkpoints.len()));
        let distance = match (checkpoint.and_then(|n| scenario.checkpoints.get(n.checked_sub(1)?)), truth.final_pose) {
            (Some(c), Some([x, y, _])) => Some(round((x - c.x).hypot(y - c.y), 3)),
            _ => None,
        };
        let pose_error = match (hub_final_pose, truth.final_pose) {
            (Some([x, y, _]), Some([tx, ty, _])) => Some(round((x - tx).hypot(y - ty), 3)),
            _ => None,
        };
        Self {
            robot: spec.robot.clone(),
            mode: mode.as_str().to_owned(),
            stepped,
            contacts_sim,
            contacts_room: truth.contacts,
            final_pose_room: truth.final_pose.map(|[x, y, h]| [round(x, 4), round(y, 4), round(h, 2)]),
            checkpoint,
            distance_to_checkpoint_m: distance,
            pose_error_m: pose_error,
            truth_steps: truth.steps,
            truth: TRUTH.to_owned(),
        }
    }

    /// The expectation failure of the room's contacts, if they are more than `max`.
    pub fn room_failure(&self, max: Option<u64>) -> Option<String> {
        max.filter(|&m| self.contacts_room > m).map(|m| {
            format!("{}: {} contacts in the emulator's room (at most {m} expected)", self.robot, self.contacts_room)
        })
    }

    /// One line for the printed summary.
    pub fn line(&self) -> String {
        let pose = match self.final_pose_room {
            Some([x, y, h]) => format!("true final pose {x:.3}, {y:.3}, {h:.1}°"),
            None => "no true pose logged".to_owned(),
        };
        let distance = match (self.distance_to_checkpoint_m, self.checkpoint) {
            (Some(d), Some(n)) => format!(", {d:.3} m from checkpoint {n}"),
            _ => String::new(),
        };
        let error = match self.pose_error_m {
            Some(e) => format!("; the hub's pose {e:.3} m off"),
            None => String::new(),
        };
        format!(
            "{} in the emulator's room ({} sensors{}): {} contacts, {pose}{distance}{error}",
            self.robot,
            self.mode,
            if self.stepped { ", stepped" } else { "" },
            self.contacts_room
        )
    }
}

/// `value` to `places` decimals, as `format!` prints it, so equal runs write equal text.
fn round(value: f64, places: usize) -> f64 {
    format!("{value:.places$}").parse().unwrap_or(value)
}

/// `summary.json`'s text: the run's keys as [`RunSummary::to_json`] writes them, then
/// `"chair"` when the run had one (readers of the run's keys skip it).
pub fn summary_json(run: &RunSummary, chair: Option<&ChairSummary>) -> Result<String, serde_json::Error> {
    let Some(chair) = chair else { return Ok(run.to_json()) };
    #[derive(Serialize)]
    struct File<'a> {
        #[serde(flatten)]
        run: RunSummary,
        chair: &'a ChairSummary,
    }
    // Read back from its own text, so the run's numbers keep the rounding its writer gives.
    let run: RunSummary = serde_json::from_str(&run.to_json())?;
    Ok(serde_json::to_string(&File { run, chair })? + "\n")
}

/// The `"chair"` of a `summary.json`, if the run had one.
pub fn read_chair_summary(path: &Path) -> Result<Option<ChairSummary>, run_records::summary::SummaryReadError> {
    use run_records::summary::SummaryReadError;
    #[derive(Deserialize)]
    struct File {
        #[serde(default)]
        chair: Option<ChairSummary>,
    }
    let text = std::fs::read_to_string(path).map_err(|source| SummaryReadError::Io { path: path.into(), source })?;
    let file: File = serde_json::from_str(&text).map_err(|e| SummaryReadError::Json {
        path: path.into(),
        line: e.line(),
        column: e.column(),
        message: format!("not a run summary: {e}"),
    })?;
    Ok(file.chair)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> ChairSpec {
        let s = Scenario::load("builtin:slalom-augmented").expect("built in");
        s.chair.expect("a chair")
    }

    #[test]
    fn the_emulator_and_the_adapter_get_the_chair_of_the_scenario() {
        let spec = spec();
        let args = emulator_args(&spec, "builtin:liacc", 7, true, Path::new("out/chair.pty"), Path::new("out/t.jsonl"));
        assert_eq!(
            args.join(" "),
            "chair-emulator --lab builtin:liacc --box C,14,6.1,14.6,6.4 --pose 10,6.1,0 --seed 7 \
             --link out/chair.pty --truth out/t.jsonl --stepped"
        );
        let args = adapter_args(&spec, ChairMode::Virtual, "s1", false, Path::new("out/chair.pty"));
        assert_eq!(
            args.join(" "),
            "serial --device out/chair.pty --robot chair1 --mode virtual --pose 10,6.1,0 --session s1 --auto-resume"
        );
        let raw = ChairSpec { localise: false, ..spec.clone() };
        let args = adapter_args(&raw, ChairMode::Real, "s1", true, Path::new("l"));
        assert!(args.ends_with(&["--stepped".to_owned(), "--odometry-only".to_owned()]), "{args:?}");
        let mut dark = spec.clone();
        dark.room[0].dark = true;
        let args = emulator_args(&dark, "x.xml", 1, false, Path::new("l"), Path::new("t"));
        assert!(
            args.contains(&"C,14,6.1,14.6,6.4,dark".to_owned()) && !args.contains(&"--stepped".to_owned()),
            "{args:?}"
        );
    }

    #[test]
    fn the_truth_gives_the_last_pose_and_the_contacts_and_tolerates_a_cut_last_line() {
        let text = "{\"t_ns\":5,\"board_ms\":0,\"x\":10,\"y\":6.1,\"heading_deg\":0,\"cmd\":[0,0],\"contacts\":0}\n\
                    {\"t_ns\":6,\"event\":\"motors_zero\",\"reason\":\"watchdog\"}\n\
                    \n\
                    {\"t_ns\":7,\"board_ms\":20,\"x\":10.01,\"y\":6.1,\"heading_deg\":-0.5,\"cmd\":[0.5,0.5],\"contacts\":3}\n\
                    {\"t_ns\":8,\"event\":\"motors_zero\",\"reason\":\"command\"}\n\
                    {\"t_ns\":9,\"board_ms\":40,\"x\":10.0";
        let t = parse_truth(text, Path::new("t.jsonl")).expect("reads");
        assert_eq!(
            t,
            RoomTruth {
                steps: 2,
                contacts: 3,
                final_pose: Some([10.01, 6.1, -0.5]),
                events: vec![("motors_zero".into(), 2)]
            }
        );
        let dir = std::env::temp_dir().join(format!("runner-truth-{}-{}", std::process::id(), crate::run::unique()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join(TRUTH);
        std::fs::write(&path, text).expect("written");
        assert_eq!(read_truth(&path).expect("reads the file"), t);
        std::fs::write(&path, "{\"x\":1,\"y\":2,\"heading_deg\":3}\nnot json\n{\"x\":1}\n").expect("written");
        let err = read_truth(&path).expect_err("a bad line");
        assert!(matches!(&err, TruthReadError::Line { line: 2, .. }), "{err:?}");
        assert!(err.to_string().starts_with(&format!("{}:2: not a ground-truth line", path.display())), "{err}");
        let err = parse_truth("{\"x\":1}\n", Path::new("t")).expect_err("no y");
        assert!(matches!(err, TruthReadError::Line { line: 1, .. }), "{err:?}");
        let err = read_truth(&dir.join("none.jsonl")).expect_err("no file");
        assert!(matches!(err, TruthReadError::Io { .. }), "{err:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_chair_summary_measures_the_true_pose_from_the_routes_last_checkpoint() {
        let s = Scenario::load("builtin:slalom-real").expect("built in");
        let spec = s.chair.clone().expect("a chair");
        let truth = RoomTruth { steps: 9, contacts: 2, final_pose: Some([19.7, 6.5, 3.333_33]), events: vec![] };
        let c = ChairSummary::new(&s, &spec, ChairMode::Real, true, 1, Some([19.7, 6.45, 0.0]), &truth);
        assert_eq!((c.checkpoint, c.distance_to_checkpoint_m), (Some(2), Some(0.5)));
        assert_eq!(c.pose_error_m, Some(0.05));
        assert_eq!(c.final_pose_room, Some([19.7, 6.5, 3.33]));
        assert_eq!((c.contacts_sim, c.contacts_room, c.truth_steps), (1, 2, 9));
        assert_eq!(
            c.room_failure(Some(0)).as_deref(),
            Some("chair1: 2 contacts in the emulator's room (at most 0 expected)")
        );
        assert_eq!(c.room_failure(Some(2)), None);
        assert_eq!(c.room_failure(None), None);
        assert_eq!(
            c.line(),
            "chair1 in the emulator's room (real sensors, stepped): 2 contacts, true final pose 19.700, 6.500, 3.3°, 0.500 m from checkpoint 2; the hub's pose 0.050 m off"
        );
        let none = ChairSummary::new(&s, &spec, ChairMode::Real, false, 0, Some([1.0; 3]), &RoomTruth::default());
        assert_eq!((none.final_pose_room, none.distance_to_checkpoint_m, none.pose_error_m), (None, None, None));
    }

    #[test]
    fn summary_json_adds_the_chair_after_the_runs_keys_and_reads_back() {
        let run = RunSummary { scenario: "slalom-real".into(), wall_s: 1.234_56, ..Default::default() };
        assert_eq!(summary_json(&run, None).expect("json"), run.to_json());
        let chair = ChairSummary { robot: "chair1".into(), contacts_room: 4, ..Default::default() };
        let text = summary_json(&run, Some(&chair)).expect("json");
        let plain = run.to_json();
        assert!(text.starts_with(plain.trim_end().trim_end_matches('}')), "{text}");
        assert!(
            text.contains(
                r#","chair":{"robot":"chair1","mode":"","stepped":false,"contacts_sim":0,"contacts_room":4,"#
            ),
            "{text}"
        );
        let dir = std::env::temp_dir().join(format!("runner-summary-{}-{}", std::process::id(), crate::run::unique()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("summary.json");
        std::fs::write(&path, &text).expect("written");
        assert_eq!(RunSummary::read(&path).expect("the run's keys read as ever").wall_s, 1.235);
        assert_eq!(read_chair_summary(&path).expect("reads"), Some(chair));
        std::fs::write(&path, plain).expect("written");
        assert_eq!(read_chair_summary(&path).expect("reads"), None);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
