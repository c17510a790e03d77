//! Per-robot CSV logs, one line per tick, in the columns of the thesis's Annex C with units in
//! the header: `tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,…,heading_deg,
//! x_m,y_m,collision,contacts,power_left,power_right`.
//!
//! Every agent writes its own robots' logs (it has their sensor blocks), so a run's logs are
//! complete whatever the tick rate. They hold what the robot measured: `heading_deg` is its
//! compass and `x_m`, `y_m` its GPS fix (NaN when the run has no such sensor), never its true
//! pose, which only observers see; `iwsim run` judges a run from the hub's recording instead.
#![warn(missing_docs)]

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
    /// Creates `dir/<stem>.csv` (and `dir`) for a robot with `proximity` sensors, `<stem>`
    /// being [`file_stem`] of its name.
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
        // What the robot's own sensors say (an agent never gets its true pose): the compass's
        // heading and the GPS fix, NaN for a sensor the run does not have.
        let has = |bit: u32| b.present & bit != 0;
        let heading = if has(ipc_types::HAS_COMPASS) { b.compass_deg } else { f64::NAN };
        let (x, y) = if has(ipc_types::HAS_GPS) { (b.gps_x_m, b.gps_y_m) } else { (f64::NAN, f64::NAN) };
        line += &format!(
            ",{:.3},{:.4},{:.4},{},{},{:.3},{:.3}\n",
            heading,
            x,
            y,
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

/// A robot name as a file stem, one to one: ASCII letters, digits, `-` and `_` stay as they
/// are (so a plain name is its own stem: `chair1` → `chair1.csv`), and every other byte of the
/// name's UTF-8, `%` included, becomes `%XX` in upper-case hex (`chair 1` → `chair%201`).
/// Two different names therefore never share a log file, and [`robot_name`] gives the name
/// back (two robots with the same name, which the hub allows, still do). The empty name, which no hub accepts, is `%` (a stem no other name has).
pub fn file_stem(name: &str) -> String {
    if name.is_empty() {
        return "%".into();
    }
    let mut stem = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b == b'-' || b == b'_' {
            stem.push(char::from(b));
        } else {
            stem.push_str(&format!("%{b:02X}"));
        }
    }
    stem
}

/// The robot name a log's file stem stands for: the inverse of [`file_stem`]. `None` when the
/// stem is not one [`file_stem`] makes (a file renamed or written by hand), so a caller can
/// fall back to the stem itself.
pub fn robot_name(stem: &str) -> Option<String> {
    if stem == "%" {
        return Some(String::new());
    }
    let bytes = stem.as_bytes();
    let mut name = Vec::with_capacity(bytes.len());
    let mut k = 0;
    while k < bytes.len() {
        let b = bytes[k];
        if b == b'%' {
            let hex = stem.get(k + 1..k + 3)?;
            // Only upper-case hex, as written: a second spelling of one byte would make two
            // stems for one name.
            if !hex.bytes().all(|h| h.is_ascii_digit() || (b'A'..=b'F').contains(&h)) {
                return None;
            }
            let byte = u8::from_str_radix(hex, 16).ok()?;
            if byte.is_ascii_alphanumeric() || byte == b'-' || byte == b'_' {
                return None;
            }
            name.push(byte);
            k += 3;
        } else if b.is_ascii_alphanumeric() || b == b'-' || b == b'_' {
            name.push(b);
            k += 1;
        } else {
            return None;
        }
    }
    String::from_utf8(name).ok().filter(|n| !n.is_empty())
}

/// The robot whose log `path` is: [`robot_name`] of its file stem, or the stem itself for a
/// file [`RobotLog`] did not name (a log renamed by hand keeps its new name).
pub fn robot_name_of(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    robot_name(&stem).unwrap_or(stem)
}

/// The columns the writer fills with numbers (and `proximityK_m`): a reader insists on
/// numbers there; other columns (a user's additions) may hold anything and read as NaN when
/// they are not numbers.
const NUMERIC_COLUMNS: [&str; 11] = [
    "tick",
    "time_s",
    "encoder_left_ticks",
    "encoder_right_ticks",
    "heading_deg",
    "x_m",
    "y_m",
    "collision",
    "contacts",
    "power_left",
    "power_right",
];

fn is_numeric_column(name: &str) -> bool {
    NUMERIC_COLUMNS.contains(&name)
        || name
            .strip_prefix("proximity")
            .and_then(|rest| rest.strip_suffix("_m"))
            .is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()))
}

/// A log read back: its column names and one row of numbers per tick. The one reader of the
/// project's logs (`iwsim run`'s summary and `iwsim plot` both use it).
///
/// Columns are found by name, so logs with fewer proximity sensors, extra columns, or without
/// the `contacts`/`power_*` columns of older writers all read. Blank lines are skipped but
/// counted, so errors give the line a text editor shows.
#[derive(Debug, Clone, PartialEq)]
pub struct LogTable {
    /// The file, as named in errors.
    pub path: PathBuf,
    /// Column names, from the header.
    pub columns: Vec<String>,
    /// The header's line, 1-based.
    pub header_line: usize,
    /// Rows, each as long as `columns` (NaN for what is not a number in a column of the
    /// user's own).
    pub rows: Vec<Vec<f64>>,
    /// Each row's line, 1-based.
    pub lines: Vec<usize>,
}

/// Why a log could not be read. Lines count from 1; columns from 1.
#[derive(Debug, thiserror::Error)]
pub enum LogReadError {
    /// The file could not be opened or read.
    #[error("{}: cannot read the log: {source}", .path.display())]
    Io {
        /// The log file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file holds nothing, not even a header.
    #[error("{}: the log is empty: expected a header line `tick,time_s,…,x_m,y_m,…`", .path.display())]
    Empty {
        /// The log file.
        path: PathBuf,
    },
    /// The first line holds data, not column names.
    #[error("{}:{line}: no header: expected column names `tick,time_s,…,x_m,y_m,…`, found `{found}`", .path.display())]
    NoHeader {
        /// The log file.
        path: PathBuf,
        /// The line that should have been the header.
        line: usize,
        /// Its start, as found.
        found: String,
    },
    /// The header names a column twice.
    #[error("{}:{line}: the header names column `{column}` twice", .path.display())]
    DuplicateColumn {
        /// The log file.
        path: PathBuf,
        /// The header's line.
        line: usize,
        /// The repeated name.
        column: String,
    },
    /// The header lacks a column the reader needs.
    #[error("{}:{line}: the header has no column `{column}`", .path.display())]
    MissingColumn {
        /// The log file.
        path: PathBuf,
        /// The header's line.
        line: usize,
        /// The missing column.
        column: String,
    },
    /// A row has more or fewer fields than the header has columns.
    #[error("{}:{line}: {found} fields, expected {expected} as in the header", .path.display())]
    FieldCount {
        /// The log file.
        path: PathBuf,
        /// The row's line.
        line: usize,
        /// Columns in the header.
        expected: usize,
        /// Fields in this row.
        found: usize,
    },
    /// A field is not what its column holds.
    #[error("{}:{line}: column {column} ({name}): `{text}` is not {expected}", .path.display())]
    BadNumber {
        /// The log file.
        path: PathBuf,
        /// The row's line.
        line: usize,
        /// The column, counting from 1.
        column: usize,
        /// The column's name.
        name: String,
        /// The field as found.
        text: String,
        /// What was expected ("a number", "a whole number", "a finite number").
        expected: &'static str,
    },
    /// The header is there but no row follows.
    #[error("{}: the log has a header but no rows", .path.display())]
    NoRows {
        /// The log file.
        path: PathBuf,
    },
}

/// The largest log read, in bytes (256 MiB: a day of ticks at 10 a second, one robot).
pub const MAX_LOG_BYTES: u64 = 256 * 1024 * 1024;

impl LogTable {
    /// Reads the log at `path`: a regular file (a device or a pipe is refused) of at most
    /// [`MAX_LOG_BYTES`].
    pub fn read(path: &Path) -> Result<Self, LogReadError> {
        use std::io::Read as _;
        let io = |source| LogReadError::Io { path: path.into(), source };
        let mut bytes = Vec::new();
        places::files::open_regular(path).map_err(io)?.take(MAX_LOG_BYTES + 1).read_to_end(&mut bytes).map_err(io)?;
        if u64::try_from(bytes.len()).unwrap_or(u64::MAX) > MAX_LOG_BYTES {
            let why = format!("larger than {MAX_LOG_BYTES} bytes: not a robot's log");
            return Err(io(std::io::Error::new(std::io::ErrorKind::InvalidData, why)));
        }
        let text = String::from_utf8(bytes)
            .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {e}"))))?;
        Self::parse(&text, path)
    }

    /// Parses log text; `path` only names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, LogReadError> {
        let mut lines = text.lines().enumerate().map(|(k, l)| (k + 1, l.trim_end_matches('\r')));
        let (header_line, head) = lines
            .by_ref()
            .find(|(_, l)| !l.trim().is_empty())
            .ok_or_else(|| LogReadError::Empty { path: path.into() })?;
        let columns: Vec<String> = head.split(',').map(|c| c.trim().to_owned()).collect();
        if columns.first().is_some_and(|c| c.parse::<f64>().is_ok()) {
            let found: String = head.chars().take(40).collect();
            return Err(LogReadError::NoHeader { path: path.into(), line: header_line, found });
        }
        for (k, c) in columns.iter().enumerate() {
            if columns[..k].contains(c) {
                return Err(LogReadError::DuplicateColumn { path: path.into(), line: header_line, column: c.clone() });
            }
        }
        let numeric: Vec<bool> = columns.iter().map(|c| is_numeric_column(c)).collect();
        let mut rows = Vec::new();
        let mut row_lines = Vec::new();
        for (line, text) in lines {
            if text.trim().is_empty() {
                continue;
            }
            let fields: Vec<&str> = text.split(',').map(str::trim).collect();
            if fields.len() != columns.len() {
                return Err(LogReadError::FieldCount {
                    path: path.into(),
                    line,
                    expected: columns.len(),
                    found: fields.len(),
                });
            }
            let row = fields
                .iter()
                .enumerate()
                .map(|(k, f)| match f.parse::<f64>() {
                    Ok(v) => Ok(v),
                    Err(_) if !numeric[k] => Ok(f64::NAN),
                    Err(_) => Err(LogReadError::BadNumber {
                        path: path.into(),
                        line,
                        column: k + 1,
                        name: columns[k].clone(),
                        text: (*f).to_owned(),
                        expected: "a number",
                    }),
                })
                .collect::<Result<Vec<f64>, _>>()?;
            rows.push(row);
            row_lines.push(line);
        }
        Ok(Self { path: path.into(), columns, header_line, rows, lines: row_lines })
    }

    /// The index of column `name`, or an error naming the file and the header's line.
    pub fn column(&self, name: &str) -> Result<usize, LogReadError> {
        self.columns.iter().position(|c| c == name).ok_or_else(|| LogReadError::MissingColumn {
            path: self.path.clone(),
            line: self.header_line,
            column: name.to_owned(),
        })
    }

    /// The error for the field of row `row`, column `column` that is not `expected`.
    pub fn bad_field(&self, row: usize, column: usize, expected: &'static str) -> LogReadError {
        LogReadError::BadNumber {
            path: self.path.clone(),
            line: self.lines.get(row).copied().unwrap_or(0),
            column: column + 1,
            name: self.columns.get(column).cloned().unwrap_or_default(),
            text: self.rows.get(row).and_then(|r| r.get(column)).map_or_else(String::new, |v| v.to_string()),
            expected,
        }
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
        (b.compass_deg, b.gps_x_m, b.gps_y_m) = (90.0, 10.5, 6.1);
        b.present = ipc_types::COLLISION | ipc_types::HAS_COMPASS | ipc_types::HAS_GPS;
        b.collision_count = 2;
        log.row(&b, 0.3, [0.5, -0.5]).expect("row");
        log.row(&b, 0.3, [0.5, -0.5]).expect("repeat skipped");
        // Without GPS and compass, the pose columns say so.
        b.tick = 4;
        b.present = 0;
        log.row(&b, 0.4, [0.5, -0.5]).expect("row");
        log.flush().expect("flush");
        assert_eq!(log.path(), dir.join("chair%201.csv"));
        let text = std::fs::read_to_string(log.path()).expect("file");
        assert_eq!(
            text,
            "tick,time_s,encoder_left_ticks,encoder_right_ticks,proximity0_m,proximity1_m,heading_deg,x_m,y_m,collision,contacts,power_left,power_right\n\
             3,0.300,10,-4,0.5000,1.2500,90.000,10.5000,6.1000,1,2,0.500,-0.500\n\
             4,0.400,10,-4,0.5000,1.2500,NaN,NaN,NaN,0,2,0.500,-0.500\n"
        );
        let table = LogTable::read(&dir.join("chair%201.csv")).expect("reads back");
        assert_eq!(table.rows.len(), 2);
        assert_eq!(table.rows[0][table.column("x_m").expect("x")], 10.5);
        assert!(table.rows[1][table.column("x_m").expect("x")].is_nan());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn file_stems_keep_plain_names_and_never_collide() {
        for plain in ["chair1", "door-2", "A_b", "B"] {
            assert_eq!(file_stem(plain), plain);
            assert_eq!(robot_name(plain).as_deref(), Some(plain));
        }
        // The names that used to share `a_b.csv`, and others a file system would mangle.
        let names = ["a b", "a_b", "a%20b", "a.b", "../x", ".hidden", "é", "a/b", "", "%", "x%"];
        let stems: Vec<String> = names.iter().map(|n| file_stem(n)).collect();
        assert_eq!(stems[..4], ["a%20b", "a_b", "a%2520b", "a%2Eb"]);
        for (k, (name, stem)) in names.iter().zip(&stems).enumerate() {
            assert!(!stems[..k].contains(stem), "{name:?} shares {stem:?}");
            assert!(stem.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_%".contains(&b)), "{stem:?}");
            assert_eq!(robot_name(stem).as_deref(), Some(*name), "{stem:?}");
        }
        // Stems no name maps to: a hand-made file is not mistaken for a robot.
        for odd in ["a b", "a%2", "a%zz", "a%2e", "a%41", "a.csv", "%C3"] {
            assert_eq!(robot_name(odd), None, "{odd:?}");
        }
        assert_eq!(robot_name_of(Path::new("runs/chair%201.csv")), "chair 1");
        assert_eq!(robot_name_of(Path::new("runs/chair1.csv")), "chair1");
        assert_eq!(robot_name_of(Path::new("runs/my run.csv")), "my run", "a hand-named file keeps its name");
    }

    #[test]
    fn bad_logs_name_the_file_line_and_column() {
        let parse = |t: &str| LogTable::parse(t, Path::new("runs/a.csv"));
        let err = parse("tick,x_m\n1,2\n\n2,oops\n").expect_err("bad number");
        assert_eq!(err.to_string(), "runs/a.csv:4: column 2 (x_m): `oops` is not a number");
        let err = parse("tick,x_m\n1\n").expect_err("short row");
        assert_eq!(err.to_string(), "runs/a.csv:2: 1 fields, expected 2 as in the header");
        assert!(matches!(parse("\n\n"), Err(LogReadError::Empty { .. })));
        let err = parse("1,0.1,10,6.1\n").expect_err("no header");
        assert!(err.to_string().starts_with("runs/a.csv:1: no header"), "{err}");
        let err = parse("tick,x_m,x_m\n").expect_err("twice");
        assert!(matches!(&err, LogReadError::DuplicateColumn { column, .. } if column == "x_m"), "{err:?}");
        // NaN is a number (a sensor that saw nothing); a user's own column may hold text.
        let t = parse("tick,x_m,note\r\n1,NaN,hello\r\n").expect("reads");
        assert!(t.rows[0][1].is_nan() && t.rows[0][2].is_nan());
        let err = t.column("y_m").expect_err("no y_m");
        assert_eq!(err.to_string(), "runs/a.csv:1: the header has no column `y_m`");
        assert_eq!(
            t.bad_field(0, 1, "a finite number").to_string(),
            "runs/a.csv:2: column 2 (x_m): `NaN` is not a finite number"
        );
    }
}
