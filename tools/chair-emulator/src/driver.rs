//! The emulator's I/O: the port (a pseudo-terminal or a serial device), byte pacing at the
//! line's baud rate, the clock, the ground-truth log, and the loop that ties them to the
//! [`Board`].

use std::collections::VecDeque;
use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Read as _, Write as _};
use std::os::fd::OwnedFd;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use sim_model::PoseDeg;

use crate::board::{Board, BoardBuildError, BoardConfig, BoardCounters, EventKind, Outbox};
use crate::room::{Room, RoomBuildError};
use crate::sys;

/// The longest the loop sleeps, so a stop request is seen within this.
const MAX_WAIT: Duration = Duration::from_millis(50);
/// The shortest wake-up for paced output: bytes go out in small bursts rather than one system
/// call per byte, never earlier than the line would have carried them.
const MIN_TX_WAKE_NS: u64 = 200_000;

/// Where the emulator talks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortChoice {
    /// A new pseudo-terminal pair; hosts open its slave path.
    Pty,
    /// An existing serial device (a USB adapter looped to the host's), opened raw at the baud
    /// rate.
    Device(PathBuf),
}

/// Everything an emulator is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// The room.
    pub room: Room,
    /// The board and its chair.
    pub board: BoardConfig,
    /// The port.
    pub port: PortChoice,
    /// A symlink to make to the pseudo-terminal's slave (replaced if it exists, removed on exit).
    pub link: Option<PathBuf>,
    /// The line's baud rate: every byte written takes 10 bits' time (8N1); 0 = no pacing.
    pub baud: u32,
    /// Where to write the ground-truth log (JSON lines).
    pub truth: Option<PathBuf>,
}

impl EmulatorConfig {
    /// The chair at its default pose on the LIACC floor, on a pseudo-terminal at 115200 baud.
    pub fn new(room: Room, board: BoardConfig) -> Self {
        Self { room, board, port: PortChoice::Pty, link: None, baud: 115_200, truth: None }
    }
}

impl From<RoomBuildError> for EmulatorError {
    fn from(e: RoomBuildError) -> Self {
        EmulatorError::Room(Box::new(e))
    }
}

/// Why the emulator could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    /// The fault-injection signal handlers could not be installed.
    #[error("cannot install the SIGUSR1/SIGUSR2 handlers: {0}")]
    Signals(io::Error),
    /// The room could not be put together (boxed: it is large, and errors are rare).
    #[error(transparent)]
    Room(Box<RoomBuildError>),
    /// The board or chair could not be built.
    #[error(transparent)]
    Board(#[from] BoardBuildError),
    /// No pseudo-terminal could be opened.
    #[error("cannot open a pseudo-terminal: {0}")]
    Pty(#[source] io::Error),
    /// The serial device could not be opened or configured.
    #[error("cannot open serial port {}: {source}", path.display())]
    OpenPort {
        /// The device.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// Reading or writing the port failed (a device unplugged).
    #[error("serial port {} failed: {source}", path.display())]
    Port {
        /// The port.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// The link to the pseudo-terminal could not be made.
    #[error("cannot link {} to the pseudo-terminal: {source}", path.display())]
    Link {
        /// The link's path.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// The ground-truth log could not be written.
    #[error("cannot write the truth log {}: {source}", path.display())]
    Truth {
        /// The log's path.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// `--link` needs a pseudo-terminal.
    #[error("--link makes a link to a pseudo-terminal; it cannot be used with --port")]
    LinkWithDevice,
    /// The emulator's thread panicked (a bug).
    #[error("the emulator's thread panicked")]
    Panicked,
}

/// How a run ended: what came in, what went out, and where the chair truly is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// What the board counted (frames by kind, refused chunks by reason).
    pub counters: BoardCounters,
    /// Contacts with the room.
    pub contacts: u64,
    /// The chair's true pose at the end: x, y (metres), heading (degrees).
    pub pose: PoseDeg,
    /// The board's clock at the end, ms.
    pub board_ms: f64,
    /// Bytes put on the line.
    pub bytes_sent: u64,
    /// Bytes the line could not take (the port's buffer full: nobody reading).
    pub bytes_lost: u64,
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counters;
        let d = &c.decoder;
        write!(
            f,
            "chair-emulator: frames ok {} (hello {}, motors {}, heartbeat {}, estop {}, simstep {}); \
             dropped {} (crc {}, malformed {}, oversize {}, bad version {}, unknown type {}, bad length {}, \
             invalid field {}); ignored (latched {}, simstep {}, wrong direction {}); sent {} frames, {} bytes \
             ({} lost); contacts {}; true pose {:.3} {:.3} {:.1}°; board {:.0} ms",
            d.frames,
            c.hellos,
            c.motor_commands + c.ignored_latched,
            c.heartbeats,
            c.emergency_stops,
            c.sim_steps + c.ignored_sim_steps,
            d.errors(),
            d.crc_errors,
            d.malformed,
            d.oversize,
            d.bad_version,
            d.unknown_type,
            d.bad_length,
            d.invalid_field,
            c.ignored_latched,
            c.ignored_sim_steps,
            c.wrong_direction,
            c.frames_sent,
            self.bytes_sent,
            self.bytes_lost,
            self.contacts,
            self.pose[0],
            self.pose[1],
            self.pose[2],
            self.board_ms,
        )
    }
}

/// The emulator's end of the line.
#[derive(Debug)]
struct Port {
    file: File,
    /// The pseudo-terminal's slave, held open (see [`sys::PtyPair::slave`]).
    slave: Option<OwnedFd>,
    path: PathBuf,
}

impl Port {
    fn open(choice: &PortChoice, baud: u32) -> Result<Port, EmulatorError> {
        match choice {
            PortChoice::Pty => {
                let pair = sys::open_pty().map_err(EmulatorError::Pty)?;
                Ok(Port { file: pair.master, slave: Some(pair.slave), path: pair.path })
            }
            PortChoice::Device(path) => {
                let err = |source| EmulatorError::OpenPort { path: path.clone(), source };
                let file = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC)
                    .open(path)
                    .map_err(err)?;
                // Baud 0 means "do not pace"; the device then keeps its own speed.
                sys::make_raw(&file, (baud > 0).then_some(baud)).map_err(err)?;
                Ok(Port { file, slave: None, path: path.clone() })
            }
        }
    }
}

/// A symlink to the pseudo-terminal, removed when dropped if it still points there.
#[derive(Debug)]
struct Link {
    path: PathBuf,
    target: PathBuf,
}

impl Link {
    /// Makes `path` → `target`, replacing whatever is at `path` in one step (a temporary link
    /// renamed over it), so a host reopening the path never finds it missing.
    fn make(path: &Path, target: &Path) -> io::Result<Link> {
        let name = path.file_name().ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
        let mut tmp_name = name.to_os_string();
        tmp_name.push(format!(".tmp{}", std::process::id()));
        let tmp = path.with_file_name(tmp_name);
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(target, &tmp)?;
        if let Err(e) = std::fs::rename(&tmp, path) {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        Ok(Link { path: path.to_owned(), target: target.to_owned() })
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        // Another emulator may have taken the path over since; its link is left alone.
        if std::fs::read_link(&self.path).is_ok_and(|t| t == self.target) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Bytes waiting for the line, each leaving no earlier than a real line at the baud rate
/// would have finished sending it.
#[derive(Debug)]
struct Tx {
    queue: VecDeque<u8>,
    /// Nanoseconds per byte (10 bits, 8N1); 0: no pacing.
    byte_ns: u64,
    /// When the line finishes the front byte of the queue.
    next_due_ns: u64,
    /// When the line finished (or will finish) the last byte it took.
    line_free_ns: u64,
    sent: u64,
    lost: u64,
}

impl Tx {
    fn new(baud: u32) -> Tx {
        let byte_ns = if baud == 0 { 0 } else { 10 * 1_000_000_000 / u64::from(baud) };
        Tx { queue: VecDeque::new(), byte_ns, next_due_ns: 0, line_free_ns: 0, sent: 0, lost: 0 }
    }

    fn push(&mut self, bytes: &[u8], now_ns: u64) {
        if bytes.is_empty() {
            return;
        }
        if self.queue.is_empty() {
            self.next_due_ns = now_ns.max(self.line_free_ns) + self.byte_ns;
        }
        self.queue.extend(bytes);
    }

    /// Forgets what has not gone out yet (a new session: it is stale).
    fn discard(&mut self) {
        self.queue.clear();
    }

    fn next_due_ns(&self) -> Option<u64> {
        (!self.queue.is_empty()).then_some(self.next_due_ns)
    }

    /// Writes every byte whose time has come. A line does not wait for its receiver: bytes
    /// the port cannot take (its buffer full, nobody reading) are lost, and counted.
    fn write_due(&mut self, now_ns: u64, port: &mut File) -> io::Result<()> {
        let due = if self.byte_ns == 0 {
            self.queue.len()
        } else if self.next_due_ns > now_ns {
            0
        } else {
            (1 + (now_ns - self.next_due_ns) / self.byte_ns).min(self.queue.len() as u64) as usize
        };
        if due == 0 {
            return Ok(());
        }
        let bytes: Vec<u8> = self.queue.drain(..due).collect();
        let written = match port.write(&bytes) {
            Ok(n) => n,
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted) => 0,
            Err(e) => return Err(e),
        };
        self.sent += written as u64;
        self.lost += (due - written) as u64;
        let due = due as u64;
        self.line_free_ns = self.next_due_ns + (due - 1) * self.byte_ns;
        self.next_due_ns += due * self.byte_ns;
        Ok(())
    }
}

/// The ground-truth log: one JSON object per line, flushed per line so a test can read it live.
#[derive(Debug)]
struct TruthLog {
    out: BufWriter<File>,
    path: PathBuf,
}

impl TruthLog {
    fn create(path: &Path) -> Result<TruthLog, EmulatorError> {
        let file = File::create(path).map_err(|source| EmulatorError::Truth { path: path.to_owned(), source })?;
        Ok(TruthLog { out: BufWriter::new(file), path: path.to_owned() })
    }

    fn write(&mut self, t_ns: u64, board_us: u64, kind: &EventKind) -> Result<(), EmulatorError> {
        let board_ms = board_us as f64 / 1000.0;
        let line = match kind {
            EventKind::Step { pose, cmd, contacts } => serde_json::json!({
                "t_ns": t_ns, "board_ms": board_ms, "x": pose.x, "y": pose.y,
                "heading_deg": pose.heading_deg(), "cmd": cmd, "contacts": contacts,
            }),
            EventKind::MotorsZero(reason) => {
                serde_json::json!({"t_ns": t_ns, "board_ms": board_ms, "event": "motors_zero", "reason": reason.name()})
            }
            EventKind::FrameDropped(reason) => {
                serde_json::json!({"t_ns": t_ns, "board_ms": board_ms, "event": "frame_dropped", "reason": reason})
            }
            EventKind::Hello { period_ms } => {
                serde_json::json!({"t_ns": t_ns, "board_ms": board_ms, "event": "hello", "period_ms": period_ms})
            }
            EventKind::EmergencyStop { reason } => {
                serde_json::json!({"t_ns": t_ns, "board_ms": board_ms, "event": "estop", "reason": reason})
            }
        };
        self.line(&line)
    }

    fn line(&mut self, line: &serde_json::Value) -> Result<(), EmulatorError> {
        let err = |source| EmulatorError::Truth { path: self.path.clone(), source };
        writeln!(self.out, "{line}").map_err(err)?;
        self.out.flush().map_err(|source| EmulatorError::Truth { path: self.path.clone(), source })
    }
}

/// An emulator, built and with its port open, not yet running.
#[derive(Debug)]
pub struct Emulator {
    board: Board,
    port: Port,
    tx: Tx,
    truth: Option<TruthLog>,
    /// Dropped after the loop, which removes the link.
    link: Option<Link>,
    /// CLOCK_MONOTONIC at power-up (board time 0), ns.
    origin_ns: u64,
    /// Test-bench faults by signal, when the command line asked for them.
    faults: Option<&'static sys::FaultSignals>,
    /// How many of each fault signal were handled: (mute toggles, bursts).
    faults_handled: (u32, u32),
    /// The transmit line is cut (SIGUSR1): the board still receives, acts and logs, but
    /// nothing it sends reaches the host.
    muted: bool,
}

impl Emulator {
    /// Builds the board, opens the port, makes the link and creates the truth log.
    pub fn new(cfg: EmulatorConfig) -> Result<Emulator, EmulatorError> {
        if cfg.link.is_some() && cfg.port != PortChoice::Pty {
            return Err(EmulatorError::LinkWithDevice);
        }
        let board = Board::new(&cfg.board, &cfg.room)?;
        let port = Port::open(&cfg.port, cfg.baud)?;
        let link = match &cfg.link {
            Some(path) => Some(
                Link::make(path, &port.path).map_err(|source| EmulatorError::Link { path: path.clone(), source })?,
            ),
            None => None,
        };
        let truth = cfg.truth.as_deref().map(TruthLog::create).transpose()?;
        Ok(Emulator {
            board,
            port,
            tx: Tx::new(cfg.baud),
            truth,
            link,
            origin_ns: sys::monotonic_ns(),
            faults: None,
            faults_handled: (0, 0),
            muted: false,
        })
    }

    /// Lets SIGUSR1 and SIGUSR2 inject the faults a test bench needs: SIGUSR1 cuts (or mends)
    /// the transmit line — the board keeps receiving, acting and logging, but the host hears
    /// nothing, as with a broken TX wire; SIGUSR2 sends one burst of garbage, a frame with a
    /// bad CRC, a truncated frame, a frame of an unknown type and one with a bad length. Both
    /// are noted in the truth log (`tx_mute`, `garbage_burst`).
    pub fn with_fault_signals(mut self) -> Result<Emulator, EmulatorError> {
        sys::install_fault_signals().map_err(EmulatorError::Signals)?;
        let faults = &sys::FAULTS;
        self.faults_handled = (faults.mute_toggles.load(Ordering::SeqCst), faults.bursts.load(Ordering::SeqCst));
        self.faults = Some(faults);
        Ok(self)
    }

    /// Applies the fault signals that arrived since the last look.
    fn apply_faults(&mut self, now_ns: u64) -> Result<(), EmulatorError> {
        let Some(faults) = self.faults else { return Ok(()) };
        let toggles = faults.mute_toggles.load(Ordering::SeqCst);
        while self.faults_handled.0 != toggles {
            self.faults_handled.0 = self.faults_handled.0.wrapping_add(1);
            self.muted = !self.muted;
            if self.muted {
                // What was on its way is lost with the wire.
                self.tx.discard();
            }
            let board_ms = self.board_us(now_ns) as f64 / 1000.0;
            self.note(serde_json::json!({"t_ns": now_ns, "board_ms": board_ms, "event": "tx_mute", "on": self.muted}))?;
        }
        let bursts = faults.bursts.load(Ordering::SeqCst);
        while self.faults_handled.1 != bursts {
            self.faults_handled.1 = self.faults_handled.1.wrapping_add(1);
            let junk = garbage(self.faults_handled.1);
            if !self.muted {
                self.tx.push(&junk, now_ns);
            }
            let board_ms = self.board_us(now_ns) as f64 / 1000.0;
            self.note(
                serde_json::json!({"t_ns": now_ns, "board_ms": board_ms, "event": "garbage_burst", "bytes": junk.len()}),
            )?;
        }
        Ok(())
    }

    fn note(&mut self, line: serde_json::Value) -> Result<(), EmulatorError> {
        match &mut self.truth {
            Some(log) => log.line(&line),
            None => Ok(()),
        }
    }

    /// The path a host opens: the pseudo-terminal's slave, or the device.
    pub fn path(&self) -> &Path {
        &self.port.path
    }

    /// Runs until `stop` is set or the port fails, then removes the link.
    pub fn run(mut self, stop: &AtomicBool) -> Result<Outcome, EmulatorError> {
        self.origin_ns = sys::monotonic_ns();
        let result = self.run_loop(stop);
        drop(self.link.take());
        result.map(|()| self.outcome())
    }

    /// Runs on a thread of its own; the handle stops it.
    pub fn spawn(self) -> EmulatorHandle {
        let path = self.path().to_owned();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let join = std::thread::spawn(move || self.run(&flag));
        EmulatorHandle { path, stop, join: Some(join) }
    }

    fn board_us(&self, now_ns: u64) -> u64 {
        now_ns.saturating_sub(self.origin_ns) / 1000
    }

    fn run_loop(&mut self, stop: &AtomicBool) -> Result<(), EmulatorError> {
        let mut buf = [0u8; 1024];
        let mut out = Outbox::default();
        let stepped = self.board.stepped();
        while !stop.load(Ordering::Relaxed) {
            let now = sys::monotonic_ns();
            self.apply_faults(now)?;
            if !stepped {
                self.board.advance_to(self.board_us(now), &mut out);
                self.drain(&mut out, now)?;
            }
            self.tx.write_due(now, &mut self.port.file).map_err(|e| self.port_error(e))?;
            let mut wait_ns = MAX_WAIT.as_nanos() as u64;
            if !stepped {
                let due = self.origin_ns + self.board.next_event_us() * 1000;
                wait_ns = wait_ns.min(due.saturating_sub(now));
            }
            if let Some(due) = self.tx.next_due_ns() {
                wait_ns = wait_ns.min(due.saturating_sub(now).max(MIN_TX_WAKE_NS));
            }
            if !sys::wait_readable(&self.port.file, Duration::from_nanos(wait_ns)).map_err(|e| self.port_error(e))? {
                continue;
            }
            let n = match self.port.file.read(&mut buf) {
                Ok(0) => {
                    let e = io::Error::new(io::ErrorKind::UnexpectedEof, "the port was closed");
                    return Err(self.port_error(e));
                }
                Ok(n) => n,
                Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted) => continue,
                Err(e) => return Err(self.port_error(e)),
            };
            let now = sys::monotonic_ns();
            if !stepped {
                // Everything due before the bytes arrived happens first.
                self.board.advance_to(self.board_us(now), &mut out);
            }
            self.board.receive(&buf[..n], &mut out);
            self.drain(&mut out, now)?;
        }
        Ok(())
    }

    fn port_error(&self, source: io::Error) -> EmulatorError {
        EmulatorError::Port { path: self.port.path.clone(), source }
    }

    /// Moves the board's output to the line and the truth log.
    fn drain(&mut self, out: &mut Outbox, now_ns: u64) -> Result<(), EmulatorError> {
        let mut wire = &out.wire[..];
        if let Some(k) = out.flush_before {
            // A Hello: whatever the host has not read from before it is stale (see Outbox).
            self.tx.discard();
            if let Some(slave) = &self.port.slave {
                // A pseudo-terminal keeps bytes for a host that is not there; a line does not.
                sys::flush_input(slave).map_err(|e| self.port_error(e))?;
            }
            wire = wire.get(k..).unwrap_or_default();
        }
        if !self.muted {
            self.tx.push(wire, now_ns);
        }
        if let Some(log) = &mut self.truth {
            for e in &out.events {
                // In real time the board's clock is the monotonic clock shifted; in stepped mode
                // the board's clock is its own, and the log gets the moment it was written.
                let t_ns = if self.board.stepped() { now_ns } else { self.origin_ns + e.board_us * 1000 };
                log.write(t_ns, e.board_us, &e.kind)?;
            }
        }
        out.clear();
        Ok(())
    }

    fn outcome(&self) -> Outcome {
        let pose = self.board.pose();
        Outcome {
            counters: self.board.counters(),
            contacts: self.board.contacts(),
            pose: [pose.x, pose.y, pose.heading_deg()],
            board_ms: self.board.now_us() as f64 / 1000.0,
            bytes_sent: self.tx.sent,
            bytes_lost: self.tx.lost,
        }
    }
}

/// An emulator running on its own thread. Dropping the handle stops it.
#[derive(Debug)]
pub struct EmulatorHandle {
    /// The path a host opens.
    pub path: PathBuf,
    stop: Arc<AtomicBool>,
    join: Option<JoinHandle<Result<Outcome, EmulatorError>>>,
}

impl EmulatorHandle {
    /// Stops the emulator and waits for it (at most about 50 ms), giving how the run ended.
    pub fn stop(mut self) -> Result<Outcome, EmulatorError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.join.take() {
            Some(join) => join.join().map_err(|_| EmulatorError::Panicked)?,
            None => Err(EmulatorError::Panicked),
        }
    }

    /// Whether the emulator has ended on its own (its port failed).
    pub fn is_finished(&self) -> bool {
        self.join.as_ref().is_none_or(JoinHandle::is_finished)
    }
}

impl Drop for EmulatorHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(join) = self.join.take() {
            let _ = join.join();
        }
    }
}

/// Starts an emulator on a new pseudo-terminal, on a thread of its own (whatever `cfg.port`
/// says).
pub fn spawn_on_pty(cfg: EmulatorConfig) -> Result<EmulatorHandle, EmulatorError> {
    Ok(Emulator::new(EmulatorConfig { port: PortChoice::Pty, ..cfg })?.spawn())
}

/// Burst number `n` of junk toward the host: stray bytes, then a frame whose CRC does not
/// match, a frame cut short, a frame of a type nobody knows and one whose payload is too long
/// for its type. A host must count every piece and act on none.
fn garbage(n: u32) -> Vec<u8> {
    use serial_protocol::{Message, StopAck, StopReason};
    let mut out = Vec::with_capacity(256);
    // Stray bytes from a simple xorshift (zeros included: they end "frames" of junk).
    let mut x = 0x9E37_79B9u32 ^ n.wrapping_mul(0x85EB_CA6B);
    for _ in 0..48 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        out.push(x as u8);
    }
    let mut wire = [0u8; serial_protocol::MAX_ENCODED_LEN];
    let ack = Message::StopAck(StopAck { stop_seq: 0, reason: StopReason(0) });
    if let Ok(len) = serial_protocol::encode(&ack, 0xEE, &mut wire) {
        // The CRC no longer matches: one payload bit flipped inside the COBS body.
        let mut bad = wire[..len].to_vec();
        if let Some(b) = bad.get_mut(len / 2) {
            *b ^= 0x04;
            if *b == 0 {
                *b = 0x04;
            }
        }
        out.extend_from_slice(&bad);
        // Cut short: the next frame's leading delimiter ends it.
        out.extend_from_slice(&wire[..len - 3]);
    }
    // Well-formed frames that must still be refused: an unknown type, and a StopAck with a
    // payload longer than its type's.
    for raw in [
        vec![serial_protocol::VERSION, 0x7F, 0xEF, 1, 2, 3],
        vec![serial_protocol::VERSION, 0x84, 0xF0, 1, 2, 3, 4, 5, 6],
    ] {
        if let Ok(n) = serial_protocol::encode_raw(&raw, &mut wire) {
            out.extend_from_slice(&wire[..n]);
        }
    }
    out
}
