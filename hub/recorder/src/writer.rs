//! [`Recorder`]: the hub's side. The tick thread encodes replay events and copies world frames
//! into pooled buffers and hands them to a writer thread through one bounded queue; the writer
//! thread turns them into MCAP messages.
//!
//! One queue, not two, so the order of messages in the file is the order the hub produced them
//! and two recordings of the same lock-step run are byte-identical.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{SystemTime, UNIX_EPOCH};

use ipc_types::{RobotInfo, RobotState};
use mcap::records::{MessageHeader, Metadata};

use crate::foxglove;
use crate::journal::{Event, RunStart, encode_event, encode_run_start};
use crate::{
    EVENTS_TOPIC, FRAME_TRANSFORMS_SCHEMA_NAME, JOURNAL_ENCODING, LAB_TOPIC, METADATA_NAME, PROTOBUF, PROXIMITY_TOPIC,
    ROBOTS_TOPIC, RUN_TOPIC, SCENE_UPDATE_SCHEMA_NAME, TF_TOPIC, WALL_CLOCK_METADATA_NAME,
};

/// How a [`Recorder`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderOptions {
    /// Items the queue to the writer thread holds (events and world frames together).
    pub queue_len: usize,
    /// A chunk is closed and written through to the file before it grows past this many bytes.
    pub chunk_bytes: u64,
    /// … or once it spans this much simulated time, nanoseconds.
    pub chunk_sim_ns: u64,
    /// The wall-clock time the run started, written to a metadata record of its own. `None`
    /// leaves it out, so that two recordings of one lock-step run are identical byte for byte.
    pub wall_clock_start: Option<SystemTime>,
    /// Wait for the writer thread rather than drop a world frame (lock-step runs: no tick has
    /// a wall-clock deadline to keep, so the people channels hold every tick); off, a frame
    /// is dropped and counted when the writer is behind, so a real-time tick never waits.
    pub keep_every_frame: bool,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            queue_len: 256,
            chunk_bytes: 256 * 1024,
            chunk_sim_ns: 1_000_000_000,
            wall_clock_start: None,
            keep_every_frame: false,
        }
    }
}

/// What a finished recording holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordStats {
    /// Replay events written (`/iwsim/events`), the run start not counted.
    pub events: u64,
    /// World frames written (each is one message on `/robots`, `/tf` and `/proximity`).
    pub world_frames: u64,
    /// Messages written on every channel together, `/lab` and `/iwsim/run` included.
    pub messages: u64,
    /// World frames dropped because the writer thread was behind.
    pub dropped_world_frames: u64,
    /// Times an event (or, keeping every frame, a world frame) found the queue full and the
    /// tick waited for the writer thread.
    pub replay_stalls: u64,
    /// File size, bytes.
    pub bytes: u64,
    /// Chunks written.
    pub chunks: u64,
}

/// Why a recording could not be started.
#[derive(Debug, thiserror::Error)]
pub enum RecorderCreateError {
    /// The file could not be created.
    #[error("cannot create the recording {path}: {source}")]
    Create {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP header, schemas, channels or first messages could not be written.
    #[error("cannot start the recording {path}: {source}")]
    Start {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// The writer thread could not be started.
    #[error("cannot start the recording thread: {0}")]
    Thread(std::io::Error),
}

/// Why a recording could not be finished. What was written before the failure stays readable
/// up to its last complete chunk.
#[derive(Debug, thiserror::Error)]
pub enum RecorderFinishError {
    /// Writing failed (disk full, file removed, …); the rest of the run was not recorded.
    #[error("writing the recording {path} failed: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// The writer thread panicked.
    #[error("the recording thread of {path} panicked")]
    Panicked {
        /// The file.
        path: PathBuf,
    },
}

/// One robot-state frame, kept in a pool and reused.
#[derive(Debug, Default)]
struct Frame {
    t_ns: u64,
    states: Vec<RobotState>,
    sensors: Vec<RobotInfo>,
}

/// What the tick thread sends the writer thread.
#[derive(Debug)]
enum Job {
    Event { t_ns: u64, bytes: Vec<u8> },
    World(Frame),
    Metadata(mcap::records::Metadata),
}

/// Records a run into an MCAP file. See the crate docs for the channels.
#[derive(Debug)]
pub struct Recorder {
    path: PathBuf,
    cycle_ns: u64,
    /// The tick an event not carrying one belongs to: the tick after the last step.
    now_tick: u64,
    jobs: Option<SyncSender<Job>>,
    spare_bytes: Receiver<Vec<u8>>,
    spare_frames: Receiver<Frame>,
    thread: Option<JoinHandle<Result<WriterTotals, mcap::McapError>>>,
    dropped_world_frames: u64,
    replay_stalls: u64,
    keep_every_frame: bool,
}

/// What the writer thread counts.
#[derive(Debug, Default)]
struct WriterTotals {
    events: u64,
    world_frames: u64,
    messages: u64,
    chunks: u64,
    bytes: u64,
}

impl Recorder {
    /// Creates `path` (replacing a file there), writes the run start and the lab, and starts
    /// the writer thread.
    pub fn create(
        path: impl AsRef<Path>,
        start: &RunStart,
        options: RecorderOptions,
    ) -> Result<Recorder, RecorderCreateError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path).map_err(|source| RecorderCreateError::Create { path: path.clone(), source })?;
        let cycle_ns = u64::from(start.cycle_ms) * 1_000_000;
        let out = Output::start(BufWriter::new(file), start, &options)
            .map_err(|source| RecorderCreateError::Start { path: path.clone(), source })?;
        let queue_len = options.queue_len.max(1);
        let (jobs, inbox) = sync_channel(queue_len);
        // The return queues hold every buffer that can be in flight, so returning never blocks
        // the writer thread; surplus buffers are simply dropped.
        let (bytes_back, spare_bytes) = sync_channel(queue_len + 1);
        let (frames_back, spare_frames) = sync_channel(queue_len + 1);
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || out.run(inbox, bytes_back, frames_back))
            .map_err(RecorderCreateError::Thread)?;
        Ok(Recorder {
            path,
            cycle_ns,
            now_tick: 0,
            jobs: Some(jobs),
            spare_bytes,
            spare_frames,
            thread: Some(thread),
            dropped_world_frames: 0,
            replay_stalls: 0,
            keep_every_frame: options.keep_every_frame,
        })
    }

    fn t_ns(&self, tick: u64) -> u64 {
        tick.saturating_mul(self.cycle_ns)
    }

    /// Records a replay event. Never dropped: when the writer thread is behind, this waits for
    /// it (and counts a stall) rather than lose replay data.
    ///
    /// Message time: a step at its `tick` (the tick before it), a finish at its tick, and the
    /// other events at the tick after the last step.
    pub fn event(&mut self, event: &Event) {
        let tick = match event {
            Event::Step { tick, .. } => {
                self.now_tick = tick.saturating_add(1);
                *tick
            }
            Event::Finish { tick, .. } => *tick,
            _ => self.now_tick,
        };
        let t_ns = self.t_ns(tick);
        let mut bytes = self.spare_bytes.try_recv().unwrap_or_default();
        bytes.clear();
        encode_event(event, &mut bytes);
        let Some(jobs) = &self.jobs else { return };
        match jobs.try_send(Job::Event { t_ns, bytes }) {
            Ok(()) => {}
            Err(TrySendError::Full(job)) => {
                self.replay_stalls += 1;
                if jobs.send(job).is_err() {
                    // The writer thread stopped on an error; finish() reports it.
                    self.jobs = None;
                }
            }
            Err(TrySendError::Disconnected(_)) => self.jobs = None,
        }
    }

    /// Records what the world looks like at `tick` (after the step that led to it) for people.
    /// When the writer thread is behind, dropped and counted (the tick never waits for it), or
    /// with [`RecorderOptions::keep_every_frame`] waited for (counted as a stall).
    pub fn world(&mut self, tick: u64, states: &[RobotState], sensors: &[RobotInfo]) {
        let Some(jobs) = &self.jobs else { return };
        let mut frame = self.spare_frames.try_recv().unwrap_or_default();
        frame.t_ns = self.t_ns(tick);
        frame.states.clear();
        frame.states.extend_from_slice(states);
        frame.sensors.clear();
        frame.sensors.extend_from_slice(sensors);
        match jobs.try_send(Job::World(frame)) {
            Ok(()) => {}
            Err(TrySendError::Full(job)) if self.keep_every_frame => {
                self.replay_stalls += 1;
                if jobs.send(job).is_err() {
                    self.jobs = None;
                }
            }
            Err(TrySendError::Full(_)) => self.dropped_world_frames += 1,
            Err(TrySendError::Disconnected(_)) => self.jobs = None,
        }
    }

    /// Records a named table of text (an MCAP metadata record, which any MCAP reader lists
    /// without iwsim's codec): the run's final challenge standings, for one. Never dropped.
    pub fn metadata(&mut self, name: &str, entries: std::collections::BTreeMap<String, String>) {
        let Some(jobs) = &self.jobs else { return };
        if jobs.send(Job::Metadata(mcap::records::Metadata { name: name.to_owned(), metadata: entries })).is_err() {
            self.jobs = None;
        }
    }

    /// Writes everything still queued, the summary and the footer, and closes the file.
    pub fn finish(mut self) -> Result<RecordStats, RecorderFinishError> {
        // Closing the queue tells the writer thread to finish the file.
        self.jobs = None;
        let Some(thread) = self.thread.take() else {
            return Err(RecorderFinishError::Panicked { path: self.path.clone() });
        };
        let totals = match thread.join() {
            Ok(Ok(t)) => t,
            Ok(Err(source)) => return Err(RecorderFinishError::Write { path: self.path.clone(), source }),
            Err(_) => return Err(RecorderFinishError::Panicked { path: self.path.clone() }),
        };
        Ok(RecordStats {
            events: totals.events,
            world_frames: totals.world_frames,
            messages: totals.messages,
            dropped_world_frames: self.dropped_world_frames,
            replay_stalls: self.replay_stalls,
            bytes: totals.bytes,
            chunks: totals.chunks,
        })
    }
}

impl Drop for Recorder {
    /// A recorder dropped without [`Recorder::finish`] still closes its file properly (a hub
    /// that unwinds keeps its recording).
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(thread) = self.thread.take() {
            match thread.join() {
                Ok(Ok(_)) => {}
                Ok(Err(e)) => tracing::warn!(path = %self.path.display(), "recording failed: {e}"),
                Err(_) => tracing::warn!(path = %self.path.display(), "the recording thread panicked"),
            }
        }
    }
}

/// Channel ids.
#[derive(Debug, Clone, Copy)]
struct Channels {
    events: u16,
    robots: u16,
    tf: u16,
    proximity: u16,
}

/// The writer thread's state.
struct Output {
    mcap: mcap::Writer<BufWriter<File>>,
    channels: Channels,
    /// Next sequence number of each channel, by channel id.
    sequences: [u32; 8],
    chunk_bytes: u64,
    chunk_sim_ns: u64,
    /// Bytes and start time of the chunk being filled; `None` when no chunk is open.
    chunk: Option<(u64, u64)>,
    totals: WriterTotals,
    buf: Vec<u8>,
    id: String,
    name: String,
}

impl std::fmt::Debug for Output {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Output").field("channels", &self.channels).finish_non_exhaustive()
    }
}

/// Bytes of an MCAP Message record beyond its data (opcode, length, header).
const MESSAGE_OVERHEAD: u64 = 1 + 8 + 2 + 4 + 8 + 8;

impl Output {
    fn start(file: BufWriter<File>, start: &RunStart, options: &RecorderOptions) -> Result<Self, mcap::McapError> {
        let mut mcap = mcap::WriteOptions::new()
            .compression(None)
            // Chunks are closed by `Output::write` (size and simulated time), never by the
            // library, and are buffered whole so the file only ever grows by complete chunks.
            .chunk_size(None)
            .disable_seeking(true)
            .library(format!("iwsim-recorder {}", env!("CARGO_PKG_VERSION")))
            .create(file)?;
        let no_meta = BTreeMap::new();
        let journal = |m: &mut mcap::Writer<_>, topic| m.add_channel(0, topic, JOURNAL_ENCODING, &no_meta);
        let run = journal(&mut mcap, RUN_TOPIC)?;
        let events = journal(&mut mcap, EVENTS_TOPIC)?;
        let scene = mcap.add_schema(SCENE_UPDATE_SCHEMA_NAME, PROTOBUF, foxglove::SCENE_UPDATE_SCHEMA)?;
        let tf_schema = mcap.add_schema(FRAME_TRANSFORMS_SCHEMA_NAME, PROTOBUF, foxglove::FRAME_TRANSFORMS_SCHEMA)?;
        let lab = mcap.add_channel(scene, LAB_TOPIC, PROTOBUF, &no_meta)?;
        let robots = mcap.add_channel(scene, ROBOTS_TOPIC, PROTOBUF, &no_meta)?;
        let tf = mcap.add_channel(tf_schema, TF_TOPIC, PROTOBUF, &no_meta)?;
        let proximity = mcap.add_channel(scene, PROXIMITY_TOPIC, PROTOBUF, &no_meta)?;

        // Metadata records sit outside chunks and close the chunk in progress, so they are
        // written first. The run's description is deterministic; the wall clock is optional.
        let run_metadata = BTreeMap::from([
            ("iwsim_version".to_owned(), start.iwsim_version.clone()),
            ("lab".to_owned(), start.lab.name.clone()),
            ("seed".to_owned(), start.seed.to_string()),
            ("lockstep".to_owned(), start.lockstep.to_string()),
            ("cycle_ms".to_owned(), start.cycle_ms.to_string()),
        ]);
        mcap.write_metadata(&Metadata { name: METADATA_NAME.to_owned(), metadata: run_metadata })?;
        if let Some(wall) = options.wall_clock_start {
            let ns = wall.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos());
            let clock = BTreeMap::from([("unix_ns".to_owned(), ns.to_string())]);
            mcap.write_metadata(&Metadata { name: WALL_CLOCK_METADATA_NAME.to_owned(), metadata: clock })?;
        }

        let mut out = Output {
            mcap,
            channels: Channels { events, robots, tf, proximity },
            sequences: [0; 8],
            chunk_bytes: options.chunk_bytes.max(1),
            chunk_sim_ns: options.chunk_sim_ns.max(1),
            chunk: None,
            totals: WriterTotals::default(),
            buf: Vec::new(),
            id: String::new(),
            name: String::new(),
        };
        let mut bytes = Vec::new();
        encode_run_start(start, &mut bytes);
        out.write(run, 0, &bytes)?;
        bytes.clear();
        foxglove::lab_scene(start, 0, &mut bytes);
        out.write(lab, 0, &bytes)?;
        // The run start gets a chunk of its own, on disk before the first tick: a hub killed
        // at any later moment leaves a file that still says what the run was.
        out.close_chunk()?;
        Ok(out)
    }

    /// Writes one message, closing the chunk first when it would grow too large or span too
    /// long. A closed chunk is flushed to the file, so a killed process loses at most the chunk
    /// in progress (and what is still queued).
    fn write(&mut self, channel: u16, t_ns: u64, data: &[u8]) -> Result<(), mcap::McapError> {
        let size = MESSAGE_OVERHEAD + data.len() as u64;
        if let Some((bytes, since)) = self.chunk
            && (bytes + size > self.chunk_bytes || t_ns.saturating_sub(since) >= self.chunk_sim_ns)
        {
            self.close_chunk()?;
        }
        let slot = usize::from(channel);
        let sequence = self.sequences.get(slot).copied().unwrap_or(0);
        if let Some(s) = self.sequences.get_mut(slot) {
            *s = s.wrapping_add(1);
        }
        self.mcap.write_to_known_channel(
            &MessageHeader { channel_id: channel, sequence, log_time: t_ns, publish_time: t_ns },
            data,
        )?;
        self.totals.messages += 1;
        let (bytes, since) = self.chunk.unwrap_or((0, t_ns));
        self.chunk = Some((bytes + size, since));
        Ok(())
    }

    fn close_chunk(&mut self) -> Result<(), mcap::McapError> {
        if self.chunk.take().is_some() {
            self.mcap.flush()?;
            self.totals.chunks += 1;
        }
        Ok(())
    }

    fn run(
        mut self,
        inbox: Receiver<Job>,
        bytes_back: SyncSender<Vec<u8>>,
        frames_back: SyncSender<Frame>,
    ) -> Result<WriterTotals, mcap::McapError> {
        let Channels { events, robots, tf, proximity } = self.channels;
        // Returns to here when the recorder closes the queue (finish or drop).
        while let Ok(job) = inbox.recv() {
            match job {
                Job::Event { t_ns, bytes } => {
                    self.write(events, t_ns, &bytes)?;
                    self.totals.events += 1;
                    let _ = bytes_back.try_send(bytes);
                }
                Job::World(frame) => {
                    let t_ns = frame.t_ns;
                    let mut buf = std::mem::take(&mut self.buf);
                    buf.clear();
                    foxglove::robots_scene(&frame.states, &frame.sensors, t_ns, &mut buf, &mut self.id, &mut self.name);
                    self.write(robots, t_ns, &buf)?;
                    buf.clear();
                    foxglove::transforms(&frame.states, &frame.sensors, t_ns, &mut buf, &mut self.name);
                    self.write(tf, t_ns, &buf)?;
                    buf.clear();
                    foxglove::proximity_scene(&frame.states, &frame.sensors, t_ns, &mut buf, &mut self.id);
                    self.write(proximity, t_ns, &buf)?;
                    self.buf = buf;
                    self.totals.world_frames += 1;
                    let _ = frames_back.try_send(frame);
                }
                Job::Metadata(m) => {
                    self.close_chunk()?;
                    self.mcap.write_metadata(&m)?;
                }
            }
        }
        self.close_chunk()?;
        self.mcap.finish()?;
        let file = self.mcap.into_inner();
        let file = file.into_inner().map_err(|e| mcap::McapError::Io(e.into_error()))?;
        file.sync_all()?;
        self.totals.bytes = file.metadata()?.len();
        Ok(self.totals)
    }
}
