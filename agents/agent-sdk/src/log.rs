//! Per-robot CSV logs, one line per tick, in the columns of the thesis's Annex C with units in
//! the header: `tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,…,heading_deg,
//! x_m,y_m,collision,contacts,power_left,power_right`.
//!
//! Every agent writes its own robots' logs (it has their sensor blocks), so a run's logs are
//! complete whatever the tick rate; `iwsim run` reads them back for its summary and `iwsim
//! plot` draws them.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use ipc_types::SensorBlock;

/// The columns before the proximity readings.
pub const LEAD_COLUMNS: [&str; 4] = ["tick", "time_s", "encoder_left_ticks", "encoder_right_ticks"];
/// The columns after the proximity readings.
pub const TAIL_COLUMNS: [&str; 7] = ["heading_deg", "x_m", "y_m", "collision", "contacts", "power_left", "power_right"];

/// The header line (without newline) for a robot with `proximity` sensors.
pub fn header(proximity: usize) -> String {
    let mut cols: Vec<String> = LEAD_COLUMNS.iter().map(|s| s.to_string()).collect();
    cols.extend((0..proximity).map(|k| format!("proximity{k}_m")));
    cols.extend(TAIL_COLUMNS.iter().map(|s| s.to_string()));
    cols.join(",")
}

/// One robot's log file.
#[derive(Debug)]
pub struct RobotLog {
    out: BufWriter<File>,
    path: PathBuf,
    proximity: usize,
    last_tick: Option<u64>,
}

impl RobotLog {
    /// Creates `dir/<name>.csv` (and `dir`) for a robot with `proximity` sensors.
    pub fn create(dir: &Path, name: &str, proximity: usize) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(format!("{}.csv", file_stem(name)));
        let mut out = BufWriter::new(File::create(&path)?);
        writeln!(out, "{}", header(proximity))?;
        Ok(Self { out, path, proximity, last_tick: None })
    }

    /// The file written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends the row of one tick: the robot's sensor block at `time_s` and the powers its
    /// agent sends in answer. A tick already logged (a re-published tick) is skipped.
    pub fn row(&mut self, b: &SensorBlock, time_s: f64, powers: [f64; 2]) -> std::io::Result<()> {
        if self.last_tick.is_some_and(|t| t >= b.tick) {
            return Ok(());
        }
        self.last_tick = Some(b.tick);
        let mut line = format!("{},{:.3},{},{}", b.tick, time_s, b.encoder_ticks[0], b.encoder_ticks[1]);
        for k in 0..self.proximity {
            let d = if k < b.proximity_count as usize { b.proximity_m[k] } else { f64::NAN };
            line += &format!(",{d:.4}");
        }
        line += &format!(
            ",{:.3},{:.4},{:.4},{},{},{:.3},{:.3}\n",
            b.pose[2],
            b.pose[0],
            b.pose[1],
            u8::from(b.present & ipc_types::COLLISION != 0),
            b.collision_count,
            powers[0],
            powers[1]
        );
        self.out.write_all(line.as_bytes())
    }

    /// Flushes the file.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// A robot name as a file stem: letters, digits, `-` and `_` kept, anything else `_`.
pub fn file_stem(name: &str) -> String {
    let s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect();
    if s.is_empty() { "robot".into() } else { s }
}

/// A log read back: its column names and one row of numbers per tick.
#[derive(Debug, Clone, PartialEq)]
pub struct LogTable {
    /// Column names, from the header.
    pub columns: Vec<String>,
    /// Rows, each as long as `columns`.
    pub rows: Vec<Vec<f64>>,
}

/// Why a log could not be read.
#[derive(Debug, thiserror::Error)]
pub enum LogReadError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file has no header line.
    #[error("{path}: empty file, expected a header line")]
    Empty {
        /// File.
        path: String,
    },
    /// A row has the wrong number of fields.
    #[error("{path}:{line}: {got} fields, the header has {want}")]
    Width {
        /// File.
        path: String,
        /// Line, 1-based.
        line: usize,
        /// Fields found.
        got: usize,
        /// Fields expected.
        want: usize,
    },
    /// A field is not a number.
    #[error("{path}:{line}: column {column} ({name}): {text:?} is not a number")]
    Number {
        /// File.
        path: String,
        /// Line, 1-based.
        line: usize,
        /// Column, 1-based.
        column: usize,
        /// Column name.
        name: String,
        /// The text.
        text: String,
    },
    /// A column the reader needs is missing.
    #[error("{path}: no column {name:?} in the header")]
    MissingColumn {
        /// File.
        path: String,
        /// Column.
        name: String,
    },
}

impl LogTable {
    /// Reads a log written by [`RobotLog`] (or any all-numeric CSV with a header).
    pub fn read(path: &Path) -> Result<Self, LogReadError> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| LogReadError::Io { path: p.clone(), source })?;
        Self::parse(&text, &p)
    }

    /// Parses log text; `path` only names it in errors.
    pub fn parse(text: &str, path: &str) -> Result<Self, LogReadError> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let (_, head) = lines.next().ok_or_else(|| LogReadError::Empty { path: path.to_owned() })?;
        let columns: Vec<String> = head.split(',').map(|c| c.trim().to_owned()).collect();
        let mut rows = Vec::new();
        for (i, line) in lines {
            let fields: Vec<&str> = line.split(',').collect();
            if fields.len() != columns.len() {
                return Err(LogReadError::Width {
                    path: path.to_owned(),
                    line: i + 1,
                    got: fields.len(),
                    want: columns.len(),
                });
            }
            let row = fields
                .iter()
                .enumerate()
                .map(|(c, f)| {
                    f.trim().parse::<f64>().map_err(|_| LogReadError::Number {
                        path: path.to_owned(),
                        line: i + 1,
                        column: c + 1,
                        name: columns[c].clone(),
                        text: f.trim().to_owned(),
                    })
                })
                .collect::<Result<Vec<f64>, _>>()?;
            rows.push(row);
        }
        Ok(Self { columns, rows })
    }

    /// The index of column `name`, or an error naming `path`.
    pub fn column(&self, name: &str, path: &str) -> Result<usize, LogReadError> {
        self.columns
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| LogReadError::MissingColumn { path: path.to_owned(), name: name.to_owned() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;

    #[test]
    fn rows_follow_the_header_and_skip_repeated_ticks() {
        let dir = std::env::temp_dir().join(format!("iwsim-log-{}", std::process::id()));
        let mut log = RobotLog::create(&dir, "chair 1", 2).expect("created");
        let mut b = SensorBlock::zeroed();
        b.tick = 3;
        b.proximity_count = 2;
        b.proximity_m[..2].copy_from_slice(&[0.5, 1.25]);
        b.encoder_ticks = [10, -4];
        b.pose = [10.5, 6.1, 90.0];
        b.present = ipc_types::COLLISION;
        b.collision_count = 2;
        log.row(&b, 0.3, [0.5, -0.5]).expect("row");
        log.row(&b, 0.3, [0.5, -0.5]).expect("repeat skipped");
        log.flush().expect("flush");
        let text = std::fs::read_to_string(dir.join("chair_1.csv")).expect("file");
        assert_eq!(
            text,
            "tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,proximity1_m,heading_deg,x_m,y_m,collision,contacts,power_left,power_right\n\
             3,0.300,10,-4,0.5000,1.2500,90.000,10.5000,6.1000,1,2,0.500,-0.500\n"
        );
        let table = LogTable::read(&dir.join("chair_1.csv")).expect("reads back");
        assert_eq!(table.rows.len(), 1);
        assert_eq!(table.rows[0][table.column("x_m", "log").expect("x")], 10.5);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn bad_logs_name_the_line_and_column() {
        let err = LogTable::parse("tick,x_m\n1,2\n2,oops\n", "a.csv").expect_err("bad number");
        assert_eq!(err.to_string(), "a.csv:3: column 2 (x_m): \"oops\" is not a number");
        let err = LogTable::parse("tick,x_m\n1\n", "a.csv").expect_err("short row");
        assert_eq!(err.to_string(), "a.csv:2: 1 fields, the header has 2");
        assert!(matches!(LogTable::parse("", "a.csv"), Err(LogReadError::Empty { .. })));
        let t = LogTable::parse("tick,x_m\n1,NaN\n", "a.csv").expect("NaN is a number");
        assert!(t.rows[0][1].is_nan());
        assert!(t.column("y_m", "a.csv").is_err());
    }
}
