//! The messages, their type codes and their payload layouts (little-endian throughout).
//!
//! Type codes below 0x80 travel from the host to the board, codes from 0x80 up from the board
//! to the host, so a byte in a hex dump tells the direction.

/// The most sonar readings, and the most IR readings, one [`Sample`] carries (sensor ids
/// 0..=7 of each kind).
pub const MAX_SENSORS: usize = 8;

/// The range a sonar or IR sensor reports when nothing echoed within its reach.
pub const NO_ECHO: u16 = 0xFFFF;

/// Full motor power, forward, in per-mille; `-FULL_POWER` is full power backward.
pub const FULL_POWER: i16 = 1000;

/// The most payload bytes any message has (a [`Sample`] with 8 + 8 readings).
pub const MAX_PAYLOAD_LEN: usize = SAMPLE_FIXED_LEN + 2 * MAX_SENSORS * READING_LEN;

const SAMPLE_FIXED_LEN: usize = 17;
const READING_LEN: usize = 3;

/// The message type byte of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageType {
    /// Host → board: open a session (clears a latched emergency stop).
    Hello = 0x01,
    /// Host → board: the wheels' motor powers; feeds the board's watchdog.
    MotorPowers = 0x02,
    /// Host → board: the host is alive (does not keep the motors turning).
    Heartbeat = 0x03,
    /// Host → board: stop now and latch.
    EmergencyStop = 0x04,
    /// Host → board, test benches only: advance a stepped emulator's clock.
    SimStep = 0x10,
    /// Board → host: the answer to a Hello.
    BoardInfo = 0x81,
    /// Board → host: encoder counts and range readings of one tick.
    Sample = 0x82,
    /// Board → host: the board's heartbeat and status/fault flags.
    Status = 0x83,
    /// Board → host: an emergency stop was carried out.
    StopAck = 0x84,
    /// Board → host, emulators only: the chair's true pose in its room.
    SimTruth = 0x90,
}

impl MessageType {
    /// Every message type, in code order.
    pub const ALL: [MessageType; 10] = [
        MessageType::Hello,
        MessageType::MotorPowers,
        MessageType::Heartbeat,
        MessageType::EmergencyStop,
        MessageType::SimStep,
        MessageType::BoardInfo,
        MessageType::Sample,
        MessageType::Status,
        MessageType::StopAck,
        MessageType::SimTruth,
    ];

    /// The type with code `code`, if there is one.
    pub fn from_code(code: u8) -> Option<MessageType> {
        MessageType::ALL.into_iter().find(|t| t.code() == code)
    }

    /// The type's code on the wire.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// Whether the board sends this type (else the host does).
    pub const fn from_board(self) -> bool {
        self.code() & 0x80 != 0
    }
}

/// Host → board: opens a session. The board answers with [`BoardInfo`], clears a latched
/// emergency stop and expects motor commands from now on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Hello {
    /// The sample period the host asks for, in ms; 0 asks for the board's default (100 ms).
    /// The board clamps it to what it supports and reports the period it uses.
    pub sample_period_ms: u16,
}

/// Host → board: motor powers of the two driving wheels, in per-mille of full power
/// (-1000..=1000); positive drives that wheel's side of the chair forward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MotorPowers {
    /// Left wheel, per-mille.
    pub left_permille: i16,
    /// Right wheel, per-mille.
    pub right_permille: i16,
}

/// Why the host stops the chair (informative: the board stops the same way for every reason,
/// including codes it does not know).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct StopReason(pub u8);

impl StopReason {
    /// No reason given.
    pub const UNSPECIFIED: StopReason = StopReason(0);
    /// A person asked for it (a stop button, Ctrl-C).
    pub const OPERATOR: StopReason = StopReason(1);
    /// The host program is shutting down.
    pub const HOST_SHUTDOWN: StopReason = StopReason(2);
    /// The host heard nothing valid from the board for 300 ms.
    pub const LINK_LOST: StopReason = StopReason(3);
    /// The agent controlling the chair died or went quiet.
    pub const CONTROLLER_LOST: StopReason = StopReason(4);
    /// The simulation hub went away.
    pub const HUB_LOST: StopReason = StopReason(5);
}

/// Host → board: stop the motors now and latch the stop until the next [`Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EmergencyStop {
    /// Why.
    pub reason: StopReason,
}

/// Board → host: what the board is, sent in answer to a [`Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardInfo {
    /// The firmware's own version number (free for the firmware author).
    pub firmware_version: u16,
    /// Encoder counts per wheel turn.
    pub counts_per_rev: u32,
    /// Sonars fitted (ids 0..sonar_count), at most [`MAX_SENSORS`].
    pub sonar_count: u8,
    /// IR sensors fitted (ids 0..ir_count), at most [`MAX_SENSORS`].
    pub ir_count: u8,
    /// The sample period the board uses, in ms.
    pub sample_period_ms: u16,
}

/// The board's status and fault flags. Bits the receiver does not know are kept, not refused,
/// so a newer firmware can add flags without breaking an older host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct StatusFlags(pub u16);

impl StatusFlags {
    /// The motors are held at zero because no valid MotorPowers arrived for 300 ms.
    pub const WATCHDOG_STOP: StatusFlags = StatusFlags(1 << 0);
    /// An emergency stop is latched (cleared by the next Hello).
    pub const ESTOP_LATCHED: StatusFlags = StatusFlags(1 << 1);
    /// A motor driver reports a fault (over-current, over-temperature).
    pub const MOTOR_FAULT: StatusFlags = StatusFlags(1 << 2);
    /// An encoder gives implausible counts or none while the motor turns.
    pub const ENCODER_FAULT: StatusFlags = StatusFlags(1 << 3);
    /// A fitted sonar or IR sensor did not answer.
    pub const SENSOR_FAULT: StatusFlags = StatusFlags(1 << 4);
    /// The battery is low.
    pub const LOW_BATTERY: StatusFlags = StatusFlags(1 << 5);
    /// The board dropped frames from the host (CRC, framing) since its last Status.
    pub const RX_ERRORS: StatusFlags = StatusFlags(1 << 6);
    /// The chair's own joystick has taken over; motor commands are ignored.
    pub const MANUAL_OVERRIDE: StatusFlags = StatusFlags(1 << 7);

    /// Whether every flag of `other` is set.
    pub const fn contains(self, other: StatusFlags) -> bool {
        self.0 & other.0 == other.0
    }

    /// These flags with those of `other` added.
    pub const fn with(self, other: StatusFlags) -> StatusFlags {
        StatusFlags(self.0 | other.0)
    }

    /// Whether the board currently refuses to drive (any stop or fault flag set).
    pub const fn motors_held(self) -> bool {
        self.0
            & (StatusFlags::WATCHDOG_STOP.0
                | StatusFlags::ESTOP_LATCHED.0
                | StatusFlags::MOTOR_FAULT.0
                | StatusFlags::MANUAL_OVERRIDE.0)
            != 0
    }
}

/// Board → host: its heartbeat, sent every second and at once when a flag changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardStatus {
    /// Milliseconds since the board started (wraps after 49 days).
    pub uptime_ms: u32,
    /// Status and fault flags.
    pub flags: StatusFlags,
}

/// Board → host: the stop the host asked for is done (motors commanded to zero, latched).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StopAck {
    /// The sequence number of the EmergencyStop frame acknowledged.
    pub stop_seq: u8,
    /// Its reason, echoed.
    pub reason: StopReason,
}

/// Host → board, a test-bench extension: a board in stepped mode (an emulator run for
/// deterministic tests) advances its clock by `dt_ms` and then sends what fell due in that
/// time. A real board, or an emulator running in real time, never acts on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimStep {
    /// How far to advance the board's clock, ms (0 advances nothing).
    pub dt_ms: u16,
}

/// The largest heading a [`SimTruth`] carries, milli-degrees; headings lie in
/// (−`HEADING_MDEG_MAX`, `HEADING_MDEG_MAX`], the project's one angle convention.
pub const HEADING_MDEG_MAX: i32 = 180_000;

/// Board → host, a test-bench extension: an emulator's ground truth, sent right after each
/// [`Sample`]. The host may show it to observers as the chair's true pose (a "ghost" beside
/// the odometry pose); it must never reach the agent controlling the chair. A real board never
/// sends it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimTruth {
    /// The board's clock at the Sample this truth belongs to, ms (wraps).
    pub board_time_ms: u32,
    /// True x of the chair's centre of movement in the emulator's room, mm.
    pub x_mm: i32,
    /// True y, mm.
    pub y_mm: i32,
    /// True heading, milli-degrees in (−180000, 180000].
    pub heading_mdeg: i32,
    /// Contacts with the room so far (moves the room refused, counted on their first tick).
    pub contacts: u32,
}

/// One range reading of a sonar or IR sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Reading {
    /// The sensor's id among its kind, 0..=7.
    pub id: u8,
    /// The range in millimetres, or [`NO_ECHO`].
    pub range_mm: u16,
}

/// Up to [`MAX_SENSORS`] readings of one kind, without allocation.
#[derive(Clone, Copy, Default)]
pub struct Readings {
    len: u8,
    items: [Reading; MAX_SENSORS],
}

impl Readings {
    /// No readings.
    pub const fn new() -> Readings {
        Readings { len: 0, items: [Reading { id: 0, range_mm: 0 }; MAX_SENSORS] }
    }

    /// The readings of `items`, or `None` when there are more than [`MAX_SENSORS`].
    pub fn from_slice(items: &[Reading]) -> Option<Readings> {
        let mut r = Readings::new();
        for &item in items {
            r.push(item).ok()?;
        }
        Some(r)
    }

    /// Adds a reading; gives it back when [`MAX_SENSORS`] are already held.
    pub fn push(&mut self, reading: Reading) -> Result<(), Reading> {
        let slot = self.items.get_mut(usize::from(self.len)).ok_or(reading)?;
        *slot = reading;
        self.len += 1;
        Ok(())
    }

    /// The readings held, in the order they were added (the order on the wire).
    pub fn as_slice(&self) -> &[Reading] {
        &self.items[..usize::from(self.len)]
    }

    /// How many readings are held.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether no reading is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The range of sensor `id`, if this set has a reading of it.
    pub fn range_mm(&self, id: u8) -> Option<u16> {
        self.as_slice().iter().find(|r| r.id == id).map(|r| r.range_mm)
    }

    /// Why this set cannot go on the wire, if it cannot: an id of 8 or more, or an id twice.
    fn check(&self) -> Result<(), &'static str> {
        let mut seen = 0u8;
        for r in self.as_slice() {
            if usize::from(r.id) >= MAX_SENSORS {
                return Err("sensor id above 7");
            }
            let bit = 1u8 << r.id;
            if seen & bit != 0 {
                return Err("sensor id repeated");
            }
            seen |= bit;
        }
        Ok(())
    }
}

impl core::fmt::Debug for Readings {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // The unused tail of the array is not part of the value.
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl PartialEq for Readings {
    fn eq(&self, other: &Readings) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl Eq for Readings {}

/// Board → host: what the board measured in one tick. Sonars fired in groups appear in the
/// samples of the ticks they were read in; IR sensors appear in every sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sample {
    /// The board's clock when the sample was taken, ms (wraps).
    pub board_time_ms: u32,
    /// Left wheel encoder, cumulative counts since power-up (wraps; forward counts up).
    pub encoder_left: i32,
    /// Right wheel encoder, cumulative counts since power-up (wraps; forward counts up).
    pub encoder_right: i32,
    /// Status and fault flags.
    pub flags: StatusFlags,
    /// The sequence number of the last MotorPowers frame the board applied (0 before any).
    pub last_motor_seq: u8,
    /// Sonar readings of this tick.
    pub sonar: Readings,
    /// IR readings of this tick.
    pub ir: Readings,
}

/// One message of the protocol, either direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Host → board, 0x01.
    Hello(Hello),
    /// Host → board, 0x02.
    MotorPowers(MotorPowers),
    /// Host → board, 0x03 (no payload).
    Heartbeat,
    /// Host → board, 0x04.
    EmergencyStop(EmergencyStop),
    /// Host → board, 0x10 (test benches only).
    SimStep(SimStep),
    /// Board → host, 0x81.
    BoardInfo(BoardInfo),
    /// Board → host, 0x82.
    Sample(Sample),
    /// Board → host, 0x83.
    Status(BoardStatus),
    /// Board → host, 0x84.
    StopAck(StopAck),
    /// Board → host, 0x90 (emulators only).
    SimTruth(SimTruth),
}

impl Message {
    /// This message's type.
    pub const fn message_type(&self) -> MessageType {
        match self {
            Message::Hello(_) => MessageType::Hello,
            Message::MotorPowers(_) => MessageType::MotorPowers,
            Message::Heartbeat => MessageType::Heartbeat,
            Message::EmergencyStop(_) => MessageType::EmergencyStop,
            Message::BoardInfo(_) => MessageType::BoardInfo,
            Message::Sample(_) => MessageType::Sample,
            Message::Status(_) => MessageType::Status,
            Message::StopAck(_) => MessageType::StopAck,
            Message::SimStep(_) => MessageType::SimStep,
            Message::SimTruth(_) => MessageType::SimTruth,
        }
    }

    /// Why this message cannot go on the wire, if it cannot. The encoder refuses what the
    /// decoder would refuse, so everything encoded decodes.
    pub(crate) fn check(&self) -> Result<(), &'static str> {
        let power_ok = |p: i16| (-FULL_POWER..=FULL_POWER).contains(&p);
        match self {
            Message::MotorPowers(m) if !power_ok(m.left_permille) => Err("left motor power beyond ±1000"),
            Message::MotorPowers(m) if !power_ok(m.right_permille) => Err("right motor power beyond ±1000"),
            Message::BoardInfo(b) if usize::from(b.sonar_count) > MAX_SENSORS => Err("more than 8 sonars"),
            Message::BoardInfo(b) if usize::from(b.ir_count) > MAX_SENSORS => Err("more than 8 IR sensors"),
            Message::Sample(s) => s.sonar.check().and(s.ir.check()),
            Message::SimTruth(t) if !(-HEADING_MDEG_MAX < t.heading_mdeg && t.heading_mdeg <= HEADING_MDEG_MAX) => {
                Err("heading beyond (-180000, 180000] milli-degrees")
            }
            _ => Ok(()),
        }
    }

    /// Writes the payload into `out` (at least [`MAX_PAYLOAD_LEN`] bytes), returning its length.
    pub(crate) fn write_payload(&self, out: &mut [u8; MAX_PAYLOAD_LEN]) -> usize {
        let mut w = Writer { out, at: 0 };
        match self {
            Message::Hello(h) => w.u16(h.sample_period_ms),
            Message::MotorPowers(m) => {
                w.i16(m.left_permille);
                w.i16(m.right_permille);
            }
            Message::Heartbeat => {}
            Message::EmergencyStop(e) => w.u8(e.reason.0),
            Message::BoardInfo(b) => {
                w.u16(b.firmware_version);
                w.u32(b.counts_per_rev);
                w.u8(b.sonar_count);
                w.u8(b.ir_count);
                w.u16(b.sample_period_ms);
            }
            Message::Sample(s) => {
                w.u32(s.board_time_ms);
                w.i32(s.encoder_left);
                w.i32(s.encoder_right);
                w.u16(s.flags.0);
                w.u8(s.last_motor_seq);
                w.u8(s.sonar.len);
                w.u8(s.ir.len);
                for r in s.sonar.as_slice().iter().chain(s.ir.as_slice()) {
                    w.u8(r.id);
                    w.u16(r.range_mm);
                }
            }
            Message::Status(s) => {
                w.u32(s.uptime_ms);
                w.u16(s.flags.0);
            }
            Message::StopAck(a) => {
                w.u8(a.stop_seq);
                w.u8(a.reason.0);
            }
            Message::SimStep(s) => w.u16(s.dt_ms),
            Message::SimTruth(t) => {
                w.u32(t.board_time_ms);
                w.i32(t.x_mm);
                w.i32(t.y_mm);
                w.i32(t.heading_mdeg);
                w.u32(t.contacts);
            }
        }
        w.at
    }

    /// Reads a payload of type `t`; `Err(None)` when its length is wrong for the type,
    /// `Err(Some(why))` when a field holds a value the protocol does not allow.
    pub(crate) fn read_payload(t: MessageType, payload: &[u8]) -> Result<Message, Option<&'static str>> {
        let mut r = Reader { data: payload, at: 0 };
        let m = match t {
            MessageType::Hello => Message::Hello(Hello { sample_period_ms: r.u16()? }),
            MessageType::MotorPowers => {
                Message::MotorPowers(MotorPowers { left_permille: r.i16()?, right_permille: r.i16()? })
            }
            MessageType::Heartbeat => Message::Heartbeat,
            MessageType::EmergencyStop => Message::EmergencyStop(EmergencyStop { reason: StopReason(r.u8()?) }),
            MessageType::BoardInfo => Message::BoardInfo(BoardInfo {
                firmware_version: r.u16()?,
                counts_per_rev: r.u32()?,
                sonar_count: r.u8()?,
                ir_count: r.u8()?,
                sample_period_ms: r.u16()?,
            }),
            MessageType::Sample => {
                let board_time_ms = r.u32()?;
                let encoder_left = r.i32()?;
                let encoder_right = r.i32()?;
                let flags = StatusFlags(r.u16()?);
                let last_motor_seq = r.u8()?;
                let n_sonar = r.u8()?;
                let n_ir = r.u8()?;
                if usize::from(n_sonar) > MAX_SENSORS || usize::from(n_ir) > MAX_SENSORS {
                    return Err(Some("more than 8 readings of one kind"));
                }
                let mut sonar = Readings::new();
                let mut ir = Readings::new();
                for i in 0..n_sonar + n_ir {
                    let reading = Reading { id: r.u8()?, range_mm: r.u16()? };
                    let into = if i < n_sonar { &mut sonar } else { &mut ir };
                    // Cannot fail: both counts were checked against MAX_SENSORS above.
                    into.push(reading).map_err(|_| Some("more than 8 readings of one kind"))?;
                }
                Message::Sample(Sample { board_time_ms, encoder_left, encoder_right, flags, last_motor_seq, sonar, ir })
            }
            MessageType::Status => Message::Status(BoardStatus { uptime_ms: r.u32()?, flags: StatusFlags(r.u16()?) }),
            MessageType::StopAck => Message::StopAck(StopAck { stop_seq: r.u8()?, reason: StopReason(r.u8()?) }),
            MessageType::SimStep => Message::SimStep(SimStep { dt_ms: r.u16()? }),
            MessageType::SimTruth => Message::SimTruth(SimTruth {
                board_time_ms: r.u32()?,
                x_mm: r.i32()?,
                y_mm: r.i32()?,
                heading_mdeg: r.i32()?,
                contacts: r.u32()?,
            }),
        };
        if r.at != payload.len() {
            return Err(None);
        }
        m.check().map_err(Some)?;
        Ok(m)
    }
}

/// Little-endian writer into a payload buffer. Every payload fits [`MAX_PAYLOAD_LEN`] by
/// construction (a `Readings` holds at most 8), so writes past the end cannot happen; they
/// would be dropped rather than panic.
struct Writer<'a> {
    out: &'a mut [u8; MAX_PAYLOAD_LEN],
    at: usize,
}

impl Writer<'_> {
    fn bytes<const N: usize>(&mut self, b: [u8; N]) {
        if let Some(dst) = self.out.get_mut(self.at..self.at + N) {
            dst.copy_from_slice(&b);
            self.at += N;
        }
    }
    fn u8(&mut self, v: u8) {
        self.bytes([v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(v.to_le_bytes());
    }
    fn i16(&mut self, v: i16) {
        self.bytes(v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.bytes(v.to_le_bytes());
    }
}

/// Little-endian reader over a received payload; running off the end is a length error.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], Option<&'static str>> {
        let b = self.data.get(self.at..self.at + N).and_then(|s| <[u8; N]>::try_from(s).ok()).ok_or(None)?;
        self.at += N;
        Ok(b)
    }
    fn u8(&mut self) -> Result<u8, Option<&'static str>> {
        Ok(self.bytes::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, Option<&'static str>> {
        Ok(u16::from_le_bytes(self.bytes()?))
    }
    fn i16(&mut self) -> Result<i16, Option<&'static str>> {
        Ok(i16::from_le_bytes(self.bytes()?))
    }
    fn u32(&mut self) -> Result<u32, Option<&'static str>> {
        Ok(u32::from_le_bytes(self.bytes()?))
    }
    fn i32(&mut self) -> Result<i32, Option<&'static str>> {
        Ok(i32::from_le_bytes(self.bytes()?))
    }
}
