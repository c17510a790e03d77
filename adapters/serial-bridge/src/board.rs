//! The adapter's side of the serial link, apart from the hub: it keeps the port (reopening it
//! every 500 ms when it goes away), feeds the safety state machine with the board's frames and
//! the clock, writes what it asks for, integrates the odometry and collects the readings. The
//! hub side hands it each tick's sensor block and sends the action block it returns, so a test
//! drives it over a pseudo-terminal with made-up blocks and no hub.

use std::os::fd::RawFd;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use ipc_types::{ACT_GHOST, ACT_LINK_DOWN, ACT_REAL, ActionBlock, SensorBlock};
use serial_protocol::{BoardInfo, DecoderStats, Frame, FrameDecodeError, Hello, Message, SimStep};
use sim_model::{Pose, PoseDeg, chair};

use crate::localise::Localiser;
use crate::odometry::{Step, WheelOdometry};
use crate::port::{self, Port};
use crate::readings::FreshReadings;
use crate::safety::{Output, Safety, StopCause};

/// How often a port that went away is tried again.
pub const REOPEN_EVERY: Duration = Duration::from_millis(500);
/// In stepped mode, how long a tick waits for the sample its step produces before the board
/// counts as silent.
pub const STEP_WAIT: Duration = Duration::from_secs(1);
/// In stepped mode, how long to wait after a step's sample for a SimTruth while the board has
/// not proved to be the emulator (a real board sends none). The emulator sends one after every
/// sample, so once it has sent one the wait is [`STEP_WAIT`]: its frames leave at the line's
/// pace, and a loaded machine can hold its thread between the two for longer than this.
pub const TRUTH_WAIT: Duration = Duration::from_millis(100);
/// The longest the loops here sleep between looks at the port and the timers (the protocol
/// asks for at least every 20 ms).
pub const LOOK_EVERY: Duration = Duration::from_millis(10);

/// How the link is run.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// The port's device path (a pty's slave path works like a real port).
    pub device: PathBuf,
    /// Baud rate.
    pub baud: u32,
    /// The board is a stepped emulator: each tick sends a SimStep of `cycle_ms` and waits for
    /// the sample it produces.
    pub stepped: bool,
    /// The hub's tick period, ms.
    pub cycle_ms: u32,
    /// The hub's encoder units: ticks per metre of wheel travel.
    pub hub_ticks_per_m: f64,
    /// Where the chair starts.
    pub start: Pose,
    /// The chair's name in the hub (for the operator's resume command).
    pub robot: String,
    /// Resume after a stop as soon as every cause has cleared (see [`Safety::with_auto_resume`]).
    pub auto_resume: bool,
}

/// What the adapter did, for its report at exit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Outcome {
    /// Hub ticks answered.
    pub ticks: u64,
    /// Frames from the board: `frames.frames` decoded, the rest dropped by reason (and
    /// `missed`, the gaps in the board's sequence numbers), over every connection.
    pub frames: DecoderStats,
    /// Valid frames of a host → board type that came from the board (an echo, a loopback
    /// cable): never acted on, never taken as a sign of life.
    pub unexpected_frames: u64,
    /// Readings of sensor ids the chair does not have, ignored.
    pub unknown_readings: u64,
    /// Commands not sent because the port's output buffer was full.
    pub writes_dropped: u64,
    /// Each stop: why, and the last hub tick seen when it began.
    pub stops: Vec<(StopCause, u64)>,
    /// Stops lifted (by the operator, or `--auto-resume`).
    pub resumes: u32,
    /// Times the port came back after going away.
    pub reconnects: u32,
}

impl std::fmt::Display for Outcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.frames;
        write!(
            f,
            "{} ticks; {} frames from the board, dropped: {} crc, {} malformed, {} oversize, {} bad version, {} \
             unknown type, {} bad length, {} invalid field ({} missed by sequence number, {} unexpected); {} \
             commands dropped on a full port; {} stops, {} resumed",
            self.ticks,
            s.frames,
            s.crc_errors,
            s.malformed,
            s.oversize,
            s.bad_version,
            s.unknown_type,
            s.bad_length,
            s.invalid_field,
            s.missed,
            self.unexpected_frames,
            self.writes_dropped,
            self.stops.len(),
            self.resumes
        )?;
        for (cause, tick) in &self.stops {
            write!(f, "; at tick {tick}: {cause}")?;
        }
        write!(f, "; {} reconnects", self.reconnects)
    }
}

/// The serial side of the adapter.
#[derive(Debug)]
pub struct BoardLink {
    cfg: LinkConfig,
    start: Instant,
    port: Option<Port>,
    next_open: Duration,
    safety: Safety,
    odometry: WheelOdometry,
    /// Map matching of the odometry pose (see [`Localiser`]); `None` pushes raw odometry.
    localiser: Option<Localiser>,
    fresh: FreshReadings,
    /// The emulator's true pose (its SimTruth) in the wire form the hub takes, x, y metres and
    /// heading degrees, forwarded as the board sent it.
    ghost: Option<PoseDeg>,
    board: Option<BoardInfo>,
    /// Stepped mode: board time stepped since the last sample, ms.
    due_ms: u32,
    /// Stepped mode: when the awaited sample (and its SimTruth) arrived.
    sample_at: Option<Duration>,
    truth_seen: bool,
    /// The decoders' counters of ports already closed.
    closed_stats: DecoderStats,
    outcome: Outcome,
    last_tick: u64,
    shutting_down: bool,
    /// Bad frames so far, for the log's bounded rate.
    bad_frames: u64,
}

impl BoardLink {
    /// Takes over an open port and says Hello to its board.
    pub fn new(cfg: LinkConfig, port: Port) -> BoardLink {
        let hello = Hello { sample_period_ms: if cfg.stepped { hello_period(cfg.cycle_ms) } else { 0 } };
        let safety = Safety::new(Duration::ZERO, cfg.stepped, hello)
            .with_cycle(Duration::from_millis(u64::from(cfg.cycle_ms)))
            .with_auto_resume(cfg.auto_resume);
        let odometry = WheelOdometry::new(cfg.start, chair::BODY[1], chair::WHEEL_RADIUS_M);
        let mut link = BoardLink {
            cfg,
            start: Instant::now(),
            port: None,
            next_open: Duration::ZERO,
            safety,
            odometry,
            localiser: None,
            fresh: FreshReadings::new(),
            ghost: None,
            board: None,
            due_ms: 0,
            sample_at: None,
            truth_seen: false,
            closed_stats: DecoderStats::default(),
            outcome: Outcome::default(),
            last_tick: 0,
            shutting_down: false,
            bad_frames: 0,
        };
        link.attach(port);
        link
    }

    /// Corrects the odometry pose by map matching from now on (see [`Localiser`]).
    pub fn localise(&mut self, localiser: Localiser) {
        self.localiser = Some(localiser);
    }

    /// Time since the link started.
    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    /// The port's descriptor for `poll(2)`, while it is open.
    pub fn fd(&self) -> Option<RawFd> {
        self.port.as_ref().map(Port::fd)
    }

    /// Reads what the board sent, reopens a lost port when due, checks the timers and sends
    /// what they call for. Call it at least every 20 ms; it never waits.
    pub fn service(&mut self) {
        let now = self.now();
        if self.port.is_none() && !self.shutting_down && now >= self.next_open {
            match Port::open(&self.cfg.device, self.cfg.baud) {
                Ok(p) => {
                    self.outcome.reconnects += 1;
                    agent_sdk::report!("iwsim serial: serial port {} is back; saying Hello", self.cfg.device.display());
                    self.attach(p);
                }
                Err(e) => {
                    tracing::debug!("{e}");
                    self.next_open = now + REOPEN_EVERY;
                }
            }
        }
        self.receive();
        let now = self.now();
        self.safety.poll(now);
        self.apply();
    }

    /// Answers hub tick `tick` for robot `robot_id`, whose sensor block is `block`: forwards
    /// the controller's powers (or a heartbeat), steps a stepped board and waits for its
    /// sample, and returns the pose, real readings and true pose to push.
    /// `age`: how long before now the hub published the tick (its header's time).
    pub fn on_tick(&mut self, tick: u64, age: Duration, robot_id: u32, block: &SensorBlock) -> ActionBlock {
        self.outcome.ticks += 1;
        self.last_tick = tick;
        self.receive();
        self.safety.tick_aged(self.now(), age, block.drive, block.drive_flags);
        self.apply();
        if self.cfg.stepped {
            self.step();
        }
        self.safety.answered(self.now());
        self.apply();
        self.action(robot_id)
    }

    /// Stops the chair for good (see [`Safety::shutdown`]); keep calling [`BoardLink::service`]
    /// until [`BoardLink::shutdown_done`].
    pub fn shutdown(&mut self, cause: StopCause) {
        self.shutting_down = true;
        self.safety.shutdown(self.now(), cause);
        self.apply();
    }

    /// Whether the shutdown's stop is over (acknowledged, given up after 1 s, or no port).
    pub fn shutdown_done(&self) -> bool {
        self.safety.shutdown_done()
    }

    /// The odometry pose.
    pub fn pose(&self) -> Pose {
        self.odometry.pose()
    }

    /// Whether the board is known and talking.
    pub fn link_up(&self) -> bool {
        self.safety.link_up(self.now())
    }

    /// What the link did so far.
    pub fn outcome(&self) -> Outcome {
        let mut o = self.outcome.clone();
        o.frames = self.closed_stats;
        if let Some(p) = &self.port {
            port::add_stats(&mut o.frames, &p.stats());
        }
        o.unknown_readings = self.fresh.unknown();
        o
    }

    fn attach(&mut self, port: Port) {
        self.port = Some(port);
        self.board = None;
        self.due_ms = 0;
        // The new connection's counters are the new zero: the pose goes on from where it was.
        self.odometry.rebase();
        self.safety.port_opened(self.now());
        self.apply();
    }

    fn lost(&mut self, why: &std::io::Error) {
        if let Some(p) = self.port.take() {
            port::add_stats(&mut self.closed_stats, &p.stats());
        }
        agent_sdk::report!("iwsim serial: serial port {} went away ({why}); reconnecting", self.cfg.device.display());
        let now = self.now();
        self.next_open = now + REOPEN_EVERY;
        self.safety.port_lost(now);
        self.apply();
    }

    /// Reads and handles every frame that has arrived.
    fn receive(&mut self) {
        let Some(port) = &mut self.port else { return };
        let mut frames: Vec<Result<Frame, FrameDecodeError>> = Vec::new();
        let read = port.receive(|f| frames.push(f));
        let now = self.now();
        for f in frames {
            match f {
                Ok(frame) => self.handle(now, &frame.message),
                Err(e) => {
                    // Counted by the decoder; told at a bounded rate, so a noisy line cannot
                    // flood the log.
                    self.bad_frames = self.bad_frames.saturating_add(1);
                    let n = self.bad_frames;
                    if n.is_power_of_two() {
                        agent_sdk::report!("iwsim serial: dropped a bad frame from the board ({e}); {n} so far");
                    } else {
                        tracing::debug!("dropped a bad frame from the board: {e}");
                    }
                }
            }
        }
        if let Err(e) = read {
            self.lost(&e);
        }
        self.apply();
    }

    fn handle(&mut self, now: Duration, message: &Message) {
        if !message.message_type().from_board() {
            self.outcome.unexpected_frames += 1;
            return;
        }
        match message {
            Message::BoardInfo(info) => self.board_info(info),
            Message::Sample(s) => {
                match self.odometry.sample(s.board_time_ms, [s.encoder_left, s.encoder_right]) {
                    Step::BoardRestarted => {
                        agent_sdk::report!(
                            "iwsim serial: the board's clock went back (it restarted): new encoder baseline"
                        )
                    }
                    Step::Moved | Step::Baseline | Step::Unscaled => {}
                }
                self.fresh.add(s);
                self.due_ms = 0;
                self.sample_at.get_or_insert(now);
            }
            Message::SimTruth(t) => {
                self.ghost =
                    Some([f64::from(t.x_mm) / 1000.0, f64::from(t.y_mm) / 1000.0, f64::from(t.heading_mdeg) / 1000.0]);
                self.truth_seen = true;
            }
            _ => {}
        }
        self.safety.frame(now, message);
    }

    fn board_info(&mut self, info: &BoardInfo) {
        if self.board.as_ref() == Some(info) {
            return; // the answer to a repeated Hello
        }
        agent_sdk::report!(
            "iwsim serial: board ready: firmware {}, {} counts a turn, {} sonars, {} IR, a sample every {} ms",
            info.firmware_version,
            info.counts_per_rev,
            info.sonar_count,
            info.ir_count,
            info.sample_period_ms
        );
        let known = self.board.map(|b| b.counts_per_rev);
        if known != Some(info.counts_per_rev) && !self.odometry.set_counts_per_rev(info.counts_per_rev) {
            agent_sdk::report!(
                "iwsim serial: the board says 0 encoder counts a turn; odometry assumes the chair's {}",
                chair::COUNTS_PER_REV
            );
            self.odometry.set_counts_per_rev(chair::COUNTS_PER_REV);
        }
        if self.cfg.stepped && u32::from(info.sample_period_ms) != self.cfg.cycle_ms {
            agent_sdk::report!(
                "iwsim serial: the board samples every {} ms, the hub ticks every {} ms: some steps carry no sample",
                info.sample_period_ms,
                self.cfg.cycle_ms
            );
        }
        self.board = Some(*info);
    }

    /// Stepped mode: advances the board by one hub cycle and waits (at most [`STEP_WAIT`])
    /// for the sample that falls due, and the SimTruth after it.
    fn step(&mut self) {
        if self.port.is_none() || !self.safety.board_known() || self.shutting_down {
            return;
        }
        let dt_ms = self.cfg.cycle_ms.clamp(1, u32::from(u16::MAX));
        self.send(Message::SimStep(SimStep { dt_ms: dt_ms as u16 }));
        let period = self.board.map_or(100, |b| u32::from(b.sample_period_ms).max(1));
        self.due_ms = self.due_ms.saturating_add(dt_ms);
        if self.safety.stepped_silent() || self.due_ms < period {
            // Silent since an unanswered step: the step goes out, but the hub is not held for
            // it; a frame from the board ends the silence.
            return;
        }
        (self.sample_at, self.truth_seen) = (None, false);
        let deadline = self.now() + STEP_WAIT;
        loop {
            self.receive();
            let now = self.now();
            self.safety.poll(now);
            self.apply();
            let Some(fd) = self.fd() else { return };
            let truth_wait = if self.safety.emulated() { STEP_WAIT } else { TRUTH_WAIT };
            match self.sample_at {
                Some(at) if self.truth_seen || now >= at + truth_wait => return,
                _ if now >= deadline => {
                    agent_sdk::report!(
                        "iwsim serial: the board did not answer a step within {} ms",
                        STEP_WAIT.as_millis()
                    );
                    self.safety.step_unanswered(now);
                    self.apply();
                    return;
                }
                _ => port::wait_readable(&[fd], LOOK_EVERY),
            }
        }
    }

    fn action(&mut self, robot_id: u32) -> ActionBlock {
        let fresh = self.fresh.take();
        let link_up = self.safety.link_up(self.now());
        // The pose pushed: the odometry's, map-matched when localising (learning from this
        // tick's readings only while they are the board's own, scaled and fresh).
        let wire = self.odometry.pose().to_wire_deg();
        let [x, y, heading] = match &mut self.localiser {
            None => wire,
            Some(l) => {
                // The localiser matches the pose as pushed, its heading normalised in degrees,
                // so that a localised run pushes the very poses it always did.
                let odometry = Pose::from_wire_deg(wire);
                let pose =
                    if link_up && self.odometry.scaled() { l.update(odometry, &fresh) } else { l.estimate(odometry) };
                pose.to_wire_deg()
            }
        };
        let mut a = ActionBlock::pose(robot_id, x, y, heading);
        if link_up {
            if self.odometry.scaled() {
                a.flags |= ACT_REAL;
                a.real_m = fresh;
                a.real_encoders = self.odometry.hub_encoders(self.cfg.hub_ticks_per_m);
            }
            if let Some(g) = self.ghost {
                a.flags |= ACT_GHOST;
                a.ghost = g;
            }
        } else {
            a.flags |= ACT_LINK_DOWN;
        }
        a
    }

    /// Carries out what the safety state machine asked for.
    fn apply(&mut self) {
        let outputs: Vec<Output> = self.safety.drain().collect();
        for o in outputs {
            match o {
                Output::Send(m) => self.send(m),
                Output::Stop(cause) => {
                    agent_sdk::report!("iwsim serial: stopping the chair: {cause}");
                    self.outcome.stops.push((cause, self.last_tick));
                }
                Output::StopAcked(cause) => {
                    agent_sdk::report!("iwsim serial: the board acknowledged the stop ({cause})");
                }
                Output::StopUnacknowledged(cause) => agent_sdk::report!(
                    "iwsim serial: no StopAck within 1 s for the stop ({cause}); the board's watchdog holds the motors"
                ),
                Output::Resume(cause) => {
                    agent_sdk::report!("iwsim serial: resuming after the stop ({cause})");
                    self.outcome.resumes += 1;
                }
                Output::AwaitingResume(cause) => agent_sdk::report!(
                    "iwsim serial: every cause of the stop ({cause}) has cleared; the chair stays stopped until \
                     the operator resumes it (`iwsim resume {} --session …`, or `r` in `iwsim agent teleop`)",
                    self.cfg.robot
                ),
                Output::ResumeRefused(cause) => {
                    agent_sdk::report!("iwsim serial: resume refused: {cause}; ask again once it has cleared")
                }
                Output::BoardReady => agent_sdk::report!("iwsim serial: the board answered; the link is up"),
            }
        }
    }

    fn send(&mut self, m: Message) {
        let Some(port) = &mut self.port else { return };
        match port.send(&m) {
            Ok(Some(_)) => {}
            Ok(None) => self.outcome.writes_dropped += 1,
            Err(e) => self.lost(&e),
        }
    }
}

/// The sample period a stepped board is asked for: one sample per hub tick, within what
/// boards support (20..=1000 ms is the protocol's recommendation).
fn hello_period(cycle_ms: u32) -> u16 {
    cycle_ms.clamp(20, 1000) as u16
}
