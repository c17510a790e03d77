//! How a hub run ended: the one JSON line `iwsim hub --json` prints last, and what the runner,
//! the benchmarks and the tests read back from the hub's stdout.
//!
//! ```
//! use run_records::outcome::{HubOutcome, StateHash};
//!
//! let out = HubOutcome { ticks: 40, state_hash: StateHash(0xbeef), ..Default::default() };
//! let stdout = format!("some line\n{}\n", out.json_line());
//! assert!(stdout.contains(r#""state_hash":"000000000000beef""#));
//! assert_eq!(HubOutcome::from_stdout(&stdout)?, out);
//! # Ok::<(), run_records::outcome::OutcomeReadError>(())
//! ```

use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A world's state hash; written as a string of 16 hex digits, as people compare it by eye.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct StateHash(pub u64);

/// 16 hex digits, zero-padded.
impl fmt::Display for StateHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:016x}", self.0)
    }
}

impl Serialize for StateHash {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for StateHash {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        u64::from_str_radix(&text, 16)
            .ok()
            .filter(|_| text.len() == 16)
            .map(StateHash)
            .ok_or_else(|| serde::de::Error::custom(format!("state_hash {text:?} is not 16 hex digits")))
    }
}

/// A robot where the run left it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct RobotAtEnd {
    /// Robot id.
    pub id: u32,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, degrees.
    pub heading_deg: f64,
    /// `ipc_types::ROBOT_*` flags.
    pub flags: u32,
}

/// A robot's final standing in the run's Ciber-Rato challenge.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ScoreAtEnd {
    /// Robot id.
    pub id: u32,
    /// Robot name.
    pub name: String,
    /// Its state as Ciber-Rato names it (`Running`, `Returning`, `Finished`).
    pub state: String,
    /// Its score.
    pub score: i64,
    /// Competitive mode: the tick it arrived.
    pub arrival_tick: u64,
    /// Competitive mode: ticks since its return began.
    pub returning_ticks: u64,
    /// Collision events.
    pub collisions: u32,
    /// The targets visited, one `0`/`1` per target in lab order (Ciber-Rato's `VisitedMask`).
    pub visited: String,
}

impl ScoreAtEnd {
    /// As one line of JSON.
    pub fn json(&self) -> String {
        crate::to_json(self)
    }
}

/// How a hub run ended.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct HubOutcome {
    /// Ticks stepped.
    pub ticks: u64,
    /// Wall-clock seconds from the first step to the end of the run.
    pub run_s: f64,
    /// The world's state hash at the end.
    pub state_hash: StateHash,
    /// Agents that said hello.
    pub agents_seen: usize,
    /// Agents noticed dead (their robots were frozen).
    pub agents_died: usize,
    /// Actions and requests in an agent's name that came from another process's port (not
    /// the client that said hello, not the publisher it named), dropped unread.
    #[serde(default)]
    pub foreign_dropped: u64,
    /// Bytes of the run's recording (0: not recorded).
    #[serde(default)]
    pub recorded_bytes: u64,
    /// World frames for people the recorder dropped because its writer was behind (the
    /// replay journal is never dropped).
    #[serde(default)]
    pub recording_dropped_frames: u64,
    /// World snapshots published: one per tick, plus republications of a tick in hand (a
    /// command, an agent getting ready, robots registered: those settle first, so registering
    /// many robots costs one republication, not one per robot).
    #[serde(default)]
    pub snapshots: u64,
    /// Poses pushed for Real robots that their bodies could not have reached (refused).
    #[serde(default)]
    pub refused_poses: u64,
    /// Stopped by SIGINT/SIGTERM.
    pub interrupted: bool,
    /// Robots at the end.
    pub robots: Vec<RobotAtEnd>,
    /// The challenge's scoring mode (Ciber-Rato's `--scoring N`).
    #[serde(default)]
    pub scoring: u32,
    /// Every robot's final standing in the challenge, in id order.
    #[serde(default)]
    pub scores: Vec<ScoreAtEnd>,
    /// In lock-step, how long each tick waited from its publication to its last answer (the
    /// round trip of one tick through every agent, and through a bridge to remote agents):
    /// percentiles over the run's ticks (the first million), or `None` in real time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answer_wait: Option<crate::latency::Percentiles>,
}

/// Why a hub's stdout gave no outcome.
#[derive(Debug, thiserror::Error)]
pub enum OutcomeReadError {
    /// No line starts with `{` (was the hub run with `--json`?).
    #[error("the hub printed no JSON outcome line (was it run with --json?)")]
    NoJsonLine,
    /// The last such line is not a hub outcome.
    #[error("the hub's outcome line is not what `iwsim hub --json` prints: {0}")]
    Json(#[from] serde_json::Error),
}

impl HubOutcome {
    /// The JSON line (without a newline), `run_s` rounded to the microsecond.
    pub fn json_line(&self) -> String {
        let rounded = Self { run_s: crate::round_to(self.run_s, 6), ..self.clone() };
        crate::to_json(&rounded)
    }

    /// Reads the outcome from a hub's stdout: its last line that starts with `{`.
    pub fn from_stdout(stdout: &str) -> Result<Self, OutcomeReadError> {
        let line = crate::last_json_line(stdout, |_| true).ok_or(OutcomeReadError::NoJsonLine)?;
        Ok(serde_json::from_str(line)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_has_the_documented_keys_in_order() {
        let out = HubOutcome {
            ticks: 60,
            run_s: 0.123_456_789,
            state_hash: StateHash(0x0123_4567_89ab_cdef),
            agents_seen: 2,
            agents_died: 1,
            foreign_dropped: 4,
            recorded_bytes: 0,
            recording_dropped_frames: 0,
            snapshots: 61,
            refused_poses: 0,
            interrupted: false,
            robots: vec![RobotAtEnd { id: 3, x_m: 10.5, y_m: 6.1, heading_deg: -90.0, flags: 4 }],
            scoring: 1,
            scores: vec![ScoreAtEnd {
                id: 3,
                name: "RS1".into(),
                state: "Finished".into(),
                score: -5,
                arrival_tick: 0,
                returning_ticks: 0,
                collisions: 1,
                visited: "00".into(),
            }],
            answer_wait: Some(crate::latency::Percentiles {
                samples: 60,
                p50_us: 812.5,
                p99_us: 2000.0,
                p999_us: 2100.0,
            }),
        };
        assert_eq!(
            out.json_line(),
            r#"{"ticks":60,"run_s":0.123457,"state_hash":"0123456789abcdef","agents_seen":2,"agents_died":1,"foreign_dropped":4,"recorded_bytes":0,"recording_dropped_frames":0,"snapshots":61,"refused_poses":0,"interrupted":false,"robots":[{"id":3,"x_m":10.5,"y_m":6.1,"heading_deg":-90.0,"flags":4}],"scoring":1,"scores":[{"id":3,"name":"RS1","state":"Finished","score":-5,"arrival_tick":0,"returning_ticks":0,"collisions":1,"visited":"00"}],"answer_wait":{"samples":60,"p50_us":812.5,"p99_us":2000.0,"p999_us":2100.0}}"#
        );
    }

    #[test]
    fn the_last_json_line_of_stdout_is_read_and_positions_survive_exactly() {
        let out = HubOutcome {
            ticks: 40,
            robots: vec![RobotAtEnd {
                id: 1,
                x_m: 11.031_078_331_452_159,
                y_m: 1e-7,
                heading_deg: 179.999_999_999,
                flags: 0,
            }],
            ..Default::default()
        };
        let stdout = format!("{{\"ticks\":1}}\ntick 40\n{}\n", out.json_line());
        assert_eq!(HubOutcome::from_stdout(&stdout).expect("an outcome"), out);
    }

    #[test]
    fn missing_or_bad_lines_are_errors() {
        assert!(matches!(HubOutcome::from_stdout("tick 40 state hash 00\n"), Err(OutcomeReadError::NoJsonLine)));
        assert!(matches!(HubOutcome::from_stdout("{\"ticks\":\"x\"}"), Err(OutcomeReadError::Json(_))));
        let short_hash = r#"{"ticks":1,"run_s":0,"state_hash":"beef","agents_seen":0,"agents_died":0,"interrupted":false,"robots":[]}"#;
        let e = HubOutcome::from_stdout(short_hash).expect_err("short hash").to_string();
        assert!(e.contains("16 hex digits"), "{e}");
    }
}
