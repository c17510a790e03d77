//! The per-robot CSV logs of one agent ([`crate::log::RobotLog`]), kept the same way by every
//! agent: a log opens at its robot's first tick (when the sensor block says how many proximity
//! sensors the robot has), gets a row per tick answered, and ends with the run's final tick —
//! the readings the hub publishes as it finishes, which no agent answers (logged with zero
//! powers). So every agent's log of a run of N ticks holds ticks 0 to N.
//!
//! ```no_run
//! use agent_sdk::logs::RobotLogs;
//! use agent_sdk::{Agent, Wait};
//! use ipc_types::{ActionBlock, RobotRegistration};
//!
//! let mut agent = Agent::connect("demo", "my-agent").expect("a hub serves session demo");
//! let id = agent.register(&RobotRegistration::new("chair")).expect("accepted");
//! agent.ready().expect("hub still there");
//! let mut logs = RobotLogs::new(Some("runs".as_ref()));
//! logs.add(id, "chair");
//! while let Some(tick) = agent.wait_tick(Wait::Blocking).expect("hub alive") {
//!     let powers = [0.5, 0.5];
//!     agent.send(tick.tick, &[ActionBlock::motors(id, powers[0], powers[1])]).expect("sent");
//!     for b in agent.sensors() {
//!         logs.row(b, tick.sim_time_s, powers).expect("logged");
//!     }
//! }
//! logs.finish(&agent).expect("the final tick logged");
//! ```

use std::path::{Path, PathBuf};

use ipc_types::SensorBlock;

use crate::Agent;
use crate::log::RobotLog;

/// Why a log could not be written.
#[derive(Debug, thiserror::Error)]
pub enum LogWriteError {
    /// The directory or the file could not be created.
    #[error("cannot create the log of {name} in {}: {source}", .dir.display())]
    Create {
        /// The log directory.
        dir: PathBuf,
        /// The robot.
        name: String,
        /// What the system said.
        source: std::io::Error,
    },
    /// A row could not be written, or the file not flushed.
    #[error("cannot write {}: {source}", .path.display())]
    Write {
        /// The log file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
}

/// One robot's entry: its name, and its log once its first tick came.
#[derive(Debug)]
struct Entry {
    robot_id: u32,
    name: String,
    log: Option<RobotLog>,
}

/// The logs of an agent's robots, found by robot id. Without a directory nothing is written
/// and every call succeeds, so an agent calls it the same way with or without `--log`.
#[derive(Debug)]
pub struct RobotLogs {
    dir: Option<PathBuf>,
    robots: Vec<Entry>,
}

impl RobotLogs {
    /// Logs into `dir` (created when the first log opens), or nowhere when `None`.
    pub fn new(dir: Option<&Path>) -> Self {
        Self { dir: dir.map(Path::to_path_buf), robots: Vec::new() }
    }

    /// Logs robot `robot_id` (as the hub numbered it at registration) under `name`, the log's
    /// file being `robot_log::file_stem(name)` `.csv`.
    pub fn add(&mut self, robot_id: u32, name: &str) {
        self.robots.push(Entry { robot_id, name: name.to_owned(), log: None });
    }

    /// Writes the row of one tick answered: robot `block.robot_id`'s readings at `time_s`
    /// and the powers sent in answer. The robot's log opens at its first row; a robot not
    /// added, or a tick already logged, is passed over.
    pub fn row(&mut self, block: &SensorBlock, time_s: f64, powers: [f64; 2]) -> Result<(), LogWriteError> {
        let Some(dir) = &self.dir else { return Ok(()) };
        let Some(entry) = self.robots.iter_mut().find(|e| e.robot_id == block.robot_id) else { return Ok(()) };
        let log = match &mut entry.log {
            Some(log) => log,
            None => {
                let created = RobotLog::create(dir, &entry.name, block.proximity_count as usize)
                    .map_err(|source| LogWriteError::Create { dir: dir.clone(), name: entry.name.clone(), source })?;
                entry.log.insert(created)
            }
        };
        log.row(block, time_s, powers).map_err(|source| LogWriteError::Write { path: log.path().into(), source })
    }

    /// Writes the run's final tick — `blocks` as the hub published them when the run finished,
    /// at `time_s` — with zero powers, since nobody answers it; then flushes every log.
    pub fn final_rows(&mut self, blocks: &[SensorBlock], time_s: f64) -> Result<(), LogWriteError> {
        for b in blocks {
            self.row(b, time_s, [0.0, 0.0])?;
        }
        self.flush()
    }

    /// Ends the logs of `agent`'s run: when the hub finished the run (the agent's
    /// `wait_tick` returned `None`, or `try_tick` gave the Finished tick), writes its final
    /// readings as [`RobotLogs::final_rows`] does; in any case flushes every log. An agent
    /// that leaves before the run ends (a tick budget, a quit key) has no final tick to log.
    pub fn finish(&mut self, agent: &Agent) -> Result<(), LogWriteError> {
        if agent.finished() {
            // The Finished tick's own time: the tick loop never returned it.
            self.final_rows(agent.sensors(), agent.ticks.last_header.sim_time_s)
        } else {
            self.flush()
        }
    }

    /// Flushes every log opened.
    pub fn flush(&mut self) -> Result<(), LogWriteError> {
        for log in self.robots.iter_mut().filter_map(|e| e.log.as_mut()) {
            log.flush().map_err(|source| LogWriteError::Write { path: log.path().into(), source })?;
        }
        Ok(())
    }

    /// The files opened so far, in the order the robots were added.
    pub fn paths(&self) -> impl Iterator<Item = &Path> {
        self.robots.iter().filter_map(|e| e.log.as_ref().map(RobotLog::path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::LogTable;
    use bytemuck::Zeroable as _;

    fn block(robot_id: u32, tick: u64, proximity_count: u32) -> SensorBlock {
        let mut b = SensorBlock::zeroed();
        (b.robot_id, b.tick, b.proximity_count) = (robot_id, tick, proximity_count);
        b.gps_x_m = tick as f64;
        b.present = ipc_types::HAS_GPS;
        b
    }

    fn temp_dir(test: &str) -> PathBuf {
        std::env::temp_dir().join(format!("iwsim-sdk-logs-{test}-{}", std::process::id()))
    }

    #[test]
    fn every_robot_gets_a_row_per_tick_and_the_final_tick_last() {
        let dir = temp_dir("final");
        let _ = std::fs::remove_dir_all(&dir);
        let mut logs = RobotLogs::new(Some(&dir));
        logs.add(3, "door 1");
        logs.add(5, "chair1");
        assert_eq!(logs.paths().count(), 0, "logs open at the first tick, not before");
        for tick in 0..3 {
            logs.row(&block(3, tick, 4), tick as f64 * 0.1, [0.5, -0.5]).expect("row");
            logs.row(&block(5, tick, 8), tick as f64 * 0.1, [1.0, 1.0]).expect("row");
            // Another agent's robot is none of these logs' business.
            logs.row(&block(9, tick, 1), tick as f64 * 0.1, [1.0, 1.0]).expect("ignored");
        }
        // The hub finishes at tick 3: its readings come unanswered.
        logs.final_rows(&[block(3, 3, 4), block(5, 3, 8)], 0.3).expect("final rows");
        assert_eq!(logs.paths().collect::<Vec<_>>(), [dir.join("door%201.csv"), dir.join("chair1.csv")]);
        for (file, proximity) in [("door%201.csv", 4), ("chair1.csv", 8)] {
            let t = LogTable::read(&dir.join(file)).expect("readable");
            let col = |c: &str| t.column(c).expect("column");
            let ticks: Vec<f64> = t.rows.iter().map(|r| r[col("tick")]).collect();
            assert_eq!(ticks, [0.0, 1.0, 2.0, 3.0], "{file}");
            let last = &t.rows[3];
            assert_eq!((last[col("time_s")], last[col("x_m")]), (0.3, 3.0), "{file}");
            assert_eq!((last[col("power_left")], last[col("power_right")]), (0.0, 0.0), "{file}");
            assert_eq!(t.columns.iter().filter(|c| c.starts_with("proximity")).count(), proximity, "{file}");
        }
        assert_eq!(std::fs::read_dir(&dir).expect("dir").count(), 2, "no log for robot 9");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_final_tick_already_answered_is_not_logged_twice() {
        let dir = temp_dir("twice");
        let mut logs = RobotLogs::new(Some(&dir));
        logs.add(1, "a");
        logs.row(&block(1, 7, 2), 0.7, [0.2, 0.2]).expect("row");
        logs.final_rows(&[block(1, 7, 2)], 0.7).expect("final");
        let t = LogTable::read(&dir.join("a.csv")).expect("readable");
        assert_eq!(t.rows.len(), 1);
        assert_eq!(t.rows[0][t.column("power_left").expect("column")], 0.2);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn without_a_directory_nothing_is_written() {
        let mut logs = RobotLogs::new(None);
        logs.add(1, "a");
        logs.row(&block(1, 0, 2), 0.0, [0.0, 0.0]).expect("no-op");
        logs.final_rows(&[block(1, 1, 2)], 0.1).expect("no-op");
        assert_eq!(logs.paths().count(), 0);
    }

    #[test]
    fn an_uncreatable_directory_is_a_create_error() {
        let file = temp_dir("blocker");
        std::fs::write(&file, "a file where the directory should go").expect("write");
        let mut logs = RobotLogs::new(Some(&file));
        logs.add(1, "a");
        let err = logs.row(&block(1, 0, 2), 0.0, [0.0, 0.0]).expect_err("a file is not a directory");
        assert!(matches!(&err, LogWriteError::Create { name, .. } if name == "a"), "{err:?}");
        let _ = std::fs::remove_file(file);
    }
}
