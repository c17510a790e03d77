//! The emulated board and chair: the protocol's rules, the chair's physics and its sensors,
//! with no I/O and no clock. Bytes from the host go in with [`Board::receive`]; time goes in with
//! [`Board::advance_to`] (real time) or with the host's SimStep frames (stepped mode); frames for
//! the host and ground-truth events come out in an [`Outbox`]. The same inputs always give the
//! same outputs, which is what makes stepped runs reproducible byte for byte.

use serial_protocol::{
    BoardInfo, BoardStatus, Decoder, DecoderStats, FrameDecodeError, MAX_ENCODED_LEN, MAX_SENSORS, Message,
    MotorPowers, NO_ECHO, Reading, Readings, Sample, SimTruth, StatusFlags, StopAck, StopReason, encode,
};
use sim_model::{PoseDeg, chair};
use world::map::{NoiseParams, Params};
use world::math::Pose;
use world::rng::Rng;
use world::{Action, AddRobotError, ProximitySpec, RobotHandle, RobotKind, RobotSpec, World, WorldBuildError};

use crate::room::Room;

/// The physics step, µs: the emulated chair moves in steps of 20 ms on the board's clock.
pub const PHYSICS_US: u64 = 20_000;
/// The board's watchdog, µs: motors to zero when no valid MotorPowers came for this long.
pub const WATCHDOG_US: u64 = 300_000;
/// The Status period, µs.
pub const STATUS_US: u64 = 1_000_000;
/// The sample period a Hello asking for 0 gets, ms.
pub const DEFAULT_PERIOD_MS: u16 = 100;
/// The shortest sample period the emulated board supports, ms (one physics step).
pub const MIN_PERIOD_MS: u16 = 20;
/// The longest sample period the emulated board supports, ms.
pub const MAX_PERIOD_MS: u16 = 1000;
/// The firmware version the emulator reports in BoardInfo ("0xE" for emulator, then 1).
pub const FIRMWARE_VERSION: u16 = 0xE001;

/// The motor filter's coefficient per 20 ms physics step. `chair::ACCEL_CURVE` (thesis §7.2)
/// is per 100 ms tick; applying it five times as often would make the motors respond five times
/// faster, so each step uses its fifth root: five steps filter as one tick does.
fn accel_curve_per_step() -> f64 {
    chair::ACCEL_CURVE.powf(PHYSICS_US as f64 / 100_000.0)
}

/// The real-world imperfections the emulated chair shows. Fractions are of one (0.03 = 3 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Imperfections {
    /// The right motor is this fraction weaker than the left (the chair pulls right at equal
    /// powers), in [0, 1).
    pub asymmetry: f64,
    /// Wheel slip: each wheel's counted travel is off by this fraction (1σ) per 100 ms of
    /// driving, as `world::map::NoiseParams::encoder_slip_frac`; the true motion is the
    /// world's. Odometry drifts by it.
    pub slip: f64,
    /// The chance that a sonar reading gets no echo, in [0, 1].
    pub sonar_dropout: f64,
    /// The chance that a sonar reading is a spurious short echo (a uniform range from 0.1 m to
    /// the sensor's reach), in [0, 1].
    pub sonar_spike: f64,
    /// Gaussian noise on every range that got an echo, metres (1σ).
    pub range_noise_m: f64,
}

impl Imperfections {
    /// What a real chair shows: the right motor 3 % weaker, 2 % wheel slip per 100 ms, 2 %
    /// sonar dropouts, 0.5 % sonar spikes, 1 cm range noise.
    pub const REAL_CHAIR: Imperfections =
        Imperfections { asymmetry: 0.03, slip: 0.02, sonar_dropout: 0.02, sonar_spike: 0.005, range_noise_m: 0.01 };
    /// None at all: the emulated chair is the world model's ideal chair.
    pub const NONE: Imperfections =
        Imperfections { asymmetry: 0.0, slip: 0.0, sonar_dropout: 0.0, sonar_spike: 0.0, range_noise_m: 0.0 };

    fn check(&self) -> Result<(), BoardBuildError> {
        let bad = |name: &'static str, value: f64, expected: &'static str| {
            Err(BoardBuildError::BadImperfection { name, value, expected })
        };
        if !(0.0..1.0).contains(&self.asymmetry) {
            return bad("asymmetry", self.asymmetry, "in [0, 1)");
        }
        for (name, value) in [("sonar_dropout", self.sonar_dropout), ("sonar_spike", self.sonar_spike)] {
            if !(0.0..=1.0).contains(&value) {
                return bad(name, value, "in [0, 1]");
            }
        }
        for (name, value) in [("slip", self.slip), ("range_noise", self.range_noise_m)] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(name, value, ">= 0");
            }
        }
        Ok(())
    }
}

impl Default for Imperfections {
    fn default() -> Self {
        Self::REAL_CHAIR
    }
}

/// What the board and chair are built from.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardConfig {
    /// The chair's true start pose: x, y (metres) and heading (degrees).
    pub pose: PoseDeg,
    /// Fixes every random draw.
    pub seed: u64,
    /// The clock advances only on SimStep frames (deterministic); otherwise on
    /// [`Board::advance_to`].
    pub stepped: bool,
    /// The chair's imperfections.
    pub imperfections: Imperfections,
    /// Every Sample carries 8 sonar and 8 IR readings, all sonars firing every period (the
    /// largest frame the protocol has, for benchmarks); the ids the chair has no sensor for
    /// read no echo. Off: the chair's own sensors, sonars in two alternating groups.
    pub full_frames: bool,
}

impl Default for BoardConfig {
    fn default() -> Self {
        Self {
            pose: [10.0, 6.1, 0.0],
            seed: 1,
            stepped: false,
            imperfections: Imperfections::REAL_CHAIR,
            full_frames: false,
        }
    }
}

/// Why a board could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoardBuildError {
    /// The room's geometry is unusable for the world model.
    #[error("the room cannot be built: {0}")]
    World(#[from] WorldBuildError),
    /// The world refused the chair (a pose off the room, a non-finite number).
    #[error("the chair cannot be placed at ({x}, {y}, {heading_deg}°): {source}")]
    Robot {
        /// Start x, metres.
        x: f64,
        /// Start y, metres.
        y: f64,
        /// Start heading, degrees.
        heading_deg: f64,
        /// Why.
        #[source]
        source: AddRobotError,
    },
    /// The chair's body at its start pose overlaps a wall or a box.
    #[error("the chair's start pose ({x}, {y}, {heading_deg}°) puts its body inside a wall or box of the room")]
    PoseBlocked {
        /// Start x, metres.
        x: f64,
        /// Start y, metres.
        y: f64,
        /// Start heading, degrees.
        heading_deg: f64,
    },
    /// An imperfection is out of range.
    #[error("{name} = {value} is out of range: expected {expected}")]
    BadImperfection {
        /// Which.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The allowed range.
        expected: &'static str,
    },
}

/// Why the applied motor powers went to zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZeroReason {
    /// A MotorPowers asked for zero.
    Command,
    /// An EmergencyStop.
    Estop,
    /// The 300 ms watchdog.
    Watchdog,
    /// A Hello (a new session starts with the motors at zero).
    Hello,
}

impl ZeroReason {
    /// Its name in the truth log.
    pub fn name(self) -> &'static str {
        match self {
            ZeroReason::Command => "command",
            ZeroReason::Estop => "estop",
            ZeroReason::Watchdog => "watchdog",
            ZeroReason::Hello => "hello",
        }
    }
}

/// Something the ground-truth log records.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EventKind {
    /// A physics step ended: the chair's true pose, the applied powers, contacts so far.
    Step {
        /// True pose.
        pose: Pose,
        /// Applied powers, left and right, in [−1, 1] (before the motors' asymmetry).
        cmd: [f64; 2],
        /// Contacts with the room so far.
        contacts: u64,
    },
    /// The applied powers became zero from nonzero.
    MotorsZero(ZeroReason),
    /// A chunk of bytes from the host was not a valid frame, and was not acted on.
    FrameDropped(&'static str),
    /// A Hello opened a session.
    Hello {
        /// The sample period in use, ms.
        period_ms: u16,
    },
    /// An EmergencyStop was carried out.
    EmergencyStop {
        /// Its reason code.
        reason: u8,
    },
}

/// An event and when it happened on the board's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event {
    /// The board's clock, µs since power-up.
    pub board_us: u64,
    /// What happened.
    pub kind: EventKind,
}

/// What the board produced: bytes for the host, in order, and events for the truth log.
#[derive(Debug, Clone, Default)]
pub struct Outbox {
    /// Encoded frames for the host, in the order they are sent.
    pub wire: Vec<u8>,
    /// Ground-truth events, in time order.
    pub events: Vec<Event>,
    /// Set when a Hello started a session: whatever the host has not read of what was sent
    /// before `wire[flush_before..]` is stale, and a real line would not have kept it for a
    /// host that was not there; the driver discards it (see the crate docs).
    pub flush_before: Option<usize>,
}

impl Outbox {
    /// Empties the outbox.
    pub fn clear(&mut self) {
        self.wire.clear();
        self.events.clear();
        self.flush_before = None;
    }
}

/// What the board counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardCounters {
    /// Frames from the host decoded, and each kind of refused chunk.
    pub decoder: DecoderStats,
    /// Hellos.
    pub hellos: u32,
    /// MotorPowers applied.
    pub motor_commands: u32,
    /// MotorPowers ignored because an emergency stop was latched.
    pub ignored_latched: u32,
    /// Heartbeats.
    pub heartbeats: u32,
    /// EmergencyStops.
    pub emergency_stops: u32,
    /// SimSteps carried out (stepped mode).
    pub sim_steps: u32,
    /// SimSteps ignored (real-time mode).
    pub ignored_sim_steps: u32,
    /// Valid frames of a board → host type, which a board never acts on.
    pub wrong_direction: u32,
    /// Frames sent: Samples, and all frames.
    pub samples_sent: u32,
    /// All frames sent.
    pub frames_sent: u32,
}

/// The emulated board with its chair.
#[derive(Debug)]
pub struct Board {
    world: World,
    chair: RobotHandle,
    /// The room without its dark boxes, where a twin of the chair is put at the true pose to
    /// see what the IR beams would meet without them.
    ir_world: Option<(World, RobotHandle)>,
    rng: Rng,
    imperfections: Imperfections,
    stepped: bool,
    full_frames: bool,
    now_us: u64,
    next_physics_us: u64,
    /// Next Sample and next periodic Status; `None` until a Hello opens a session (the board
    /// speaks only when spoken to).
    next_sample_us: Option<u64>,
    next_status_us: Option<u64>,
    period_ms: u16,
    /// Applied powers in [−1, 1], left and right.
    applied: [f64; 2],
    last_command_us: u64,
    last_motor_seq: u8,
    flags: StatusFlags,
    reported_flags: StatusFlags,
    tx_seq: u8,
    samples: u32,
    decoder: Decoder,
    counters: BoardCounters,
}

/// The chair's body and sensors as the world model takes them.
fn chair_spec([x_m, y_m, heading_deg]: PoseDeg, kind: RobotKind) -> RobotSpec {
    let [length, width, com] = chair::BODY;
    let sensors = chair::SENSORS
        .iter()
        .map(|m| ProximitySpec {
            range_m: Some(m.range_m),
            ..ProximitySpec::deg(m.x_m, m.y_m, m.angle_deg, m.cone_deg)
        })
        .collect();
    RobotSpec::at(x_m, y_m, heading_deg)
        .named("chair")
        .kind(kind)
        .body(length, width, com)
        .motors(chair::MAX_SPEED_MPS, accel_curve_per_step())
        .sensors(sensors)
}

/// Range in mm as the protocol carries it (0xFFFF is reserved for no echo).
fn mm(d_m: f64) -> u16 {
    (d_m * 1000.0).round().clamp(0.0, f64::from(NO_ECHO - 1)) as u16
}

/// Whether a world's reading means nothing within the sensor's reach: the world caps its
/// distances at the range exactly, and computes them in f32, hence the small margin.
fn no_echo(d_m: f64, range_m: f64) -> bool {
    d_m >= range_m - 1e-4
}

impl Board {
    /// A board whose chair stands at `cfg.pose` in `room`, at power-up (clock 0, motors at
    /// zero, silent until a Hello).
    pub fn new(cfg: &BoardConfig, room: &Room) -> Result<Board, BoardBuildError> {
        cfg.imperfections.check()?;
        let mut params = Params { cycle_ms: (PHYSICS_US / 1000) as u32, ..Params::default() };
        params.encoder_ticks_per_rev = chair::COUNTS_PER_REV;
        params.wheel_radius_m = chair::WHEEL_RADIUS_M;
        // The world's slip is per step; the drift it makes grows with the square root of the step
        // (NoiseParams' docs), so a 20 ms step needs √5 times the per-100-ms figure.
        let per_step = (100_000.0 / PHYSICS_US as f64).sqrt();
        params.noise = NoiseParams { encoder_slip_frac: cfg.imperfections.slip * per_step, ..NoiseParams::NONE };
        let [x, y, heading_deg] = cfg.pose;
        let spec = chair_spec(cfg.pose, RobotKind::Simulated);
        let mut world = World::new(&room.lab(true), params.clone(), cfg.seed)?;
        let robot_error = |source| BoardBuildError::Robot { x, y, heading_deg, source };
        spec.validate_at(PHYSICS_US as f64 / 1e6).map_err(robot_error)?;
        if !world.is_free(&spec) {
            return Err(BoardBuildError::PoseBlocked { x, y, heading_deg });
        }
        let chair = world.add_robot(spec).map_err(robot_error)?;
        world.refresh_sensors();
        let ir_world = if room.has_dark() {
            let mut w = World::new(&room.lab(false), params, cfg.seed ^ 0x1e)?;
            let h = w.add_robot(chair_spec(cfg.pose, RobotKind::Real)).map_err(robot_error)?;
            Some((w, h))
        } else {
            None
        };
        Ok(Board {
            world,
            chair,
            ir_world,
            // The sensors' own generator, apart from the world's, so that switching a sensor
            // imperfection on or off leaves the chair's motion alone.
            rng: Rng::seed_from_u64(cfg.seed ^ 0x5e45_0125),
            imperfections: cfg.imperfections,
            stepped: cfg.stepped,
            full_frames: cfg.full_frames,
            now_us: 0,
            next_physics_us: PHYSICS_US,
            next_sample_us: None,
            next_status_us: None,
            period_ms: DEFAULT_PERIOD_MS,
            applied: [0.0; 2],
            last_command_us: 0,
            last_motor_seq: 0,
            flags: StatusFlags::default(),
            reported_flags: StatusFlags::default(),
            tx_seq: 0,
            samples: 0,
            decoder: Decoder::new(),
            counters: BoardCounters::default(),
        })
    }

    /// The board's clock, µs since power-up.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// Whether the clock advances only on SimStep.
    pub fn stepped(&self) -> bool {
        self.stepped
    }

    /// The chair's true pose.
    pub fn pose(&self) -> Pose {
        self.world.robot(self.chair).map_or(Pose::new(0.0, 0.0, 0.0), |r| r.pose)
    }

    /// Contacts with the room so far.
    pub fn contacts(&self) -> u64 {
        self.world.robot(self.chair).map_or(0, |r| r.collision_count)
    }

    /// The applied motor powers, left and right, in [−1, 1].
    pub fn applied(&self) -> [f64; 2] {
        self.applied
    }

    /// The status flags.
    pub fn flags(&self) -> StatusFlags {
        self.flags
    }

    /// What the board counted.
    pub fn counters(&self) -> BoardCounters {
        BoardCounters { decoder: *self.decoder.stats(), ..self.counters }
    }

    /// When the next thing is due on the board's clock (physics, watchdog, sample, status), µs.
    pub fn next_event_us(&self) -> u64 {
        [Some(self.next_physics_us), self.watchdog_due(), self.next_sample_us, self.next_status_us]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(self.next_physics_us)
    }

    fn watchdog_due(&self) -> Option<u64> {
        (!self.flags.contains(StatusFlags::WATCHDOG_STOP)).then_some(self.last_command_us + WATCHDOG_US)
    }

    /// Takes bytes from the host. Each complete valid frame takes effect at the board's current
    /// time, in order; a SimStep (stepped mode) runs the clock on before the next frame.
    pub fn receive(&mut self, bytes: &[u8], out: &mut Outbox) {
        for &b in bytes {
            if let Some(result) = self.decoder.push(b) {
                self.on_frame(result, out);
            }
        }
    }

    /// Runs the clock on to `t_us`, doing everything that falls due on the way in time order:
    /// physics steps, the watchdog, samples (each followed by its SimTruth), statuses.
    pub fn advance_to(&mut self, t_us: u64, out: &mut Outbox) {
        while self.next_event_us() <= t_us {
            let t = self.next_event_us();
            self.now_us = t;
            // At one instant: the step that ends now moves the chair with the powers applied
            // until now; the watchdog then stops the motors for the steps after; a sample taken
            // now sees the chair where the step left it.
            if self.next_physics_us == t {
                self.physics_step(out);
                self.next_physics_us += PHYSICS_US;
            }
            if self.watchdog_due() == Some(t) {
                self.flags = self.flags.with(StatusFlags::WATCHDOG_STOP);
                self.zero_motors(ZeroReason::Watchdog, out);
            }
            if self.next_sample_us == Some(t) {
                self.send_sample(out);
                self.next_sample_us = Some(t + u64::from(self.period_ms) * 1000);
            }
            if self.next_status_us == Some(t) {
                self.send_status(out);
                // RX_ERRORS means "since the last Status": it is reported, then forgotten.
                self.flags = StatusFlags(self.flags.0 & !StatusFlags::RX_ERRORS.0);
                self.reported_flags = self.flags;
                self.next_status_us = Some(t + STATUS_US);
            }
            self.report_flag_change(out);
        }
        self.now_us = self.now_us.max(t_us);
    }

    fn on_frame(&mut self, result: Result<serial_protocol::Frame, FrameDecodeError>, out: &mut Outbox) {
        let frame = match result {
            Ok(frame) => frame,
            Err(e) => {
                // Never acted on, not even partly: counted (by the decoder), logged, flagged.
                self.event(out, EventKind::FrameDropped(drop_reason(&e)));
                self.flags = self.flags.with(StatusFlags::RX_ERRORS);
                self.report_flag_change(out);
                return;
            }
        };
        match frame.message {
            Message::Hello(h) => {
                self.counters.hellos += 1;
                self.period_ms = match h.sample_period_ms {
                    0 => DEFAULT_PERIOD_MS,
                    p => p.clamp(MIN_PERIOD_MS, MAX_PERIOD_MS),
                };
                self.zero_motors(ZeroReason::Hello, out);
                self.flags = StatusFlags(self.flags.0 & !StatusFlags::ESTOP_LATCHED.0);
                self.next_sample_us = Some(self.now_us + u64::from(self.period_ms) * 1000);
                self.next_status_us = Some(self.now_us + STATUS_US);
                self.event(out, EventKind::Hello { period_ms: self.period_ms });
                out.flush_before = Some(out.wire.len());
                let (sonar_count, ir_count) = self.sensor_counts();
                self.send(
                    Message::BoardInfo(BoardInfo {
                        firmware_version: FIRMWARE_VERSION,
                        counts_per_rev: chair::COUNTS_PER_REV,
                        sonar_count,
                        ir_count,
                        sample_period_ms: self.period_ms,
                    }),
                    out,
                );
            }
            Message::MotorPowers(m) => self.on_motor_powers(m, frame.seq, out),
            Message::Heartbeat => self.counters.heartbeats += 1,
            Message::EmergencyStop(e) => {
                self.counters.emergency_stops += 1;
                self.zero_motors(ZeroReason::Estop, out);
                self.flags = self.flags.with(StatusFlags::ESTOP_LATCHED);
                self.event(out, EventKind::EmergencyStop { reason: e.reason.0 });
                self.send(Message::StopAck(StopAck { stop_seq: frame.seq, reason: StopReason(e.reason.0) }), out);
            }
            Message::SimStep(s) if self.stepped => {
                self.counters.sim_steps += 1;
                self.advance_to(self.now_us + u64::from(s.dt_ms) * 1000, out);
            }
            Message::SimStep(_) => self.counters.ignored_sim_steps += 1,
            Message::BoardInfo(_)
            | Message::Sample(_)
            | Message::Status(_)
            | Message::StopAck(_)
            | Message::SimTruth(_) => self.counters.wrong_direction += 1,
        }
        self.report_flag_change(out);
    }

    fn on_motor_powers(&mut self, m: MotorPowers, seq: u8, out: &mut Outbox) {
        if self.flags.contains(StatusFlags::ESTOP_LATCHED) {
            self.counters.ignored_latched += 1;
            return;
        }
        self.counters.motor_commands += 1;
        self.last_command_us = self.now_us;
        self.last_motor_seq = seq;
        self.flags = StatusFlags(self.flags.0 & !StatusFlags::WATCHDOG_STOP.0);
        // The decoder refused anything beyond ±1000, so this is already in [−1, 1]; the clamp
        // says so to the reader.
        let power = |p: i16| (f64::from(p) / 1000.0).clamp(-1.0, 1.0);
        let new = [power(m.left_permille), power(m.right_permille)];
        if new == [0.0; 2] {
            self.zero_motors(ZeroReason::Command, out);
        } else {
            self.applied = new;
        }
    }

    fn zero_motors(&mut self, reason: ZeroReason, out: &mut Outbox) {
        if self.applied != [0.0; 2] {
            self.applied = [0.0; 2];
            self.event(out, EventKind::MotorsZero(reason));
        }
    }

    fn physics_step(&mut self, out: &mut Outbox) {
        let [l, r] = self.applied;
        let action = Action::motors(self.chair, l, r * (1.0 - self.imperfections.asymmetry));
        self.world.step(&[action], PHYSICS_US as f64 / 1e6);
        let kind = EventKind::Step { pose: self.pose(), cmd: self.applied, contacts: self.contacts() };
        self.event(out, kind);
    }

    fn sensor_counts(&self) -> (u8, u8) {
        if self.full_frames {
            return (MAX_SENSORS as u8, MAX_SENSORS as u8);
        }
        let count = |k| chair::SENSORS.iter().filter(|m| m.kind == k).count() as u8;
        (count(chair::Kind::Sonar), count(chair::Kind::Ir))
    }

    fn send_sample(&mut self, out: &mut Outbox) {
        let Some(robot) = self.world.robot(self.chair) else { return };
        let readings = robot.readings;
        let pose = robot.pose;
        // What the IR beams see without the dark boxes, from the same true pose.
        let clear = match &mut self.ir_world {
            Some((w, h)) => {
                w.step(&[Action::pose(*h, pose)], PHYSICS_US as f64 / 1e6);
                w.robot(*h).map(|r| r.readings.proximity_m)
            }
            None => None,
        };
        // Sonars fire in two groups, even and odd ids, in alternate periods, so that
        // neighbours never ping together (crosstalk); IR sensors are read every period.
        let group = (self.samples % 2) as u8;
        self.samples = self.samples.wrapping_add(1);
        let mut sonar = Readings::new();
        let mut ir = Readings::new();
        let prox = readings.proximity();
        for (i, m) in chair::SENSORS.iter().enumerate() {
            let d = prox.get(i).copied().unwrap_or(m.range_m);
            let reading = match m.kind {
                chair::Kind::Sonar if self.full_frames || m.board_id % 2 == group => {
                    Reading { id: m.board_id, range_mm: self.sonar_range(d, m.range_m) }
                }
                chair::Kind::Sonar => continue,
                chair::Kind::Ir => {
                    let seen_without_dark = clear.and_then(|c| c.get(i).copied()).unwrap_or(d);
                    Reading { id: m.board_id, range_mm: self.ir_range(d, seen_without_dark, m.range_m) }
                }
            };
            let into = if m.kind == chair::Kind::Sonar { &mut sonar } else { &mut ir };
            // At most 8 per kind by construction (SENSORS has 8 mounts in all).
            let _ = into.push(reading);
        }
        if self.full_frames {
            // A board with every sensor fitted: the ids the chair lacks read no echo.
            for (set, n) in [(&mut sonar, MAX_SENSORS), (&mut ir, MAX_SENSORS)] {
                for id in 0..n as u8 {
                    if set.range_mm(id).is_none() {
                        let _ = set.push(Reading { id, range_mm: NO_ECHO });
                    }
                }
            }
        }
        let board_time_ms = (self.now_us / 1000) as u32;
        let [el, er] = readings.encoder_ticks;
        let sample = Sample {
            board_time_ms,
            // Cumulative counts wrap as a board's 32-bit counters do.
            encoder_left: el as i32,
            encoder_right: er as i32,
            flags: self.flags,
            last_motor_seq: self.last_motor_seq,
            sonar,
            ir,
        };
        self.send(Message::Sample(sample), out);
        self.counters.samples_sent += 1;
        let mut heading_mdeg = (pose.heading_deg() * 1000.0).round() as i32;
        if heading_mdeg <= -serial_protocol::HEADING_MDEG_MAX {
            heading_mdeg += 2 * serial_protocol::HEADING_MDEG_MAX;
        }
        let truth = SimTruth {
            board_time_ms,
            x_mm: (pose.x * 1000.0).round() as i32,
            y_mm: (pose.y * 1000.0).round() as i32,
            heading_mdeg,
            contacts: u32::try_from(self.contacts()).unwrap_or(u32::MAX),
        };
        self.send(Message::SimTruth(truth), out);
    }

    /// A sonar's reading of a true distance `d_m`: sometimes no echo, sometimes a spurious short
    /// echo, otherwise the distance with noise.
    fn sonar_range(&mut self, d_m: f64, range_m: f64) -> u16 {
        let im = self.imperfections;
        if im.sonar_dropout > 0.0 && self.rng.next_f64() < im.sonar_dropout {
            return NO_ECHO;
        }
        if im.sonar_spike > 0.0 && self.rng.next_f64() < im.sonar_spike {
            return mm(self.rng.uniform(0.1, range_m));
        }
        self.noisy_range(d_m, range_m)
    }

    /// An IR beam's reading: `d_m` with every box, `clear_m` without the dark ones. When the
    /// nearest thing in the beam is dark, no light comes back.
    fn ir_range(&mut self, d_m: f64, clear_m: f64, range_m: f64) -> u16 {
        if d_m < clear_m - 1e-3 {
            return NO_ECHO;
        }
        self.noisy_range(d_m, range_m)
    }

    fn noisy_range(&mut self, d_m: f64, range_m: f64) -> u16 {
        if no_echo(d_m, range_m) {
            return NO_ECHO;
        }
        let noisy = self.rng.noisy(d_m, self.imperfections.range_noise_m);
        mm(noisy.clamp(0.0, range_m))
    }

    fn send_status(&mut self, out: &mut Outbox) {
        let status = BoardStatus { uptime_ms: (self.now_us / 1000) as u32, flags: self.flags };
        self.send(Message::Status(status), out);
        self.reported_flags = self.flags;
    }

    /// A Status at once when a flag changed since the last one (in a session).
    fn report_flag_change(&mut self, out: &mut Outbox) {
        if self.flags != self.reported_flags && self.next_status_us.is_some() {
            self.send_status(out);
        }
    }

    fn send(&mut self, message: Message, out: &mut Outbox) {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        // Every message the board builds is valid, so encoding cannot fail; were it to, the
        // frame is left out rather than sent half-made.
        if let Ok(n) = encode(&message, self.tx_seq, &mut buf) {
            out.wire.extend_from_slice(&buf[..n]);
            self.tx_seq = self.tx_seq.wrapping_add(1);
            self.counters.frames_sent += 1;
        }
    }

    fn event(&self, out: &mut Outbox, kind: EventKind) {
        out.events.push(Event { board_us: self.now_us, kind });
    }
}

/// A refused chunk's reason as the truth log names it (the decoder's counter names).
pub fn drop_reason(e: &FrameDecodeError) -> &'static str {
    match e {
        FrameDecodeError::Oversize => "oversize",
        FrameDecodeError::Cobs | FrameDecodeError::TooShort { .. } => "malformed",
        FrameDecodeError::Crc { .. } => "crc",
        FrameDecodeError::BadVersion { .. } => "bad_version",
        FrameDecodeError::UnknownType { .. } => "unknown_type",
        FrameDecodeError::BadLength { .. } => "bad_length",
        FrameDecodeError::InvalidField { .. } => "invalid_field",
    }
}

#[cfg(test)]
mod tests;
