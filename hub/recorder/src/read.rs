//! Reading recordings back: the replay journal ([`Recording`]) and the robots' poses per tick
//! ([`WorldTrack`], from `/tf`).
//!
//! Both read the file front to back, one record at a time, and accept a file that ends
//! abruptly (a hub killed mid-run): they keep everything up to the last complete chunk and say
//! what was lost in `truncated`.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use mcap::McapError;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::journal::{Event, JournalDecodeError, RunStart, decode_event, decode_run_start};
use crate::proto::{Fields, Value};
use crate::{EVENTS_TOPIC, RUN_TOPIC, TF_TOPIC};

/// Length of the MCAP magic at the start of a file.
const MAGIC_LEN: u64 = 8;
/// Largest record accepted outside a chunk; far above anything the recorder writes, it keeps a
/// corrupt length from making the reader buffer gigabytes.
const RECORD_LIMIT: usize = 256 * 1024 * 1024;

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingReadError {
    /// The file could not be opened or read.
    #[error("cannot read the recording {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A record is malformed (not a cut-off end: damage inside the file).
    #[error("the recording {path} is damaged at byte {offset}: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Where the record starts.
        offset: u64,
        /// What the MCAP reader said.
        source: McapError,
    },
    /// A replay-journal message does not decode.
    #[error("the recording {path} has a bad {topic} message in the chunk at byte {offset}: {source}")]
    Journal {
        /// The file.
        path: PathBuf,
        /// The chunk holding the message.
        offset: u64,
        /// Its channel.
        topic: &'static str,
        /// What is wrong with it.
        source: JournalDecodeError,
    },
    /// A `/tf` message does not decode as `foxglove.FrameTransforms`.
    #[error("the recording {path} has a bad {TF_TOPIC} message in the chunk at byte {offset}: {what}")]
    Frame {
        /// The file.
        path: PathBuf,
        /// The chunk holding the message.
        offset: u64,
        /// What is wrong with it.
        what: String,
    },
    /// The file holds no run start (it is not an iwsim recording, or it was cut before its
    /// first chunk was complete).
    #[error("the recording {path} holds no run start{}", .truncated.as_deref().map(|t| format!(" ({t})")).unwrap_or_default())]
    NoRunStart {
        /// The file.
        path: PathBuf,
        /// What [`Recording::truncated`] would say.
        truncated: Option<String>,
    },
}

/// A recording's replay channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// What the run started from.
    pub start: RunStart,
    /// Every event, in the order the hub recorded them.
    pub events: Vec<Event>,
    /// `None` for a complete file; otherwise where it ends and what was lost.
    pub truncated: Option<String>,
    /// The file's metadata records by name (`iwsim.run`, and `iwsim.wall_clock` when the wall
    /// clock was recorded).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

/// One robot at one tick, as drawn on `/tf`.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotPose {
    /// The robot's name (its frame).
    pub name: String,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, degrees in (−180, 180].
    pub heading_deg: f64,
}

/// The robots at one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldFrame {
    /// The tick.
    pub tick: u64,
    /// The robots, in the hub's order.
    pub robots: Vec<RobotPose>,
}

/// The people channel read back: every recorded world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldTrack {
    /// Tick period, milliseconds.
    pub cycle_ms: u32,
    /// Frames in time order (frames the recorder dropped are missing).
    pub frames: Vec<WorldFrame>,
    /// As [`Recording::truncated`].
    pub truncated: Option<String>,
}

impl Recording {
    /// Reads the run start and the replay events of `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Recording, RecordingReadError> {
        let path = path.as_ref();
        let mut start = None;
        let mut events = Vec::new();
        let mut last_tick = None;
        let scan = scan(path, |topic, _, offset, data| {
            let journal = |topic, source| RecordingReadError::Journal { path: path.into(), offset, topic, source };
            if topic == RUN_TOPIC {
                start = Some(decode_run_start(data).map_err(|e| journal(RUN_TOPIC, e))?);
            } else if topic == EVENTS_TOPIC {
                let event = decode_event(data).map_err(|e| journal(EVENTS_TOPIC, e))?;
                if let Event::Step { tick, .. } | Event::Finish { tick, .. } = &event {
                    last_tick = Some(*tick);
                }
                events.push(event);
            }
            Ok(())
        })?;
        let truncated = scan.truncated.map(|end| {
            let lost = match last_tick {
                Some(t) => format!("replay events after tick {t} are lost"),
                None => "every replay event is lost".to_owned(),
            };
            format!("{end}; {lost}")
        });
        let Some(start) = start else {
            return Err(RecordingReadError::NoRunStart { path: path.into(), truncated });
        };
        Ok(Recording { start, events, truncated, metadata: scan.metadata })
    }
}

impl WorldTrack {
    /// Reads the robots' poses per tick from `/tf` (and the tick period from the run start).
    pub fn open(path: impl AsRef<Path>) -> Result<WorldTrack, RecordingReadError> {
        let path = path.as_ref();
        let mut cycle_ms = None;
        let mut frames: Vec<(u64, Vec<RobotPose>)> = Vec::new();
        let scan = scan(path, |topic, t_ns, offset, data| {
            if topic == RUN_TOPIC {
                let start = decode_run_start(data).map_err(|source| RecordingReadError::Journal {
                    path: path.into(),
                    offset,
                    topic: RUN_TOPIC,
                    source,
                })?;
                cycle_ms = Some(start.cycle_ms);
            } else if topic == TF_TOPIC {
                let robots = decode_transforms(data).map_err(|what| RecordingReadError::Frame {
                    path: path.into(),
                    offset,
                    what,
                })?;
                frames.push((t_ns, robots));
            }
            Ok(())
        })?;
        let truncated = scan.truncated.map(|end| format!("{end}; world frames after the last complete chunk are lost"));
        let Some(cycle_ms) = cycle_ms else {
            return Err(RecordingReadError::NoRunStart { path: path.into(), truncated });
        };
        let cycle_ns = u64::from(cycle_ms).max(1) * 1_000_000;
        let frames = frames.into_iter().map(|(t_ns, robots)| WorldFrame { tick: t_ns / cycle_ns, robots }).collect();
        Ok(WorldTrack { cycle_ms, frames, truncated })
    }
}

/// A double's value from its field.
fn double(v: Value) -> Result<f64, String> {
    match v {
        Value::Fixed64(bits) => Ok(f64::from_bits(bits)),
        other => Err(format!("expected a double, found {other:?}")),
    }
}

fn message<'a>(v: Value<'a>, what: &str) -> Result<&'a [u8], String> {
    match v {
        Value::Bytes(b) => Ok(b),
        other => Err(format!("expected {what}, found {other:?}")),
    }
}

/// Reads `foxglove.FrameTransforms` (field numbers of the published schema).
fn decode_transforms(data: &[u8]) -> Result<Vec<RobotPose>, String> {
    let bad = |at: usize| format!("protobuf stops making sense at byte {at}");
    let mut robots = Vec::new();
    for field in Fields::new(data) {
        let (number, value) = field.map_err(bad)?;
        if number != 1 {
            continue;
        }
        let mut pose = RobotPose { name: String::new(), x_m: 0.0, y_m: 0.0, heading_deg: 0.0 };
        let (mut qz, mut qw) = (0.0, 0.0);
        for field in Fields::new(message(value, "a FrameTransform")?) {
            match field.map_err(bad)? {
                (3, v) => {
                    pose.name = String::from_utf8(message(v, "a frame id")?.to_vec())
                        .map_err(|_| "a frame id is not UTF-8".to_owned())?;
                }
                (4, v) => {
                    for f in Fields::new(message(v, "a Vector3")?) {
                        match f.map_err(bad)? {
                            (1, v) => pose.x_m = double(v)?,
                            (2, v) => pose.y_m = double(v)?,
                            _ => {}
                        }
                    }
                }
                (5, v) => {
                    for f in Fields::new(message(v, "a Quaternion")?) {
                        match f.map_err(bad)? {
                            (3, v) => qz = double(v)?,
                            (4, v) => qw = double(v)?,
                            _ => {}
                        }
                    }
                }
                _ => {}
            }
        }
        let heading = (2.0 * f64::atan2(qz, qw)).to_degrees();
        // atan2 gives (−180°, 180°] for the half angle's quadrant; fold the doubled angle back.
        pose.heading_deg = if heading > 180.0 {
            heading - 360.0
        } else if heading <= -180.0 {
            heading + 360.0
        } else {
            heading
        };
        robots.push(pose);
    }
    Ok(robots)
}

/// What a scan found besides the messages.
struct Scan {
    truncated: Option<String>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
}

/// Calls `on_message(topic, log_time, chunk offset, data)` for every message of every complete
/// chunk, in file order. A file that ends early is not an error: the scan stops at the last
/// complete record and says where in [`Scan::truncated`].
fn scan(
    path: &Path,
    mut on_message: impl FnMut(&str, u64, u64, &[u8]) -> Result<(), RecordingReadError>,
) -> Result<Scan, RecordingReadError> {
    let io = |source| RecordingReadError::Io { path: path.into(), source };
    // A device or a pipe is refused: a FIFO with no writer would block the open for ever.
    let mut file = places::files::open_regular(path).map_err(io)?;
    // Whole chunks only: messages of a chunk are used once all of it has arrived, so a cut
    // chunk is dropped whole rather than half-read.
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LIMIT),
    );
    let mut topics: BTreeMap<u16, String> = BTreeMap::new();
    let mut metadata = BTreeMap::new();
    // End of the last complete record (the magic counts as one).
    let mut good_end = 0u64;
    let mut read_total = 0u64;
    let mut seen_footer = false;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(McapError::UnexpectedEof) => {
                let end = if seen_footer {
                    format!("the file ends at byte {read_total} inside its closing magic, after its footer")
                } else if good_end == read_total && good_end > 0 {
                    format!("the file stops after byte {read_total} without its summary (the recorder did not finish)")
                } else {
                    format!(
                        "the file ends at byte {read_total} inside a record (the last complete one ends at byte {good_end})"
                    )
                };
                return Ok(Scan { truncated: Some(end), metadata });
            }
            Err(source) => return Err(RecordingReadError::Mcap { path: path.into(), offset: good_end, source }),
        };
        match event {
            LinearReadEvent::ReadRequest(need) => {
                let n = file.read(reader.insert(need)).map_err(io)?;
                reader.notify_read(n);
                read_total += n as u64;
            }
            LinearReadEvent::Record { opcode, data } => {
                let offset = good_end.max(MAGIC_LEN);
                good_end = offset + 9 + data.len() as u64;
                let mcap_err = |source| RecordingReadError::Mcap { path: path.into(), offset, source };
                match mcap::parse_record(opcode, data).map_err(mcap_err)? {
                    Record::Chunk { header, data } => {
                        let inner = mcap::read::ChunkReader::new(header, &data).map_err(mcap_err)?;
                        for record in inner {
                            match record.map_err(mcap_err)? {
                                Record::Channel(c) => {
                                    topics.insert(c.id, c.topic);
                                }
                                Record::Message { header, data } => {
                                    if let Some(topic) = topics.get(&header.channel_id) {
                                        on_message(topic, header.log_time, offset, &data)?;
                                    }
                                }
                                _ => {}
                            }
                        }
                    }
                    Record::Channel(c) => {
                        topics.insert(c.id, c.topic);
                    }
                    Record::Message { header, data } => {
                        if let Some(topic) = topics.get(&header.channel_id) {
                            on_message(topic, header.log_time, offset, &data)?;
                        }
                    }
                    Record::Metadata(m) => {
                        metadata.insert(m.name, m.metadata);
                    }
                    Record::Footer(_) => seen_footer = true,
                    _ => {}
                }
            }
        }
    }
    Ok(Scan { truncated: None, metadata })
}
