//! `summary.json`, which `iwsim run` writes beside a run's logs: the run ([`RunSummary`]), every
//! robot ([`RobotSummary`]), and the scenario's map overlay, which `iwsim plot` reads back
//! ([`SummaryScene`]).
//!
//! ```
//! use places::Checkpoint;
//! use run_records::summary::{RunSummary, SummaryScene};
//!
//! let run = RunSummary {
//!     scenario: "slalom".into(),
//!     lab: "builtin:liacc".into(),
//!     checkpoints: vec![Checkpoint::parse("10,6.1")?],
//!     wall_s: 1.23456,
//!     ..Default::default()
//! };
//! let text = run.to_json();
//! assert!(text.contains(r#""wall_s":1.235"#));
//! let scene = SummaryScene::parse(&text, "summary.json".as_ref())?;
//! assert_eq!(scene.checkpoints, Some(run.checkpoints));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::outcome::StateHash;
use crate::round_to;
use places::{Checkpoint, Obstacle};
use sim_model::PoseDeg;

/// One robot's outcome, measured from its log.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct RobotSummary {
    /// Robot name (its log's file stem).
    pub name: String,
    /// Log file name.
    pub log: String,
    /// Its route, checkpoint numbers from 1.
    pub route: Vec<usize>,
    /// Checkpoints of the route reached, in order.
    pub checkpoints_reached: usize,
    /// Checkpoints in the route.
    pub checkpoints_total: usize,
    /// Simulated time at each reached checkpoint, seconds.
    pub reached_at_s: Vec<f64>,
    /// Simulated time at the last reached checkpoint, seconds (`null`: none reached).
    pub time_s: Option<f64>,
    /// Contacts.
    pub collisions: u64,
    /// Ticks logged.
    pub ticks: usize,
    /// Distance driven, metres (written to the millimetre).
    pub distance_m: f64,
    /// Top speed, m/s (written to 0.1 mm/s).
    pub top_speed_mps: f64,
    /// 10–90 % rise time of the speed, seconds (written to 10 ms).
    pub rise_time_s: f64,
    /// Final pose: x, y metres, heading degrees (written to 0.1 mm and 0.01°).
    pub final_pose: PoseDeg,
    /// Whether it has a route and reached every checkpoint of it.
    #[serde(default)]
    pub arrived: bool,
    /// Its body's least distance to a wall or the lab's border, metres (to the millimetre).
    #[serde(default)]
    pub min_clearance_wall_m: Option<f64>,
    /// Its body's least distance to another robot's, metres (`null`: it was alone).
    #[serde(default)]
    pub min_clearance_chair_m: Option<f64>,
    /// Contacts with another robot (the nearest thing when the contact began).
    #[serde(default)]
    pub contacts_chair: u64,
    /// Contacts with a wall or the border.
    #[serde(default)]
    pub contacts_wall: u64,
    /// Contacts with a scenario obstacle.
    #[serde(default)]
    pub contacts_obstacle: u64,
    /// Seconds it stood still (under 2 cm/s) with its route not finished (to 0.1 s).
    #[serde(default)]
    pub still_s: f64,
}

impl RobotSummary {
    /// Whether it has a route and has reached every checkpoint of it.
    pub fn finished_route(&self) -> bool {
        !self.route.is_empty() && self.checkpoints_reached == self.checkpoints_total
    }
}

/// Many robots in one run, measured as the field measures multi-robot navigation: present in
/// a summary when two or more robots have routes.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TrafficSummary {
    /// Robots with a route.
    pub chairs: usize,
    /// Of them, those that finished it.
    pub arrived: usize,
    /// `arrived / chairs`.
    pub success_rate: f64,
    /// When the last of them finished, seconds (`null` unless all did).
    pub makespan_s: Option<f64>,
    /// Their finishing times added up, a robot that did not finish counting the whole run.
    pub sum_of_times_s: f64,
    /// Times a set of robots stood still short of their goals for 20 s, each within 1.5 m of
    /// another of them.
    pub deadlocks: u64,
    /// Arrivals per minute of the run.
    pub throughput_per_min: f64,
    /// Contacts between robots, with walls and with obstacles, over all of them.
    pub contacts_chair: u64,
    /// See `contacts_chair`.
    pub contacts_wall: u64,
    /// See `contacts_chair`.
    pub contacts_obstacle: u64,
}

/// One run's outcome, as `summary.json` holds it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// Ticks the hub ran.
    pub ticks: u64,
    /// The hub's final state hash.
    pub state_hash: StateHash,
    /// Wall-clock seconds (written to the millisecond).
    pub wall_s: f64,
    /// Whether the scenario's expectations held: `failures` is empty.
    pub passed: bool,
    /// Expectations that failed.
    pub failures: Vec<String>,
    /// The lab spec of the run (`builtin:NAME` or a file).
    pub lab: String,
    /// The scenario's obstacles.
    pub obstacles: Vec<Obstacle>,
    /// The scenario's checkpoints, numbered from 1.
    pub checkpoints: Vec<Checkpoint>,
    /// Robots, by name.
    pub robots: Vec<RobotSummary>,
    /// The run's traffic, when two or more robots have routes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub traffic: Option<TrafficSummary>,
    /// The CPU time (user + system, seconds, to the millisecond) of each of the run's
    /// processes, by what the runner calls it (`hub`, `agent 1 (navigator)`, …): measured,
    /// like `wall_s`, so it differs between equal runs.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub cpu_s: BTreeMap<String, f64>,
}

impl RunSummary {
    /// The file's text, one line with a newline; measured numbers are rounded as the field
    /// docs say, so summaries of equal runs compare equal as text.
    pub fn to_json(&self) -> String {
        let mut s = self.clone();
        s.wall_s = round_to(s.wall_s, 3);
        s.cpu_s.values_mut().for_each(|v| *v = round_to(*v, 3));
        for r in &mut s.robots {
            r.distance_m = round_to(r.distance_m, 3);
            r.top_speed_mps = round_to(r.top_speed_mps, 4);
            r.rise_time_s = round_to(r.rise_time_s, 2);
            let [x, y, h] = r.final_pose;
            r.final_pose = [round_to(x, 4), round_to(y, 4), round_to(h, 2)];
            r.min_clearance_wall_m = r.min_clearance_wall_m.map(|v| round_to(v, 3));
            r.min_clearance_chair_m = r.min_clearance_chair_m.map(|v| round_to(v, 3));
            r.still_s = round_to(r.still_s, 1);
        }
        if let Some(t) = &mut s.traffic {
            t.success_rate = round_to(t.success_rate, 4);
            t.makespan_s = t.makespan_s.map(|v| round_to(v, 1));
            t.sum_of_times_s = round_to(t.sum_of_times_s, 1);
            t.throughput_per_min = round_to(t.throughput_per_min, 3);
        }
        crate::to_json(&s) + "\n"
    }

    /// Reads a `summary.json`; `path` names the file in errors.
    pub fn read(path: &Path) -> Result<Self, SummaryReadError> {
        let text = read_text(path)?;
        serde_json::from_str(&text).map_err(|e| SummaryReadError::json(path, &e))
    }
}

/// The keys of a `summary.json` that draw its scene, each `None` when absent, so that partial
/// or hand-written summaries still serve.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SummaryScene {
    /// `"lab"`: the lab spec of the run.
    pub lab: Option<String>,
    /// `"obstacles"`: `[[X0,Y0,X1,Y1,H], …]`.
    pub obstacles: Option<Vec<Obstacle>>,
    /// `"checkpoints"`: `[[X,Y,R], …]`.
    pub checkpoints: Option<Vec<Checkpoint>>,
}

/// Why a `summary.json` could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SummaryReadError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        /// The summary file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file is not JSON, or not a summary.
    #[error("{}:{line}:{column}: {message}", .path.display())]
    Json {
        /// The summary file.
        path: PathBuf,
        /// Line of the problem, from 1.
        line: usize,
        /// Column of the problem, from 1.
        column: usize,
        /// "not JSON" or "not a run summary", and what serde_json said.
        message: String,
    },
    /// A key has the wrong shape.
    #[error("{}: key `{key}`: {message}", .path.display())]
    Key {
        /// The summary file.
        path: PathBuf,
        /// The key, with the index of the item where that applies (`obstacles[2]`).
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl SummaryReadError {
    fn json(path: &Path, e: &serde_json::Error) -> Self {
        let what = if e.is_data() { "not a run summary" } else { "not JSON" };
        Self::Json { path: path.into(), line: e.line(), column: e.column(), message: format!("{what}: {e}") }
    }
}

fn read_text(path: &Path) -> Result<String, SummaryReadError> {
    std::fs::read_to_string(path).map_err(|source| SummaryReadError::Io { path: path.into(), source })
}

impl SummaryScene {
    /// Reads the scene's keys from the `summary.json` at `path`.
    pub fn read(path: &Path) -> Result<Self, SummaryReadError> {
        Self::parse(&read_text(path)?, path)
    }

    /// Parses the text of a `summary.json`; `path` only names the file in errors. Other keys
    /// are ignored; a bad item is named with its index (`obstacles[1]`).
    pub fn parse(text: &str, path: &Path) -> Result<Self, SummaryReadError> {
        // Through a `Value` first: a typed read would stop at the first bad item with only a
        // line and column, and these files are often one long line.
        let root: serde_json::Value = serde_json::from_str(text).map_err(|e| SummaryReadError::json(path, &e))?;
        let key_err = |key: String, message: String| SummaryReadError::Key { path: path.into(), key, message };
        let root = root.as_object().ok_or_else(|| key_err("(top level)".into(), "expected a JSON object".into()))?;
        let lab = match root.get("lab") {
            None | Some(serde_json::Value::Null) => None,
            Some(v) => Some(v.as_str().ok_or_else(|| key_err("lab".into(), "expected a string".into()))?.to_owned()),
        };
        Ok(Self {
            lab,
            obstacles: items(root, "obstacles", &key_err)?,
            checkpoints: items(root, "checkpoints", &key_err)?,
        })
    }
}

/// The items of the array at `key`, each read as a `T`; `None` when the key is absent.
fn items<T: serde::de::DeserializeOwned>(
    root: &serde_json::Map<String, serde_json::Value>,
    key: &str,
    key_err: &dyn Fn(String, String) -> SummaryReadError,
) -> Result<Option<Vec<T>>, SummaryReadError> {
    let Some(v) = root.get(key) else { return Ok(None) };
    let list = v.as_array().ok_or_else(|| key_err(key.into(), "expected an array".into()))?;
    let read = |(k, item): (usize, &serde_json::Value)| {
        T::deserialize(item).map_err(|e| key_err(format!("{key}[{k}]"), e.to_string()))
    };
    list.iter().enumerate().map(read).collect::<Result<_, _>>().map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use places::{DEFAULT_CHECKPOINT_RADIUS_M, DEFAULT_OBSTACLE_HEIGHT_M};

    fn run() -> RunSummary {
        RunSummary {
            scenario: "slalom".into(),
            seed: 3,
            ticks: 900,
            state_hash: StateHash(0xabc),
            wall_s: 2.345_67,
            passed: false,
            failures: vec!["chair1: 1 contacts (at most 0 expected)".into()],
            lab: "builtin:liacc".into(),
            obstacles: vec![Obstacle::new(17.0, 6.1, 17.6, 6.4, 1.0)],
            checkpoints: vec![Checkpoint { x: 10.0, y: 6.1, radius: 0.5 }],
            robots: vec![RobotSummary {
                name: "chair1".into(),
                log: "chair1.csv".into(),
                route: vec![1],
                checkpoints_reached: 1,
                checkpoints_total: 1,
                reached_at_s: vec![12.3],
                time_s: Some(12.3),
                collisions: 1,
                ticks: 900,
                distance_m: 12.345_67,
                top_speed_mps: 0.490_049,
                rise_time_s: 1.199_9,
                final_pose: [20.123_456, 6.1, -0.004_9],
                ..Default::default()
            }],
            traffic: None,
            cpu_s: BTreeMap::from([("hub".into(), 0.123_456), ("agent 1 (navigator)".into(), 1.5)]),
        }
    }

    #[test]
    fn the_file_has_todays_keys_and_rounding() {
        assert_eq!(
            run().to_json(),
            concat!(
                r#"{"scenario":"slalom","seed":3,"ticks":900,"state_hash":"0000000000000abc","wall_s":2.346,"#,
                r#""passed":false,"failures":["chair1: 1 contacts (at most 0 expected)"],"lab":"builtin:liacc","#,
                r#""obstacles":[[17.0,6.1,17.6,6.4,1.0]],"checkpoints":[[10.0,6.1,0.5]],"robots":[{"name":"chair1","#,
                r#""log":"chair1.csv","route":[1],"checkpoints_reached":1,"checkpoints_total":1,"reached_at_s":[12.3],"#,
                r#""time_s":12.3,"collisions":1,"ticks":900,"distance_m":12.346,"top_speed_mps":0.49,"#,
                r#""rise_time_s":1.2,"final_pose":[20.1235,6.1,-0.0],"arrived":false,"min_clearance_wall_m":null,"#,
                r#""min_clearance_chair_m":null,"contacts_chair":0,"contacts_wall":0,"contacts_obstacle":0,"still_s":0.0}],"#,
                r#""cpu_s":{"agent 1 (navigator)":1.5,"hub":0.123}}"#,
                "\n"
            )
        );
    }

    #[test]
    fn a_written_summary_reads_back_whole_and_as_a_scene() {
        let dir = std::env::temp_dir().join(format!("records-summary-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("summary.json");
        let s = run();
        std::fs::write(&path, s.to_json()).expect("write");
        let back = RunSummary::read(&path).expect("reads");
        assert_eq!((back.robots[0].rise_time_s, back.robots[0].time_s), (1.2, Some(12.3)));
        assert_eq!((&back.obstacles, &back.checkpoints, back.state_hash), (&s.obstacles, &s.checkpoints, s.state_hash));
        let scene = SummaryScene::read(&path).expect("a scene");
        assert_eq!(
            scene,
            SummaryScene { lab: Some(s.lab), obstacles: Some(s.obstacles), checkpoints: Some(s.checkpoints) }
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    const SUMMARY: &str = r#"{"scenario":"slalom","lab":"builtin:liacc",
        "obstacles":[[17,6.1,17.6,6.4,1.0],[19,5.8,19.6,6.1]],
        "checkpoints":[[10,6.1,0.5],[20,6.1]], "seed":1,
        "robots":[{"name":"chair1","log":"chair1.csv","ticks":120}], "extra":{"a":[1,2]}}"#;

    #[test]
    fn a_scene_takes_lab_obstacles_and_checkpoints_with_defaults() {
        let s = SummaryScene::parse(SUMMARY, Path::new("run/summary.json")).expect("parses");
        assert_eq!(s.lab.as_deref(), Some("builtin:liacc"));
        assert_eq!(
            s.obstacles,
            Some(vec![
                Obstacle::new(17.0, 6.1, 17.6, 6.4, 1.0),
                Obstacle::new(19.0, 5.8, 19.6, 6.1, DEFAULT_OBSTACLE_HEIGHT_M),
            ])
        );
        assert_eq!(
            s.checkpoints,
            Some(vec![
                Checkpoint { x: 10.0, y: 6.1, radius: 0.5 },
                Checkpoint { x: 20.0, y: 6.1, radius: DEFAULT_CHECKPOINT_RADIUS_M },
            ])
        );
        assert_eq!(SummaryScene::parse(r#"{"seed":3}"#, Path::new("s.json")).expect("parses"), SummaryScene::default());
    }

    #[test]
    fn a_file_that_is_not_json_gives_line_and_column() {
        let err = SummaryScene::parse("{\n  \"lab\": builtin }", Path::new("run/summary.json")).expect_err("not JSON");
        assert!(matches!(err, SummaryReadError::Json { line: 2, .. }), "{err:?}");
        assert!(err.to_string().starts_with("run/summary.json:2:"), "{err}");
        let err = RunSummary::read(Path::new("/nonexistent/summary.json")).expect_err("no file");
        assert!(matches!(err, SummaryReadError::Io { .. }), "{err:?}");
    }

    #[test]
    fn a_bad_scene_item_is_named_with_its_index() {
        let key = |text: &str| match SummaryScene::parse(text, Path::new("summary.json")) {
            Err(SummaryReadError::Key { key, message, .. }) => format!("{key}: {message}"),
            other => format!("{other:?}"),
        };
        assert!(key(r#"{"obstacles":[[1,1,2,2],[3,3,"x",4]]}"#).starts_with("obstacles[1]: invalid type"));
        assert!(key(r#"{"checkpoints":[[1,1,-1]]}"#).starts_with("checkpoints[0]: \"1,1,-1\": want"));
        assert!(key(r#"{"lab":3}"#).starts_with("lab: expected a string"));
        assert!(key(r#"{"obstacles":{}}"#).starts_with("obstacles: expected an array"));
    }
}
