//! A run's recording as the plot uses it: every robot's true trajectory (the hub's poses on
//! `/tf`, read by [`recorder::WorldTrack`]) as one [`RunLog`] per robot, and the lab, obstacles
//! and checkpoints of the run start (read by [`recorder::Recording`]).
//!
//! A frame's time is its tick × the run's cycle, so the speed over a frame the recorder dropped
//! is measured over the true interval, like a CSV log's over a missed tick ([`crate::log::speeds`]).
//! The recording says nothing of collisions on `/tf`, so a track's samples have none and its
//! [`RunLog::knows_collisions`] is false.

use std::path::{Path, PathBuf};

use places::Obstacle;
pub use recorder::RecordingReadError;
use recorder::journal::RunStart;
use recorder::{Recording, WorldTrack};

use crate::log::{RunLog, Sample};

/// The column names a track's [`RunLog`] carries (what a sample of it holds).
pub const TRACK_COLUMNS: [&str; 5] = ["tick", "time_s", "x_m", "y_m", "heading_deg"];

/// Why a recording's trajectories could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum TracksReadError {
    /// The file is not a readable recording.
    #[error(transparent)]
    Read(#[from] RecordingReadError),
    /// The recording holds no world frame (no robot ever joined, or the file was cut before
    /// its first complete chunk of frames).
    #[error("the recording {} holds no robot's pose{}", .path.display(), .truncated.as_deref().map(|t| format!(" ({t})")).unwrap_or_default())]
    NoFrames {
        /// The file.
        path: PathBuf,
        /// What the reader said was lost, when the file is cut short.
        truncated: Option<String>,
    },
    /// A robot asked for by name is not in the recording.
    #[error("the recording {} has no robot named {name:?}; it has {}", .path.display(), .known.join(", "))]
    UnknownRobot {
        /// The file.
        path: PathBuf,
        /// The name asked for.
        name: String,
        /// The robots it has, in the order they first appear.
        known: Vec<String>,
    },
}

/// What the plot draws from a recording.
#[derive(Debug, Clone)]
pub struct RecordedRun {
    /// What the run started from (its lab, obstacles and checkpoints among it).
    pub start: RunStart,
    /// Tick period, milliseconds.
    pub cycle_ms: u32,
    /// Each robot's name and true trajectory, in the order the robots first appear.
    pub robots: Vec<(String, RunLog)>,
    /// `None` for a complete file; otherwise where it ends and what was lost.
    pub truncated: Option<String>,
}

impl RecordedRun {
    /// Reads the recording at `path`, keeping the robots named in `only` (in that order), or
    /// every robot when `only` is empty.
    pub fn read(path: &Path, only: &[String]) -> Result<Self, TracksReadError> {
        let track = WorldTrack::open(path)?;
        let start = Recording::open(path)?.start;
        let truncated = track.truncated.clone();
        let all = robot_tracks(&track);
        if all.is_empty() {
            return Err(TracksReadError::NoFrames { path: path.into(), truncated });
        }
        let robots = if only.is_empty() {
            all
        } else {
            let known: Vec<String> = all.iter().map(|(n, _)| n.clone()).collect();
            let mut all = all;
            let mut kept = Vec::with_capacity(only.len());
            for name in only {
                // A name given twice is drawn once.
                if kept.iter().any(|(n, _): &(String, RunLog)| n == name) {
                    continue;
                }
                let Some(k) = all.iter().position(|(n, _)| n == name) else {
                    return Err(TracksReadError::UnknownRobot { path: path.into(), name: name.clone(), known });
                };
                kept.push(all.swap_remove(k));
            }
            kept
        };
        Ok(RecordedRun { cycle_ms: track.cycle_ms, start, robots, truncated })
    }
}

/// Each robot's samples from the frames that show it, robots in the order they first appear.
/// A robot that leaves and comes back keeps one track (its name is its identity in `/tf`).
pub fn robot_tracks(track: &WorldTrack) -> Vec<(String, RunLog)> {
    let seconds_per_tick = f64::from(track.cycle_ms) / 1000.0;
    let mut robots: Vec<(String, Vec<Sample>)> = Vec::new();
    for frame in &track.frames {
        let time_s = frame.tick as f64 * seconds_per_tick;
        for r in &frame.robots {
            let sample = Sample {
                tick: frame.tick,
                time_s,
                x_m: r.x_m,
                y_m: r.y_m,
                heading_deg: r.heading_deg,
                collision: false,
            };
            match robots.iter_mut().find(|(name, _)| *name == r.name) {
                Some((_, samples)) => samples.push(sample),
                None => robots.push((r.name.clone(), vec![sample])),
            }
        }
    }
    let columns: Vec<String> = TRACK_COLUMNS.iter().map(|c| (*c).to_owned()).collect();
    robots
        .into_iter()
        .map(|(name, samples)| (name, RunLog { columns: columns.clone(), samples, unplaced_rows: 0 }))
        .collect()
}

/// The lab without the scenario's obstacles, and those obstacles as boxes (the run start keeps
/// them as the lab's last walls, from `obstacle_from` on).
pub fn lab_and_obstacles(start: &RunStart) -> (world::map::Lab, Vec<Obstacle>) {
    let mut lab = start.lab.clone();
    let from = start.obstacle_from.min(lab.walls.len());
    let obstacles = lab
        .walls
        .split_off(from)
        .into_iter()
        .filter_map(|w| {
            // Scenario obstacles are axis-aligned boxes (the places crate), so the box around
            // a wall's corners is the obstacle itself.
            let (mut x0, mut y0, mut x1, mut y1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
            for c in &w.corners {
                (x0, y0, x1, y1) = (x0.min(c.x), y0.min(c.y), x1.max(c.x), y1.max(c.y));
            }
            (x0 < x1 && y0 < y1).then(|| Obstacle { name: String::new(), x0, y0, x1, y1, height: w.height_m })
        })
        .collect();
    (lab, obstacles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::{FixedName, RobotInfo, RobotState};
    use places::Checkpoint;
    use recorder::journal::Event;
    use recorder::{Recorder, RecorderOptions};
    use world::map::{Params, Wall, builtin};

    /// A fresh file path for one test, removed when dropped.
    struct TempFile(PathBuf);

    impl TempFile {
        fn new(name: &str) -> Self {
            let path = std::env::temp_dir().join(format!("iwsim-plot-track-{}-{name}.mcap", std::process::id()));
            let _ = std::fs::remove_file(&path);
            Self(path)
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    fn start(cycle_ms: u32) -> RunStart {
        let mut lab = builtin::map("liacc").expect("built in").lab;
        let obstacle_from = lab.walls.len();
        lab.walls.push(Wall::rectangle(17.0, 6.1, 17.6, 6.4, 0.8));
        RunStart {
            iwsim_version: "0.1.0-test".into(),
            seed: 1,
            dt_s: f64::from(cycle_ms) / 1000.0,
            lockstep: true,
            tick_limit: 0,
            cycle_ms,
            deadline_ms: 1000,
            lab,
            params: Params::default(),
            grid: Default::default(),
            obstacle_from,
            checkpoints: vec![Checkpoint { x: 12.0, y: 6.1, radius: 0.5 }],
        }
    }

    /// A robot's state in a snapshot and its info (which names it).
    fn state(id: u32, name: &str, x_m: f64, y_m: f64, heading_deg: f64) -> (RobotState, RobotInfo) {
        let state = RobotState {
            id,
            x_m,
            y_m,
            heading_deg,
            width_m: 1.1,
            height_m: 0.65,
            com: 0.5,
            ..bytemuck::Zeroable::zeroed()
        };
        (state, RobotInfo { robot_id: id, name: FixedName::truncated(name), ..bytemuck::Zeroable::zeroed() })
    }

    /// Records `frames` (tick, robots) as the hub does, one step event before each.
    fn record(path: &Path, start: &RunStart, frames: &[(u64, Vec<(RobotState, RobotInfo)>)]) {
        let mut rec = Recorder::create(path, start, RecorderOptions::default()).expect("created");
        rec.event(&Event::Settle);
        for (tick, robots) in frames {
            rec.event(&Event::Step { tick: tick - 1, actions: Vec::new(), hash: 0 });
            let (states, infos): (Vec<RobotState>, Vec<RobotInfo>) = robots.iter().copied().unzip();
            rec.world(*tick, &states, &infos);
        }
        let stats = rec.finish().expect("finished");
        assert_eq!(stats.dropped_world_frames, 0, "the test's frames are all written");
    }

    #[test]
    fn a_recording_gives_each_robots_true_track_and_speed_over_the_true_interval() {
        let file = TempFile::new("two");
        // chair1 drives east at 0.5 m/s (0.025 m a 50 ms tick); chair2 joins at tick 3 and
        // stands still. Tick 5 is missing, as when the recorder drops a frame.
        let mut frames = Vec::new();
        for tick in (1..=8).filter(|&t| t != 5) {
            let x = 10.0 + 0.025 * tick as f64;
            let mut robots = vec![state(1, "chair1", x, 6.1, 0.0)];
            if tick >= 3 {
                robots.push(state(2, "chair2", 20.0, 4.0, 90.0));
            }
            frames.push((tick, robots));
        }
        let start = start(50);
        record(&file.0, &start, &frames);

        let run = RecordedRun::read(&file.0, &[]).expect("reads");
        assert_eq!(run.cycle_ms, 50);
        assert!(run.truncated.is_none());
        let names: Vec<&str> = run.robots.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["chair1", "chair2"]);
        let chair1 = &run.robots[0].1;
        assert_eq!(chair1.samples.iter().map(|s| s.tick).collect::<Vec<_>>(), [1, 2, 3, 4, 6, 7, 8]);
        let s = chair1.samples[4];
        assert!((s.time_s - 0.3).abs() < 1e-12 && (s.x_m - 10.15).abs() < 1e-12 && s.y_m == 6.1, "{s:?}");
        assert!(!chair1.knows_collisions() && chair1.collision_rows() == 0);
        let v = crate::log::speeds(&chair1.samples);
        assert_eq!(v.len(), 6);
        assert!(v.iter().all(|p| (p.speed_m_s - 0.5).abs() < 1e-9), "{v:?}");
        assert!((v[3].time_s - 0.3).abs() < 1e-12, "the interval over the missing frame ends at tick 6");
        let chair2 = &run.robots[1].1;
        assert_eq!(chair2.samples.len(), 5);
        assert!((chair2.samples[0].heading_deg - 90.0).abs() < 1e-9);
        assert!(crate::log::speeds(&chair2.samples).iter().all(|p| p.speed_m_s.abs() < 1e-12));

        let only = RecordedRun::read(&file.0, &["chair2".into(), "chair1".into(), "chair2".into()]).expect("reads");
        let names: Vec<&str> = only.robots.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["chair2", "chair1"], "in the order asked, each once");
    }

    #[test]
    fn the_run_start_gives_the_lab_its_obstacles_and_checkpoints() {
        let file = TempFile::new("scene");
        let start = start(100);
        record(&file.0, &start, &[(1, vec![state(1, "chair1", 10.0, 6.1, 0.0)])]);
        let run = RecordedRun::read(&file.0, &[]).expect("reads");
        assert_eq!(run.start, start);
        let (lab, obstacles) = lab_and_obstacles(&run.start);
        assert_eq!(lab.walls.len(), start.obstacle_from, "the lab's own walls only");
        assert_eq!(lab.name, start.lab.name);
        assert_eq!(obstacles, [Obstacle { name: String::new(), x0: 17.0, y0: 6.1, x1: 17.6, y1: 6.4, height: 0.8 }]);
        assert_eq!(run.start.checkpoints, [Checkpoint { x: 12.0, y: 6.1, radius: 0.5 }]);
    }

    #[test]
    fn an_unknown_robot_or_an_empty_recording_is_named() {
        let file = TempFile::new("unknown");
        record(
            &file.0,
            &start(100),
            &[(1, vec![state(1, "chair1", 10.0, 6.1, 0.0), state(2, "door1", 9.4, 5.5, 90.0)])],
        );
        let err = RecordedRun::read(&file.0, &["chair9".into()]).expect_err("no chair9");
        assert!(
            matches!(&err, TracksReadError::UnknownRobot { name, known, .. } if name == "chair9" && known == &["chair1", "door1"]),
            "{err:?}"
        );
        assert!(err.to_string().ends_with("has no robot named \"chair9\"; it has chair1, door1"), "{err}");

        record(&file.0, &start(100), &[]);
        let err = RecordedRun::read(&file.0, &[]).expect_err("no frames");
        assert!(matches!(&err, TracksReadError::NoFrames { truncated: None, .. }), "{err:?}");
    }

    #[test]
    fn a_file_that_is_not_a_recording_is_a_read_error() {
        let file = TempFile::new("not-mcap");
        std::fs::write(&file.0, "tick,time_s,x_m,y_m\n").expect("written");
        let err = RecordedRun::read(&file.0, &[]).expect_err("not MCAP");
        assert!(matches!(err, TracksReadError::Read(_)), "{err:?}");
        let err = RecordedRun::read(Path::new("/nonexistent/iwsim/run.mcap"), &[]).expect_err("missing");
        assert!(matches!(err, TracksReadError::Read(RecordingReadError::Io { .. })), "{err:?}");
    }
}
