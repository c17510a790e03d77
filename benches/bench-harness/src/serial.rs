//! `iwsim bench serial`: the RS232 link to a chair's board, measured against the chair
//! emulator on a real pseudo-terminal at a real baud rate (the emulator paces every byte it
//! sends at 10 bits a byte; this host paces its own commands the same way).
//!
//! Two figures, each the median of `--runs` runs with min and max:
//! - **round trip**: a MotorPowers command leaves the host → the board applies it → the first
//!   Sample that says so (`last_motor_seq`) is back at the host. Commands are sent at phases
//!   spread over the board's sample period, so the figure includes the wait for the next
//!   sample, as a controller that is not synchronised with its board sees it.
//! - **the link's limit**: the bytes of one control cycle with a full frame (8 sonar + 8 IR
//!   readings and the encoders, board → host; a MotorPowers, host → board) against the line's
//!   11,520 bytes/s at 115200 baud, as the highest control rate the link sustains; checked by
//!   running the emulator at its fastest sample period (20 ms) and counting what arrives.

use std::fs::{File, OpenOptions};
use std::io::{Read as _, Write as _};
use std::process::ExitCode;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use chair_emulator::{BoardConfig, EmulatorConfig, Imperfections, Room};
use serial_protocol::{
    Decoder, Frame, Hello, MAX_ENCODED_LEN, MAX_SENSORS, Message, MotorPowers, Reading, Readings, Sample, encode,
};

use crate::args::BenchSerialArgs;
use crate::repeat::Spread;

/// The sample period of the round-trip runs, ms: the protocol's default.
const PERIOD_MS: u16 = 100;
/// The fastest sample period the emulator (and the protocol's recommendation) allows, ms.
const FAST_PERIOD_MS: u16 = 20;

/// What arrived from the board, with when.
struct Arrival {
    at: Instant,
    frame: Frame,
}

/// The host's end of the link: the pty opened as a serial port is, a reader thread decoding
/// what the board sends, and byte pacing on what the host sends.
struct Host {
    port: File,
    frames: Receiver<Arrival>,
    seq: u8,
    byte_time: Duration,
    bytes_in: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl Host {
    fn open(path: &std::path::Path, baud: u32) -> anyhow::Result<Host> {
        let port = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .with_context(|| format!("opening the emulator's port {}", path.display()))?;
        let mut reader = port.try_clone().context("a second handle on the port")?;
        let (tx, frames) = std::sync::mpsc::channel();
        let bytes_in = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        let counter = std::sync::Arc::clone(&bytes_in);
        std::thread::spawn(move || {
            let mut decoder = Decoder::new();
            let mut buf = [0u8; 512];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let at = Instant::now();
                counter.fetch_add(n as u64, std::sync::atomic::Ordering::Relaxed);
                for &b in &buf[..n] {
                    if let Some(Ok(frame)) = decoder.push(b)
                        && tx.send(Arrival { at, frame }).is_err()
                    {
                        return;
                    }
                }
            }
        });
        let byte_time = if baud == 0 { Duration::ZERO } else { Duration::from_nanos(10_000_000_000 / u64::from(baud)) };
        Ok(Host { port, frames, seq: 0, byte_time, bytes_in })
    }

    /// Sends `m` as a UART would: its last byte reaches the board `len × 10 bits` after the
    /// first leaves, so the bytes are written once that time has passed. Returns when the
    /// first byte left.
    fn send(&mut self, m: &Message) -> anyhow::Result<Instant> {
        let mut wire = [0u8; MAX_ENCODED_LEN];
        let n = encode(m, self.seq, &mut wire).map_err(|e| anyhow::anyhow!("encoding {m:?}: {e:?}"))?;
        self.seq = self.seq.wrapping_add(1);
        let start = Instant::now();
        let arrive = start + self.byte_time * n as u32;
        while Instant::now() < arrive {
            std::hint::spin_loop();
        }
        self.port.write_all(&wire[..n]).context("writing to the emulator's port")?;
        Ok(start)
    }

    /// The next frame `pick` accepts, within `timeout`.
    fn wait_for(&mut self, timeout: Duration, pick: impl Fn(&Message) -> bool) -> anyhow::Result<Arrival> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.frames.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(a) if pick(&a.frame.message) => return Ok(a),
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => anyhow::bail!("the board did not answer within {timeout:?}"),
                Err(RecvTimeoutError::Disconnected) => anyhow::bail!("the emulator's port closed"),
            }
        }
    }

    fn hello(&mut self, period_ms: u16) -> anyhow::Result<()> {
        self.send(&Message::Hello(Hello { sample_period_ms: period_ms }))?;
        self.wait_for(Duration::from_secs(2), |m| matches!(m, Message::BoardInfo(_)))?;
        Ok(())
    }
}

fn emulator(baud: u32) -> anyhow::Result<chair_emulator::EmulatorHandle> {
    let room = Room::load("builtin:liacc", Vec::new()).map_err(|e| anyhow::anyhow!("{e}"))?;
    // An ideal chair sending every reading in every sample: the frames a full board sends.
    let board = BoardConfig { imperfections: Imperfections::NONE, full_frames: true, ..BoardConfig::default() };
    let cfg = EmulatorConfig { baud, ..EmulatorConfig::new(room, board) };
    chair_emulator::spawn_on_pty(cfg).map_err(|e| anyhow::anyhow!("starting the chair emulator: {e}"))
}

/// One round-trip run: `commands` MotorPowers at phases spread over the sample period; returns
/// (p50, p99) in ms.
fn round_trip_run(baud: u32, commands: usize) -> anyhow::Result<(f64, f64)> {
    let emu = emulator(baud)?;
    let mut host = Host::open(&emu.path, baud)?;
    host.hello(PERIOD_MS)?;
    let mut rtt = Vec::with_capacity(commands);
    for i in 0..commands {
        // Standing still (zero powers) keeps the chair off the walls; the board applies and
        // acknowledges a zero command like any other.
        let seq = host.seq;
        let sent = host.send(&Message::MotorPowers(MotorPowers { left_permille: 0, right_permille: 0 }))?;
        let back =
            host.wait_for(Duration::from_secs(2), |m| matches!(m, Message::Sample(s) if s.last_motor_seq == seq))?;
        rtt.push((back.at - sent).as_secs_f64() * 1e3);
        // The next command at another phase of the period: 37 ms steps cover it evenly.
        let phase = Duration::from_millis((i as u64 * 37) % u64::from(PERIOD_MS));
        std::thread::sleep(phase);
    }
    drop(host);
    emu.stop().map_err(|e| anyhow::anyhow!("the chair emulator: {e}"))?;
    rtt.sort_unstable_by(f64::total_cmp);
    let q = |p: f64| rtt[((rtt.len() - 1) as f64 * p).round() as usize];
    Ok((q(0.5), q(0.99)))
}

/// One run at the fastest period: commands at every sample, for `seconds`; returns (samples
/// per second, bytes per second) received.
fn fast_run(baud: u32, seconds: f64) -> anyhow::Result<(f64, f64)> {
    let emu = emulator(baud)?;
    let mut host = Host::open(&emu.path, baud)?;
    host.hello(FAST_PERIOD_MS)?;
    let first = host.wait_for(Duration::from_secs(2), |m| matches!(m, Message::Sample(_)))?;
    let bytes0 = host.bytes_in.load(std::sync::atomic::Ordering::Relaxed);
    let mut samples = 0u64;
    let mut last = first.at;
    let end = first.at + Duration::from_secs_f64(seconds);
    while last < end {
        host.send(&Message::MotorPowers(MotorPowers { left_permille: 0, right_permille: 0 }))?;
        last = host.wait_for(Duration::from_secs(2), |m| matches!(m, Message::Sample(_)))?.at;
        samples += 1;
    }
    let bytes = host.bytes_in.load(std::sync::atomic::Ordering::Relaxed) - bytes0;
    let elapsed = (last - first.at).as_secs_f64();
    drop(host);
    emu.stop().map_err(|e| anyhow::anyhow!("the chair emulator: {e}"))?;
    Ok((samples as f64 / elapsed, bytes as f64 / elapsed))
}

/// Encoded sizes of one control cycle with a full board: (Sample with 8 sonar + 8 IR, the
/// MotorPowers command).
fn full_cycle_bytes() -> anyhow::Result<(usize, usize)> {
    let mut sonar = Readings::new();
    let mut ir = Readings::new();
    for id in 0..MAX_SENSORS as u8 {
        // Ranges without zero bytes are the worst case for COBS's overhead only when long; any
        // value gives the same length here (frames are under 254 bytes).
        let _ = sonar.push(Reading { id, range_mm: 1234 });
        let _ = ir.push(Reading { id, range_mm: 567 });
    }
    let sample = Message::Sample(Sample { sonar, ir, ..Sample::default() });
    let mut wire = [0u8; MAX_ENCODED_LEN];
    let n_sample = encode(&sample, 0, &mut wire).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let cmd = Message::MotorPowers(MotorPowers { left_permille: 500, right_permille: 500 });
    let n_cmd = encode(&cmd, 0, &mut wire).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok((n_sample, n_cmd))
}

/// What `iwsim bench serial` measured.
#[derive(Debug, Clone)]
pub struct SerialReport {
    /// Baud rate.
    pub baud: u32,
    /// Runs per figure.
    pub runs: usize,
    /// Commands per round-trip run.
    pub commands: usize,
    /// Round trip p50 (ms) over the runs.
    pub rtt_p50_ms: Spread,
    /// Round trip p99 (ms) over the runs.
    pub rtt_p99_ms: Spread,
    /// Bytes of a full Sample (8 sonar + 8 IR + encoders) and of a MotorPowers, on the wire.
    pub full_sample_bytes: usize,
    /// Bytes of a MotorPowers on the wire.
    pub command_bytes: usize,
    /// The highest control rate the line carries with full samples, Hz.
    pub max_rate_hz: f64,
    /// Samples per second received at the emulator's fastest period (20 ms).
    pub fast_samples_per_s: Spread,
    /// Bytes per second received then.
    pub fast_bytes_per_s: Spread,
}

impl std::fmt::Display for SerialReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = |x: &Spread| format!("{:.1} (min {:.1}, max {:.1})", x.median, x.min, x.max);
        writeln!(
            f,
            "serial link to the chair emulator over a pseudo-terminal at {} baud (8N1: {} bytes/s), medians of {} runs",
            self.baud,
            self.baud / 10,
            self.runs
        )?;
        writeln!(
            f,
            "  round trip, command → board → Sample that applied it, {} commands a run at spread phases of the {} ms sample period:",
            self.commands, PERIOD_MS
        )?;
        writeln!(f, "    p50 {} ms", s(&self.rtt_p50_ms))?;
        writeln!(f, "    p99 {} ms", s(&self.rtt_p99_ms))?;
        writeln!(
            f,
            "  a full Sample (8 sonar + 8 IR + encoders) is {} bytes on the wire, a MotorPowers {} bytes:",
            self.full_sample_bytes, self.command_bytes
        )?;
        writeln!(
            f,
            "    the link carries at most {:.0} control cycles a second ({:.1} ms each), {:.1}× the hub's 100 ms tick",
            self.max_rate_hz,
            1000.0 / self.max_rate_hz,
            self.max_rate_hz / 10.0
        )?;
        writeln!(
            f,
            "  at the emulator's fastest period ({FAST_PERIOD_MS} ms, every reading in every sample, plus its SimTruth): {} samples/s, {} bytes/s",
            s(&self.fast_samples_per_s),
            s(&self.fast_bytes_per_s)
        )
    }
}

/// Runs the benchmark.
pub fn measure(args: &BenchSerialArgs) -> anyhow::Result<SerialReport> {
    let (full_sample_bytes, command_bytes) = full_cycle_bytes()?;
    let mut p50 = Vec::new();
    let mut p99 = Vec::new();
    let mut rate = Vec::new();
    let mut bytes = Vec::new();
    for _ in 0..args.runs {
        let (a, b) = round_trip_run(args.baud, args.commands)?;
        p50.push(a);
        p99.push(b);
        let (r, by) = fast_run(args.baud, args.seconds)?;
        rate.push(r);
        bytes.push(by);
    }
    let spread = |v: &[f64]| Spread::of(v).context("no runs");
    let line = f64::from(args.baud) / 10.0;
    Ok(SerialReport {
        baud: args.baud,
        runs: args.runs,
        commands: args.commands,
        rtt_p50_ms: spread(&p50)?,
        rtt_p99_ms: spread(&p99)?,
        full_sample_bytes,
        command_bytes,
        max_rate_hz: line / full_sample_bytes.max(command_bytes) as f64,
        fast_samples_per_s: spread(&rate)?,
        fast_bytes_per_s: spread(&bytes)?,
    })
}

/// `iwsim bench serial`.
pub fn run(args: &BenchSerialArgs) -> anyhow::Result<ExitCode> {
    let r = measure(args)?;
    if args.json {
        let s = |x: &Spread| serde_json::json!({"median": x.median, "min": x.min, "max": x.max, "runs": x.runs});
        let out = serde_json::json!({
            "baud": r.baud,
            "commands_per_run": r.commands,
            "sample_period_ms": PERIOD_MS,
            "round_trip_p50_ms": s(&r.rtt_p50_ms),
            "round_trip_p99_ms": s(&r.rtt_p99_ms),
            "full_sample_bytes": r.full_sample_bytes,
            "command_bytes": r.command_bytes,
            "max_control_rate_hz": r.max_rate_hz,
            "fast_period_ms": FAST_PERIOD_MS,
            "fast_samples_per_s": s(&r.fast_samples_per_s),
            "fast_bytes_per_s": s(&r.fast_bytes_per_s),
        });
        println!("{out}");
    } else {
        print!("{r}");
    }
    Ok(ExitCode::SUCCESS)
}
