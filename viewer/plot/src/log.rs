//! A run log as the plot uses it: the per-robot CSV the agents write (read by
//! [`robot_log::LogTable`], the project's one log reader, whose errors name the file,
//! line and column), turned into samples of tick, time, position, heading and collision.
//! The plot needs `tick`, `time_s`, `x_m` and `y_m`; the tick must be a whole number and the
//! clock finite.
//!
//! An agent never knows its true pose: `x_m`, `y_m` are its GPS fix, NaN when the run has no
//! GPS. Rows without a fix (dropouts) are left out; a log with no fix at all cannot be drawn,
//! and [`RunLogReadError::NoPositions`] points to the run's recording, which holds the truth.

use std::path::{Path, PathBuf};

pub use robot_log::LogReadError;
use robot_log::LogTable;

/// Columns a log must have: the plot cannot be drawn without them.
pub const REQUIRED_COLUMNS: [&str; 4] = ["tick", "time_s", "x_m", "y_m"];

/// The recording `iwsim run` writes beside its logs.
pub const RECORDING_FILE: &str = "run.mcap";

/// Why a log could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum RunLogReadError {
    /// The file is not a readable log (the message names the file, line and column).
    #[error(transparent)]
    Read(#[from] LogReadError),
    /// No row has a finite position: the run gave its robots no GPS, so the log holds no
    /// trajectory. The run's recording does.
    #[error(
        "{} has no positions (the run has no GPS: its x_m, y_m columns are NaN); draw the run's recording instead: iwsim plot {}",
        .path.display(),
        .recording.display()
    )]
    NoPositions {
        /// The log.
        path: PathBuf,
        /// The recording of its run, where `iwsim run` puts it (beside the log).
        recording: PathBuf,
    },
}

/// One row of a log, the columns the plot uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Simulation tick.
    pub tick: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Position of the centre of movement, metres.
    pub x_m: f64,
    /// Position of the centre of movement, metres.
    pub y_m: f64,
    /// Heading in degrees; NaN when the log has no `heading_deg` column.
    pub heading_deg: f64,
    /// The collision sensor was on at this tick (`collision` = 1); false without the column.
    pub collision: bool,
}

/// A log read into memory.
#[derive(Debug, Clone, PartialEq)]
pub struct RunLog {
    /// Column names from the header, in file order.
    pub columns: Vec<String>,
    /// The rows with a position, in file order.
    pub samples: Vec<Sample>,
    /// Rows left out because their position is NaN (no GPS fix at that tick).
    pub unplaced_rows: usize,
}

impl RunLog {
    /// Reads and parses the log at `path`.
    pub fn read(path: &Path) -> Result<Self, RunLogReadError> {
        Self::from_table(LogTable::read(path)?)
    }

    /// Parses the text of a log; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, RunLogReadError> {
        Self::from_table(LogTable::parse(text, path)?)
    }

    fn from_table(t: LogTable) -> Result<Self, RunLogReadError> {
        let mut required = [0; REQUIRED_COLUMNS.len()];
        for (slot, name) in required.iter_mut().zip(REQUIRED_COLUMNS) {
            *slot = t.column(name)?;
        }
        let [tick_col, time_col, x_col, y_col] = required;
        let (heading_col, collision_col) = (t.column("heading_deg").ok(), t.column("collision").ok());
        let mut samples = Vec::with_capacity(t.rows.len());
        let mut unplaced_rows = 0;
        for (k, row) in t.rows.iter().enumerate() {
            let tick = row[tick_col];
            if !(tick >= 0.0 && tick.fract() == 0.0 && tick <= u64::MAX as f64) {
                return Err(t.bad_field(k, tick_col, "a whole number").into());
            }
            if !row[time_col].is_finite() {
                return Err(t.bad_field(k, time_col, "a finite number").into());
            }
            // NaN is the writer's "no fix"; an infinity is no position any sensor gives.
            if let Some(col) = [x_col, y_col].into_iter().find(|&c| row[c].is_infinite()) {
                return Err(t.bad_field(k, col, "a finite number or NaN").into());
            }
            if row[x_col].is_nan() || row[y_col].is_nan() {
                unplaced_rows += 1;
                continue;
            }
            samples.push(Sample {
                tick: tick as u64,
                time_s: row[time_col],
                x_m: row[x_col],
                y_m: row[y_col],
                heading_deg: heading_col.map_or(f64::NAN, |c| row[c]),
                collision: collision_col.is_some_and(|c| row[c] != 0.0 && !row[c].is_nan()),
            });
        }
        if t.rows.is_empty() {
            return Err(LogReadError::NoRows { path: t.path }.into());
        }
        if samples.is_empty() {
            let dir = t.path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
            let recording = dir.join(RECORDING_FILE);
            return Err(RunLogReadError::NoPositions { path: t.path, recording });
        }
        Ok(Self { columns: t.columns, samples, unplaced_rows })
    }

    /// Whether the log says when the robot was in collision (it has a `collision` column; a
    /// recording's track does not).
    pub fn knows_collisions(&self) -> bool {
        self.columns.iter().any(|c| c == "collision")
    }

    /// Distance driven along the logged positions, metres.
    pub fn distance_m(&self) -> f64 {
        // A fold from +0.0: an empty float `sum` is -0.0, which would print as "-0.0 m".
        self.samples.windows(2).map(|w| (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m)).fold(0.0, |a, d| a + d)
    }

    /// How many rows have the collision sensor on.
    pub fn collision_rows(&self) -> usize {
        self.samples.iter().filter(|s| s.collision).count()
    }
}

/// The speed over one interval between two logged ticks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedPoint {
    /// Time at the end of the interval, seconds.
    pub time_s: f64,
    /// Distance over the interval divided by its length, m/s.
    pub speed_m_s: f64,
    /// Index of the sample that ends the interval.
    pub sample: usize,
}

/// Speeds from successive positions, each over the true interval between two logged rows.
///
/// A row whose tick is not after the previous one (a re-published tick) is skipped, and so is
/// a row whose time does not advance; the next interval is then measured from the last row
/// kept, so no distance is lost.
pub fn speeds(samples: &[Sample]) -> Vec<SpeedPoint> {
    let mut out = Vec::with_capacity(samples.len().saturating_sub(1));
    let mut prev: Option<&Sample> = None;
    for (k, s) in samples.iter().enumerate() {
        match prev {
            None => prev = Some(s),
            Some(p) => {
                let dt = s.time_s - p.time_s;
                if s.tick <= p.tick || dt <= 0.0 {
                    continue;
                }
                let d = (s.x_m - p.x_m).hypot(s.y_m - p.y_m);
                out.push(SpeedPoint { time_s: s.time_s, speed_m_s: d / dt, sample: k });
                prev = Some(s);
            }
        }
    }
    out
}

/// A chair standing still: it stayed within [`STAND_RADIUS_M`] of where it stopped for at
/// least [`MIN_STAND_S`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stand {
    /// When it stopped, seconds.
    pub from_s: f64,
    /// When it moved on (or the log ended), seconds.
    pub to_s: f64,
    /// Where it stood, metres.
    pub x_m: f64,
    /// Where it stood, metres.
    pub y_m: f64,
    /// It never moved again before the log ended (arrived, or stuck for good).
    pub last: bool,
}

impl Stand {
    /// How long it stood, seconds.
    pub fn seconds(&self) -> f64 {
        self.to_s - self.from_s
    }
}

/// How far a chair may creep and still count as standing, metres.
pub const STAND_RADIUS_M: f64 = 0.05;
/// The shortest stand counted, seconds.
pub const MIN_STAND_S: f64 = 1.0;

/// Where and when the chair of `samples` stood still (see [`Stand`]), in time order.
pub fn stands(samples: &[Sample]) -> Vec<Stand> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < samples.len() {
        let a = &samples[i];
        let mut j = i + 1;
        while j < samples.len() && (samples[j].x_m - a.x_m).hypot(samples[j].y_m - a.y_m) <= STAND_RADIUS_M {
            j += 1;
        }
        let end = &samples[j - 1];
        let last = j == samples.len();
        let to_s = if last { end.time_s } else { samples[j].time_s };
        if to_s - a.time_s >= MIN_STAND_S {
            out.push(Stand { from_s: a.time_s, to_s, x_m: a.x_m, y_m: a.y_m, last });
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,proximity1_m,heading_deg,x_m,y_m,collision,contacts,power_left,power_right";

    fn parse(text: &str) -> Result<RunLog, RunLogReadError> {
        RunLog::parse(text, Path::new("runs/chair1.csv"))
    }

    /// The log reader's error for a log that is not readable.
    fn bad(text: &str) -> LogReadError {
        match parse(text) {
            Err(RunLogReadError::Read(e)) => e,
            other => panic!("expected a read error, got {other:?}"),
        }
    }

    #[test]
    fn a_good_log_reads_by_column_name() {
        let text = format!(
            "{HEADER}\n1,0.100,0,0,1.5000,NaN,0.000,10.0000,6.1000,0,0,0.500,0.500\n\
             2,0.200,3,3,1.4000,NaN,2.000,10.0500,6.1000,1,1,0.500,0.500\n\n"
        );
        let log = parse(&text).expect("reads");
        assert_eq!(log.columns.len(), 13);
        assert_eq!(log.samples.len(), 2);
        assert_eq!(
            log.samples[1],
            Sample { tick: 2, time_s: 0.2, x_m: 10.05, y_m: 6.1, heading_deg: 2.0, collision: true }
        );
        assert!(!log.samples[0].collision);
        assert_eq!(log.collision_rows(), 1);
        assert!(log.knows_collisions());
        assert_eq!(log.unplaced_rows, 0);
        assert!((log.distance_m() - 0.05).abs() < 1e-12);
    }

    #[test]
    fn old_logs_without_power_and_with_extra_columns_read() {
        let text = "tick,time_s,x_m,y_m,note,collision\r\n5,0.5,1,2,hello,0\r\n6,0.6,1.1,2,,0\r\n";
        let log = parse(text).expect("reads");
        assert_eq!(log.samples.len(), 2);
        assert!(log.samples[0].heading_deg.is_nan());
    }

    #[test]
    fn an_empty_file_is_reported() {
        assert!(matches!(bad("\n\n"), LogReadError::Empty { .. }));
    }

    #[test]
    fn a_log_without_header_is_reported_at_line_1() {
        let err = bad("1,0.1,10,6.1\n");
        assert!(matches!(err, LogReadError::NoHeader { line: 1, .. }), "{err:?}");
        assert!(err.to_string().starts_with("runs/chair1.csv:1: no header"), "{err}");
    }

    #[test]
    fn a_missing_position_column_is_named() {
        let err = bad("tick,time_s,x_m\n1,0.1,3\n");
        assert!(matches!(&err, LogReadError::MissingColumn { column, line: 1, .. } if column == "y_m"), "{err:?}");
    }

    #[test]
    fn a_repeated_column_is_named() {
        let err = bad("tick,time_s,x_m,y_m,x_m\n");
        assert!(matches!(&err, LogReadError::DuplicateColumn { column, .. } if column == "x_m"), "{err:?}");
    }

    #[test]
    fn a_short_row_gives_its_line_and_the_counts() {
        let err = bad("tick,time_s,x_m,y_m\n1,0.1,3,4\n\n2,0.2,3\n");
        assert!(matches!(err, LogReadError::FieldCount { line: 4, expected: 4, found: 3, .. }), "{err:?}");
        assert_eq!(err.to_string(), "runs/chair1.csv:4: 3 fields, expected 4 as in the header");
    }

    #[test]
    fn a_non_number_gives_its_line_and_column() {
        let err = bad("tick,time_s,x_m,y_m,proximity0_m\n1,0.1,3,4,0.5\n2,0.2,3,4,far\n");
        assert!(
            matches!(&err, LogReadError::BadNumber { line: 3, column: 5, name, text, expected: "a number", .. }
            if name == "proximity0_m" && text == "far"),
            "{err:?}"
        );
        assert_eq!(err.to_string(), "runs/chair1.csv:3: column 5 (proximity0_m): `far` is not a number");
    }

    #[test]
    fn a_fractional_tick_and_an_infinite_position_are_refused() {
        let err = bad("tick,time_s,x_m,y_m\n1.5,0.1,3,4\n");
        assert!(matches!(err, LogReadError::BadNumber { line: 2, column: 1, expected: "a whole number", .. }));
        let err = bad("tick,time_s,x_m,y_m\n1,0.1,3,inf\n");
        assert!(matches!(err, LogReadError::BadNumber { line: 2, column: 4, expected: "a finite number or NaN", .. }));
        let err = bad("tick,time_s,x_m,y_m\n1,NaN,3,4\n");
        assert!(matches!(err, LogReadError::BadNumber { line: 2, column: 2, expected: "a finite number", .. }));
    }

    #[test]
    fn a_log_without_gps_points_to_the_runs_recording() {
        let text = format!(
            "{HEADER}\n1,0.100,0,0,1.5,NaN,NaN,NaN,NaN,0,0,0.5,0.5\n2,0.200,3,3,1.4,NaN,NaN,NaN,NaN,0,0,0.5,0.5\n"
        );
        let err = parse(&text).expect_err("no positions");
        assert!(
            matches!(&err, RunLogReadError::NoPositions { path, recording }
                if path == Path::new("runs/chair1.csv") && recording == Path::new("runs/run.mcap")),
            "{err:?}"
        );
        assert_eq!(
            err.to_string(),
            "runs/chair1.csv has no positions (the run has no GPS: its x_m, y_m columns are NaN); \
             draw the run's recording instead: iwsim plot runs/run.mcap"
        );
        let err = RunLog::parse("tick,time_s,x_m,y_m\n1,0.1,NaN,NaN\n", Path::new("chair1.csv")).expect_err("none");
        assert!(err.to_string().ends_with("iwsim plot ./run.mcap"), "{err}");
    }

    #[test]
    fn gps_dropouts_are_skipped_and_the_speed_spans_them() {
        let text = "tick,time_s,x_m,y_m\n1,0.1,0.0,0\n2,0.2,NaN,NaN\n3,0.3,0.2,NaN\n4,0.4,0.3,0\n";
        let log = parse(text).expect("reads");
        assert_eq!(log.unplaced_rows, 2);
        assert_eq!(log.samples.iter().map(|s| s.tick).collect::<Vec<_>>(), [1, 4]);
        let v = speeds(&log.samples);
        assert_eq!(v.len(), 1);
        assert!((v[0].speed_m_s - 1.0).abs() < 1e-9, "0.3 m over 0.3 s: {v:?}");
        assert!(!log.knows_collisions());
    }

    #[test]
    fn one_row_drove_zero_metres() {
        let log = parse("tick,time_s,x_m,y_m\n1,0.1,3,4\n").expect("reads");
        assert_eq!(format!("{:.1}", log.distance_m()), "0.0");
    }

    #[test]
    fn a_header_alone_is_reported() {
        assert!(matches!(bad("tick,time_s,x_m,y_m\n"), LogReadError::NoRows { .. }));
    }

    #[test]
    fn a_missing_file_names_the_file() {
        let err = RunLog::read(Path::new("/nonexistent/iwsim/chair1.csv")).expect_err("missing");
        assert!(matches!(err, RunLogReadError::Read(LogReadError::Io { .. })));
        assert!(err.to_string().starts_with("/nonexistent/iwsim/chair1.csv: cannot read the log"), "{err}");
    }

    fn sample(tick: u64, time_s: f64, x_m: f64, y_m: f64) -> Sample {
        Sample { tick, time_s, x_m, y_m, heading_deg: 0.0, collision: false }
    }

    #[test]
    fn a_straight_run_at_constant_speed_gives_that_speed() {
        // 0.8 m/s along a diagonal, logged every 0.1 s.
        let (vx, vy) = (0.8 * 0.6, 0.8 * 0.8);
        let samples: Vec<Sample> =
            (0..50).map(|k| sample(k, 0.1 * k as f64, 10.0 + vx * 0.1 * k as f64, 6.0 + vy * 0.1 * k as f64)).collect();
        let v = speeds(&samples);
        assert_eq!(v.len(), 49);
        for (k, p) in v.iter().enumerate() {
            assert!((p.speed_m_s - 0.8).abs() < 1e-9, "{p:?}");
            assert_eq!(p.sample, k + 1);
            assert!((p.time_s - 0.1 * (k + 1) as f64).abs() < 1e-12);
        }
    }

    #[test]
    fn speed_uses_the_true_interval_and_skips_repeated_ticks() {
        let samples = [
            sample(1, 0.1, 0.0, 0.0),
            sample(2, 0.2, 0.1, 0.0),
            sample(2, 0.2, 0.1, 0.0), // re-published tick
            sample(4, 0.4, 0.5, 0.0), // a tick missed: 0.4 m over 0.2 s
            sample(5, 0.4, 0.9, 0.0), // clock did not advance: skipped
            sample(6, 0.6, 0.9, 0.0),
        ];
        let v: Vec<(f64, usize)> =
            speeds(&samples).iter().map(|p| ((p.speed_m_s * 1e6).round() / 1e6, p.sample)).collect();
        assert_eq!(v, [(1.0, 1), (2.0, 3), (2.0, 5)]);
    }

    #[test]
    fn a_chair_standing_still_for_a_second_or_more_is_found_where_and_when() {
        let at = |tick: u64, x: f64| Sample {
            tick,
            time_s: tick as f64 * 0.1,
            x_m: x,
            y_m: 2.0,
            heading_deg: 0.0,
            collision: false,
        };
        // Drives 1 s, waits 2 s (creeping 3 cm), drives 0.5 s, stops 0.5 s (too short), drives,
        // then stands to the end.
        let mut s: Vec<Sample> = (0..10).map(|t| at(t, t as f64 * 0.1)).collect();
        s.extend((10..30).map(|t| at(t, 0.9 + if t > 20 { 0.03 } else { 0.0 })));
        s.extend((30..35).map(|t| at(t, 0.93 + (t - 29) as f64 * 0.1)));
        s.extend((35..40).map(|t| at(t, 1.43)));
        s.extend((40..45).map(|t| at(t, 1.43 + (t - 39) as f64 * 0.1)));
        s.extend((45..70).map(|t| at(t, 1.93)));
        let st = stands(&s);
        assert_eq!(st.len(), 2, "{st:?}");
        assert_eq!((st[0].from_s, st[0].to_s, st[0].x_m, st[0].last), (0.9, 3.0, 0.9, false));
        assert!((st[0].seconds() - 2.1).abs() < 1e-9);
        assert_eq!((st[1].from_s, st[1].to_s, st[1].last), (4.4, 6.9, true));
    }
}
