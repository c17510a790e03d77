//! The fixed-layout types that cross process boundaries in iwsim: world snapshots, per-robot
//! sensor blocks, actions, registration, run control, the map, and the latency benchmark's
//! ping, as iceoryx2 zero-copy payloads.
//!
//! Every type is `#[repr(C)]`, made of fixed-width scalars and fixed arrays, has an explicit
//! versioned iceoryx2 type name, spells its padding out as `_reserved` (bytemuck's `Pod`
//! derive refuses hidden padding), and has its size and alignment asserted at compile time
//! (processes built apart map the same bytes, so a layout may change only together with its
//! versioned type name, never by accident). Units are SI and degrees, as on every iwsim wire;
//! the unit is in the field name where it is not obvious.
//!
//! The crate is `no_std` (with `alloc`, for the [`remote`] framing) and free of iceoryx2 proper and of any clock: the services and
//! `monotonic_ns` live in `ipc-services`.
//!
//! ```
//! use ipc_types::{FixedName, RobotRegistration, RobotKind};
//!
//! let mut reg = RobotRegistration::new("chair-1");
//! reg.kind = RobotKind::Simulated as u32;
//! assert_eq!(reg.name.as_str(), Some("chair-1"));
//! assert_eq!(FixedName::new("x".repeat(300).as_str()), None, "names are at most 255 bytes");
//! ```
#![no_std]
#![warn(missing_docs)]

// The remote framing (`remote`) builds owned payloads; nothing else allocates.
extern crate alloc;

use bytemuck::{Pod, Zeroable};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Robots one hub serves.
pub const MAX_ROBOTS: usize = 10_000;
/// Agent processes one hub serves.
pub const MAX_AGENTS: usize = 128;
/// Proximity sensors per robot.
pub const MAX_PROXIMITY: usize = 8;
/// Beacons in a lab.
pub const MAX_BEACONS: usize = 16;
/// Bytes of a name, its terminating zero included: room for any name a Ciber-Rato client or
/// a lab file gives in practice (the real simulator keeps names whole; a UDP datagram of its
/// protocol is 1024 bytes). Names travel only where they are static (registration, the
/// robots' info, the map header), never in the per-tick world snapshot.
pub const NAME_BYTES: usize = 256;
/// Bytes a robot may say per tick.
pub const MESSAGE_BYTES: usize = 100;
/// Bytes a robot may hear per tick.
pub const INBOX_BYTES: usize = 400;
/// Messages a robot may hear per tick (the bytes limit usually binds first).
pub const MAX_INBOX_MESSAGES: usize = 16;
/// Elements of the line sensor.
pub const LINE_ELEMENTS: usize = 7;

pub mod remote;

/// Service name parts, below `iwsim/<session>/`. The services crate builds full names.
pub mod service {
    /// World snapshots (pub/sub, slice of [`crate::RobotState`] with a [`crate::WorldHeader`]),
    /// and the tick doorbell (event) under the same name.
    pub const WORLD: &str = "world";
    /// The map agents get (pub/sub with history, slice of [`crate::MapItem`] with a
    /// [`crate::MapHeader`]): the lab's walls, beacons, targets, grid and route, without the
    /// scenario's obstacles (an agent's sensors must find those).
    pub const MAP: &str = "map";
    /// The map observers get (viewer, recorder, runner, the UDP bridge's viewers): the same
    /// layout as [`MAP`], with the scenario's obstacles as walls flagged `c = 1`.
    pub const OBSERVER_MAP: &str = "observer/map";
    /// Physical chairs as observers see them (pub/sub, slice of [`crate::ChairState`] with the
    /// tick as header), every tick while the run has chairs.
    pub const OBSERVER_CHAIRS: &str = "observer/chairs";
    /// Actions from every agent (pub/sub, slice of [`crate::ActionBlock`] with an
    /// [`crate::ActionHeader`]), and the agents' doorbell to the hub (event).
    pub const ACTIONS: &str = "actions";
    /// Agent hello and robot registration (request-response).
    pub const REGISTER: &str = "register";
    /// Run control (request-response).
    pub const CONTROL: &str = "control";
    /// Per-agent sensor blocks: `agent/<id>/sensors` (pub/sub, slice of
    /// [`crate::SensorBlock`] with a [`crate::TickHeader`]).
    pub const AGENT_SENSORS_PREFIX: &str = "agent";
    /// Every robot's static description, its name and proximity-sensor geometry (pub/sub with
    /// history, slice of [`crate::RobotInfo`]), republished when the set of robots changes.
    pub const ROBOT_INFO: &str = "robot-info";
    /// `iwsim bench latency`'s raw ping-pong, driver to peer: pub/sub of [`crate::Ping`], and
    /// its doorbell (event) under the same name.
    pub const BENCH_PING: &str = "ping";
    /// `iwsim bench latency`'s raw ping-pong, peer to driver: pub/sub of the ping's `seq` as
    /// `u64`, and its doorbell (event) under the same name.
    pub const BENCH_PONG: &str = "pong";
}

/// A name in a fixed buffer: UTF-8, zero-padded, at most `NAME_BYTES − 1` bytes.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::FixedName.v2")]
pub struct FixedName {
    /// The bytes, zero-padded.
    pub bytes: [u8; NAME_BYTES],
}
const _: () = assert!(core::mem::size_of::<FixedName>() == 256);
const _: () = assert!(core::mem::align_of::<FixedName>() == 1);

impl FixedName {
    /// The empty name.
    pub const EMPTY: FixedName = FixedName { bytes: [0; NAME_BYTES] };

    /// A name, or `None` when it is longer than `NAME_BYTES − 1` bytes or holds a zero byte.
    pub fn new(name: &str) -> Option<Self> {
        let b = name.as_bytes();
        if b.len() >= NAME_BYTES || b.contains(&0) {
            return None;
        }
        let mut bytes = [0; NAME_BYTES];
        bytes[..b.len()].copy_from_slice(b);
        Some(Self { bytes })
    }

    /// The name cut to fit: at its first zero byte, then to at most `NAME_BYTES − 1` bytes at
    /// a character boundary, so a long name arrives shortened rather than empty.
    pub fn truncated(name: &str) -> Self {
        let name = name.split('\0').next().unwrap_or_default();
        let mut end = name.len().min(NAME_BYTES - 1);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        Self::new(name.get(..end).unwrap_or_default()).unwrap_or(Self::EMPTY)
    }

    /// The name, or `None` when the buffer does not hold UTF-8 (it came from outside).
    pub fn as_str(&self) -> Option<&str> {
        let len = self.bytes.iter().position(|&b| b == 0).unwrap_or(NAME_BYTES);
        core::str::from_utf8(&self.bytes[..len]).ok()
    }
}

impl Default for FixedName {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl core::fmt::Debug for FixedName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:?}", self.as_str().unwrap_or("<not utf-8>"))
    }
}

/// How a robot moves (`RobotState::kind`, `RobotRegistration::kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RobotKind {
    /// Moved by the hub from its motor powers.
    Simulated = 0,
    /// A physical chair whose agent pushes its pose.
    Real = 1,
    /// A door, driven like any robot.
    Door = 2,
}

impl RobotKind {
    /// The kind a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Simulated),
            1 => Some(Self::Real),
            2 => Some(Self::Door),
            _ => None,
        }
    }
}

/// The run's state (`WorldHeader::run_state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RunState {
    /// Waiting for agents or a start command; nothing moves.
    Waiting = 0,
    /// Stepping.
    Running = 1,
    /// Paused by a command; nothing moves.
    Paused = 2,
    /// The run is over (time limit or stop); the hub is shutting down.
    Finished = 3,
}

impl RunState {
    /// The state a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Waiting),
            1 => Some(Self::Running),
            2 => Some(Self::Paused),
            3 => Some(Self::Finished),
            _ => None,
        }
    }
}

/// The header of every world snapshot.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::WorldHeader.v1")]
pub struct WorldHeader {
    /// Tick this snapshot shows (0 before the first step).
    pub tick: u64,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// The world's state hash after this tick (see `world::World::state_hash`).
    pub state_hash: u64,
    /// [`RunState`] as u32.
    pub run_state: u32,
    /// Robots in the slice that follows.
    pub robot_count: u32,
    /// Live agent processes.
    pub agent_count: u32,
    /// Whether the hub steps in lock-step (1) or real time (0).
    pub lockstep: u32,
}
const _: () = assert!(core::mem::size_of::<WorldHeader>() == 40);
const _: () = assert!(core::mem::align_of::<WorldHeader>() == 8);

/// `RobotState::flags`: the last move was refused (or a Real robot overlaps something).
pub const ROBOT_COLLISION: u32 = 1;
/// `RobotState::flags`: the robot's agent died; the robot is frozen.
pub const ROBOT_FROZEN: u32 = 1 << 1;
/// `RobotState::flags`: the robot's agent missed the lock-step deadline this tick.
pub const ROBOT_LAGGING: u32 = 1 << 2;
/// `RobotState::flags`: the body is a disc of diameter `width_m` centred on (`x_m`, `y_m`)
/// (a plain Ciber-Rato robot); otherwise a `width_m` × `height_m` rectangle placed by `com`.
pub const ROBOT_DISC: u32 = 1 << 3;

/// A robot's standing in the run's Ciber-Rato challenge (the scoring mode is
/// [`HubParams::scoring_mode`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::ChallengeStanding.v1")]
pub struct ChallengeStanding {
    /// Its state, numbered as Ciber-Rato's: 0 Stopped, 1 Running, 2 Waiting, 3 Returning,
    /// 4 Finished, 5 Removed (a Finished robot stands still for the rest of the run).
    pub phase: u32,
    /// Its score.
    pub score: i32,
    /// Competitive mode: the tick it arrived (the clock until its first visit).
    pub arrival_tick: u32,
    /// Competitive mode: ticks since its return began.
    pub returning_ticks: u32,
    /// Collision events: contacts begun while it was scored.
    pub collisions: u32,
    /// Padding.
    pub _reserved: u32,
    /// Bit `k` set once target `k` (in lab order) has been visited.
    pub visited_mask: u64,
}
const _: () = assert!(core::mem::size_of::<ChallengeStanding>() == 32);
const _: () = assert!(core::mem::align_of::<ChallengeStanding>() == 8);

/// One robot in a world snapshot.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::RobotState.v5")]
pub struct RobotState {
    /// Robot id (1-based, unique in the run).
    pub id: u32,
    /// [`RobotKind`] as u32.
    pub kind: u32,
    /// `ROBOT_*` flags.
    pub flags: u32,
    /// Contacts so far.
    pub collision_count: u32,
    /// Centre of movement x, metres.
    pub x_m: f64,
    /// Centre of movement y, metres.
    pub y_m: f64,
    /// Heading, degrees in (−180, 180].
    pub heading_deg: f64,
    /// Length along the heading, metres; a disc's diameter (with [`ROBOT_DISC`]).
    pub width_m: f32,
    /// Size across the heading, metres; a disc's diameter again.
    pub height_m: f32,
    /// Where the wheel axis sits along the length, (0, 1).
    pub com: f32,
    /// Owning agent's id.
    pub agent_id: u32,
    /// Motor outputs, left and right, in [−1, 1].
    pub motor_out: [f32; 2],
    /// The proximity readings the robot's agent got this tick, metres (noise included);
    /// NaN past the robot's sensor count. Viewers draw the cones with these.
    pub proximity_m: [f32; MAX_PROXIMITY],
    /// Its standing in the challenge (its phase as shown: Stopped while the run waits or is
    /// paused).
    pub standing: ChallengeStanding,
}
const _: () = assert!(core::mem::size_of::<RobotState>() == 128);
const _: () = assert!(core::mem::align_of::<RobotState>() == 8);

/// One proximity sensor's geometry, as viewers draw it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::SensorGeometry.v1")]
pub struct SensorGeometry {
    /// Position along the heading from the centre of movement, metres.
    pub x_m: f32,
    /// Position across the heading (left positive), metres.
    pub y_m: f32,
    /// Direction relative to the heading, degrees.
    pub angle_deg: f32,
    /// Full opening, degrees.
    pub cone_deg: f32,
    /// Readings are capped at this distance, metres.
    pub range_m: f32,
}
const _: () = assert!(core::mem::size_of::<SensorGeometry>() == 20);
const _: () = assert!(core::mem::align_of::<SensorGeometry>() == 4);

/// What does not change about a robot while it is in the run: its name and its proximity
/// sensors. The hub publishes every robot's, with history, whenever the set of robots
/// changes, so the world snapshot stays small.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::RobotInfo.v1")]
pub struct RobotInfo {
    /// Robot id.
    pub robot_id: u32,
    /// Sensors in use.
    pub count: u32,
    /// The sensors, in the robot's order (its readings follow it).
    pub sensors: [SensorGeometry; MAX_PROXIMITY],
    /// Name, whole.
    pub name: FixedName,
}
const _: () = assert!(core::mem::size_of::<RobotInfo>() == 424);
const _: () = assert!(core::mem::align_of::<RobotInfo>() == 4);

impl RobotInfo {
    /// The info of robot `id` among `infos`, looked for at `index` first: the hub publishes
    /// the infos in the world snapshot's robot order, so a snapshot's `k`-th robot is usually
    /// the `k`-th info; a subscriber that caught the two at different moments searches.
    pub fn find(infos: &[RobotInfo], index: usize, id: u32) -> Option<&RobotInfo> {
        match infos.get(index) {
            Some(i) if i.robot_id == id => Some(i),
            _ => infos.iter().find(|i| i.robot_id == id),
        }
    }
}

/// `ChairState::flags`: a live agent controls the chair.
pub const CHAIR_CONTROLLED: u32 = 1;
/// `ChairState::flags`: the adapter says its serial link to the chair is up.
pub const CHAIR_LINK_UP: u32 = 1 << 1;
/// `ChairState::flags`: `ghost` holds the chair's true pose (a test bench's).
pub const CHAIR_GHOST: u32 = 1 << 2;

/// A physical chair as observers see it (`observer/chairs`, every tick while there are
/// chairs): its sensor mode, both sets of readings, and where a test bench says it truly is,
/// so a viewer can show mixed reality and odometry drift. Never sent to agents.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::ChairState.v1")]
pub struct ChairState {
    /// Robot id.
    pub robot_id: u32,
    /// [`SensorMode`] as u32.
    pub sensor_mode: u32,
    /// `CHAIR_*` bits.
    pub flags: u32,
    /// The controlling agent's id (0 = none).
    pub controller: u32,
    /// True pose (x, y metres, heading degrees), with [`CHAIR_GHOST`].
    pub ghost: [f64; 3],
    /// The chair's real readings, metres, in the robot's sensor order: the last ones the
    /// adapter sent; NaN = none yet, +∞ = no echo.
    pub real_m: [f32; MAX_PROXIMITY],
    /// The virtual readings the hub measured on the chair's twin this tick, metres.
    pub virtual_m: [f32; MAX_PROXIMITY],
}
const _: () = assert!(core::mem::size_of::<ChairState>() == 104);
const _: () = assert!(core::mem::align_of::<ChairState>() == 8);

/// `SensorBlock::present`: compass reading present.
pub const HAS_COMPASS: u32 = 1;
/// `SensorBlock::present`: GPS reading present.
pub const HAS_GPS: u32 = 1 << 1;
/// `SensorBlock::present`: the robot is over a target (`ground` is valid).
pub const HAS_GROUND: u32 = 1 << 2;
/// `SensorBlock::present`: the robot collided.
pub const COLLISION: u32 = 1 << 3;
/// `SensorBlock::present`: `standing` holds the robot's score (the parameters' `ScoreSensor`
/// is on; without it `standing` is zero).
pub const HAS_SCORE: u32 = 1 << 4;

/// `SensorBlock::drive_flags`: a live agent controls this chair.
pub const DRIVE_CONTROLLED: u32 = 1;
/// `SensorBlock::drive_flags`: the controlling agent answered the previous tick (or this one),
/// so `drive` is current; without it the powers are stale and the adapter must stop the chair
/// once they have been for 200 ms.
pub const DRIVE_FRESH: u32 = 1 << 1;
/// `SensorBlock::drive_flags`: bits 16–31 count the operator's resume requests for this chair
/// ([`Command::ResumeChair`]), wrapping. A count, not a one-tick bit: an adapter that misses a
/// block still sees that the count moved, and a block read twice is not a second request.
pub const DRIVE_RESUMES_SHIFT: u32 = 16;

/// The operator's resume requests counted in `drive_flags` (see [`DRIVE_RESUMES_SHIFT`]).
pub fn drive_resumes(drive_flags: u32) -> u16 {
    (drive_flags >> DRIVE_RESUMES_SHIFT) as u16
}

/// One message heard: who said it and where its bytes are in `SensorBlock::inbox_bytes`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::InboxEntry.v1")]
pub struct InboxEntry {
    /// Speaker's robot id.
    pub from_id: u32,
    /// Offset in `inbox_bytes`.
    pub offset: u16,
    /// Length in bytes.
    pub len: u16,
}
const _: () = assert!(core::mem::size_of::<InboxEntry>() == 8);
const _: () = assert!(core::mem::align_of::<InboxEntry>() == 4);

/// One robot's sensor readings for one tick: only what its sensors measure (with their noise),
/// never where it truly is. True poses are for observers (the world service).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::SensorBlock.v5")]
pub struct SensorBlock {
    /// Tick these readings belong to.
    pub tick: u64,
    /// Robot id.
    pub robot_id: u32,
    /// `HAS_*` and `COLLISION` bits.
    pub present: u32,
    /// Proximity distances, metres (first `proximity_count`).
    pub proximity_m: [f64; MAX_PROXIMITY],
    /// Compass heading, degrees.
    pub compass_deg: f64,
    /// GPS x, metres.
    pub gps_x_m: f64,
    /// GPS y, metres.
    pub gps_y_m: f64,
    /// GPS heading, degrees.
    pub gps_heading_deg: f64,
    /// Bearing to each beacon relative to the heading, degrees; NaN when not visible.
    pub beacons_deg: [f64; MAX_BEACONS],
    /// Cumulative encoder ticks, left and right.
    pub encoder_ticks: [i64; 2],
    /// Contacts so far.
    pub collision_count: u32,
    /// Index of the target under the robot (valid with `HAS_GROUND`).
    pub ground: u32,
    /// Proximity sensors the robot has.
    pub proximity_count: u32,
    /// Beacons in the lab.
    pub beacon_count: u32,
    /// Messages heard (first `inbox_count` entries).
    pub inbox_count: u32,
    /// Messages dropped because the inbox was full.
    pub inbox_dropped: u32,
    /// Where each message heard is in `inbox_bytes`.
    pub inbox: [InboxEntry; MAX_INBOX_MESSAGES],
    /// The bytes of the messages heard.
    pub inbox_bytes: [u8; INBOX_BYTES],
    /// For a physical chair: the motor powers its controlling agent asks for, left and right,
    /// which the chair's adapter forwards to the chair (zero without a controller).
    pub drive: [f32; 2],
    /// `DRIVE_*` bits.
    pub drive_flags: u32,
    /// [`SensorMode`] as u32: where this block's proximity readings and encoders come from.
    pub sensor_mode: u32,
    /// The line sensor: bit `k` set when element `k` (0 = leftmost, [`LINE_ELEMENTS`] in a
    /// row 0.438 m ahead of the centre of movement, 0.24 m left to 0.24 m right) reads a line
    /// on the floor (a lab wall of height 0).
    pub line_bits: u32,
    /// Padding.
    pub _reserved: u32,
    /// With [`HAS_SCORE`]: the robot's standing in the challenge (Ciber-Rato's score sensor).
    pub standing: ChallengeStanding,
}
const _: () = assert!(core::mem::size_of::<SensorBlock>() == 864);
const _: () = assert!(core::mem::align_of::<SensorBlock>() == 8);

impl SensorBlock {
    /// The messages heard: (speaker id, bytes).
    pub fn messages(&self) -> impl Iterator<Item = (u32, &[u8])> {
        self.inbox[..(self.inbox_count as usize).min(MAX_INBOX_MESSAGES)].iter().filter_map(|e| {
            let (start, end) = (e.offset as usize, e.offset as usize + e.len as usize);
            self.inbox_bytes.get(start..end).map(|b| (e.from_id, b))
        })
    }
}

/// The header of the sensor blocks a hub sends an agent each tick.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::TickHeader.v2")]
pub struct TickHeader {
    /// The tick.
    pub tick: u64,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// [`RunState`] as u32.
    pub run_state: u32,
    /// Blocks in the slice.
    pub count: u32,
    /// CLOCK_MONOTONIC nanoseconds when the hub published this tick (for latency figures).
    pub t_pub_ns: u64,
    /// Microseconds an agent may spin for its next tick after answering this one before it
    /// sleeps: non-zero in lock-step while every agent the hub waits for can have a core of
    /// its own (then a spinning agent takes no core another process needs); 0 otherwise.
    pub spin_us: u32,
    /// [`TICK_LOCKSTEP`]; the other bits are zero (as the whole field was from hubs before it
    /// had a meaning).
    pub flags: u32,
}

/// [`TickHeader::flags`]: the hub steps only once its agents have answered (lock-step, or
/// their deadline passed); without it the next tick comes a cycle later whether an agent has
/// answered or not, and a late answer leaves the robot on its last command meanwhile.
pub const TICK_LOCKSTEP: u32 = 1;
const _: () = assert!(core::mem::size_of::<TickHeader>() == 40);
const _: () = assert!(core::mem::align_of::<TickHeader>() == 8);

/// `ActionBlock::flags`: set the motor powers.
pub const ACT_MOTORS: u32 = 1;
/// `ActionBlock::flags`: push the pose (Real robots).
pub const ACT_POSE: u32 = 1 << 1;
/// `ActionBlock::flags`: say `say_bytes[..say_len]`.
pub const ACT_SAY: u32 = 1 << 2;
/// `ActionBlock::flags` (a chair adapter's): `real_m` and `real_encoders` hold the chair's real
/// readings for this tick.
pub const ACT_REAL: u32 = 1 << 3;
/// `ActionBlock::flags` (a chair adapter's): `ghost` holds the chair's true pose as a test
/// bench knows it (the chair emulator's); observers only.
pub const ACT_GHOST: u32 = 1 << 4;
/// `ActionBlock::flags` (a chair adapter's): the serial link to the chair's board is down.
pub const ACT_LINK_DOWN: u32 = 1 << 5;
/// `ActionBlock::flags`: the end LED (Ciber-Rato `EndLed`).
pub const LED_END: u32 = 1 << 8;
/// `ActionBlock::flags`: the returning LED.
pub const LED_RETURNING: u32 = 1 << 9;
/// `ActionBlock::flags`: the visiting LED.
pub const LED_VISITING: u32 = 1 << 10;

/// What an agent asks for one robot in one tick.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::ActionBlock.v2")]
pub struct ActionBlock {
    /// Robot id.
    pub robot_id: u32,
    /// `ACT_*` and `LED_*` bits.
    pub flags: u32,
    /// Left and right motor powers in [−1, 1].
    pub motors: [f64; 2],
    /// Pushed pose of a Real robot: x, y metres, heading degrees.
    pub pose: [f64; 3],
    /// Sensors requested (a bit per sensor; used by the UDP bridge).
    pub sensor_requests: u32,
    /// Length of the message in `say_bytes`.
    pub say_len: u32,
    /// The message to say.
    pub say_bytes: [u8; MESSAGE_BYTES],
    /// Padding.
    pub _reserved: [u8; 4],
    /// A chair adapter's real range readings in the robot's sensor order, metres (with
    /// [`ACT_REAL`]): NaN = no fresh reading this tick (the hub keeps the last one), +∞ = no
    /// echo within the sensor's range.
    pub real_m: [f32; MAX_PROXIMITY],
    /// A chair adapter's real encoder counts, left and right, in the hub's encoder units
    /// (`HubParams::encoder_ticks_per_m`), with [`ACT_REAL`].
    pub real_encoders: [i64; 2],
    /// The chair's true pose (x, y metres, heading degrees) as a test bench knows it, with
    /// [`ACT_GHOST`].
    pub ghost: [f64; 3],
}
const _: () = assert!(core::mem::size_of::<ActionBlock>() == 232);
const _: () = assert!(core::mem::align_of::<ActionBlock>() == 8);

impl ActionBlock {
    /// Motor powers for a robot.
    pub fn motors(robot_id: u32, left: f64, right: f64) -> Self {
        Self { robot_id, flags: ACT_MOTORS, motors: [left, right], ..Zeroable::zeroed() }
    }

    /// A pushed pose (metres, degrees) for a Real robot.
    pub fn pose(robot_id: u32, x_m: f64, y_m: f64, heading_deg: f64) -> Self {
        Self { robot_id, flags: ACT_POSE, pose: [x_m, y_m, heading_deg], ..Zeroable::zeroed() }
    }

    /// Adds a message; `false` (and no change) when it is longer than `MESSAGE_BYTES`.
    pub fn with_say(&mut self, bytes: &[u8]) -> bool {
        if bytes.len() > MESSAGE_BYTES {
            return false;
        }
        self.say_bytes[..bytes.len()].copy_from_slice(bytes);
        self.say_len = bytes.len() as u32;
        self.flags |= ACT_SAY;
        true
    }
}

/// The header of an agent's actions for one tick.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::ActionHeader.v1")]
pub struct ActionHeader {
    /// The tick whose readings these actions answer.
    pub tick: u64,
    /// The agent.
    pub agent_id: u32,
    /// Blocks in the slice.
    pub count: u32,
}
const _: () = assert!(core::mem::size_of::<ActionHeader>() == 16);
const _: () = assert!(core::mem::align_of::<ActionHeader>() == 8);

/// One proximity sensor at registration (thesis Table 4.4).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::SensorSpec.v1")]
pub struct SensorSpec {
    /// Position along the heading from the centre of movement, metres.
    pub x_m: f64,
    /// Position across the heading (left positive), metres.
    pub y_m: f64,
    /// Direction relative to the heading, degrees.
    pub angle_deg: f64,
    /// Full opening of the cone, degrees.
    pub cone_deg: f64,
    /// Range, metres; 0 takes the hub's default.
    pub range_m: f64,
}
const _: () = assert!(core::mem::size_of::<SensorSpec>() == 40);
const _: () = assert!(core::mem::align_of::<SensorSpec>() == 8);

/// `RobotRegistration::flags`: the registration gives a start pose (else the grid slot's).
pub const REG_HAS_POSE: u32 = 1;
/// `RobotRegistration::flags`: the body is a disc of diameter `width_m` turning about its
/// centre (`height_m` and `com` are then ignored): a plain Ciber-Rato robot.
pub const REG_DISC: u32 = 1 << 1;

/// `RobotRegistration::flags`: the registrant is a chair adapter (`iwsim serial`): the robot is
/// a physical chair (kind Real) whose pose and real readings the adapter pushes, and whose
/// motor powers come from the agent that registers a robot of the same name after it (the
/// controlling agent, which attaches to it instead of adding a robot).
pub const REG_CHAIR: u32 = 1 << 2;
/// `RobotRegistration::flags`: the chair's sensor mode is *real*: its controlling agent gets the
/// chair's real proximity readings and encoders, not the virtual ones. Given by the adapter, or
/// by the controlling agent when it attaches (which then overrides the adapter's).
pub const REG_SENSORS_REAL: u32 = 1 << 3;
/// `RobotRegistration::flags`: the chair's sensor mode is *augmented*: per sensor, the nearer of
/// the real and the virtual reading (thesis §5.4.3), and the chair's real encoders.
pub const REG_SENSORS_AUGMENTED: u32 = 1 << 4;

/// Where a physical chair's controlling agent gets its readings from (thesis §5.4.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u32)]
pub enum SensorMode {
    /// The hub's virtual sensors on the chair's twin (the pose the adapter pushes).
    #[default]
    Virtual = 0,
    /// The chair's own sensors and encoders.
    Real = 1,
    /// Per sensor the nearer of real and virtual; the chair's encoders.
    Augmented = 2,
}

impl SensorMode {
    /// The mode a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Virtual),
            1 => Some(Self::Real),
            2 => Some(Self::Augmented),
            _ => None,
        }
    }

    /// The mode registration `flags` ask for, or `None` when they ask for none (or for both).
    pub fn from_reg_flags(flags: u32) -> Option<Self> {
        match (flags & REG_SENSORS_REAL != 0, flags & REG_SENSORS_AUGMENTED != 0) {
            (true, false) => Some(Self::Real),
            (false, true) => Some(Self::Augmented),
            _ => None,
        }
    }

    /// The registration flag bits that ask for this mode.
    pub fn reg_flags(self) -> u32 {
        match self {
            Self::Virtual => 0,
            Self::Real => REG_SENSORS_REAL,
            Self::Augmented => REG_SENSORS_AUGMENTED,
        }
    }
}

/// A robot as an agent registers it (thesis Tables 4.3 and 4.4).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::RobotRegistration.v3")]
pub struct RobotRegistration {
    /// Requested id = 1-based grid slot; 0 takes the first free one.
    pub requested_id: u32,
    /// [`RobotKind`] as u32.
    pub kind: u32,
    /// `REG_*` bits.
    pub flags: u32,
    /// Proximity sensors given (0 = the four defaults of thesis Table 4.5).
    pub sensor_count: u32,
    /// Length along the heading, metres.
    pub width_m: f64,
    /// Size across the heading, metres.
    pub height_m: f64,
    /// Centre of movement, (0, 1).
    pub com: f64,
    /// Top speed, m/s.
    pub max_speed_mps: f64,
    /// Motor filter coefficient, [0, 1).
    pub accel_curve: f64,
    /// Start pose: x, y metres, heading degrees (with `REG_HAS_POSE`).
    pub pose: [f64; 3],
    /// Sensors.
    pub sensors: [SensorSpec; MAX_PROXIMITY],
    /// Name.
    pub name: FixedName,
}
const _: () = assert!(core::mem::size_of::<RobotRegistration>() == 656);
const _: () = assert!(core::mem::align_of::<RobotRegistration>() == 8);

impl RobotRegistration {
    /// A simulated robot with the thesis defaults (1 m × 1 m, COM 0.5, 0.5 m/s, curve 0.5),
    /// starting at the first free grid slot. Names longer than 255 bytes are cut short.
    pub fn new(name: &str) -> Self {
        Self {
            kind: RobotKind::Simulated as u32,
            width_m: 1.0,
            height_m: 1.0,
            com: 0.5,
            max_speed_mps: 0.5,
            accel_curve: 0.5,
            name: FixedName::truncated(name),
            ..Zeroable::zeroed()
        }
    }

    /// With the rectangle `width_m` (along the heading) × `height_m` and the centre of
    /// movement `com` ∈ (0, 1) (thesis Table 4.1).
    pub fn body(mut self, width_m: f64, height_m: f64, com: f64) -> Self {
        self.flags &= !REG_DISC;
        (self.width_m, self.height_m, self.com) = (width_m, height_m, com);
        self
    }

    /// With a disc body of `diameter_m` centred on its centre of movement ([`REG_DISC`]).
    pub fn disc(mut self, diameter_m: f64) -> Self {
        self.flags |= REG_DISC;
        (self.width_m, self.height_m, self.com) = (diameter_m, diameter_m, 0.5);
        self
    }

    /// With motors of top speed `max_speed_mps` and acceleration curve `accel_curve`.
    pub fn motors(mut self, max_speed_mps: f64, accel_curve: f64) -> Self {
        (self.max_speed_mps, self.accel_curve) = (max_speed_mps, accel_curve);
        self
    }

    /// Asking for grid slot `id` (1-based; 0: the first free one).
    pub fn id(mut self, id: u32) -> Self {
        self.requested_id = id;
        self
    }

    /// Starting at `pose` (x, y metres, heading degrees) when given, else at its grid slot.
    pub fn at(mut self, pose: Option<[f64; 3]>) -> Self {
        if let Some(p) = pose {
            self.flags |= REG_HAS_POSE;
            self.pose = p;
        }
        self
    }
}

/// What an agent sends on the register service.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::RegisterRequest.v4")]
pub struct RegisterRequest {
    /// [`RegisterKind`] as u32.
    pub kind: u32,
    /// The agent's process id (the hub watches it to notice the agent's death).
    pub pid: u32,
    /// The agent id the hub gave in its welcome (0 in a hello).
    pub agent_id: u32,
    /// Padding.
    pub _reserved: u32,
    /// In a hello: the iceoryx2 id of the publisher the agent will send its actions from
    /// (`UniquePublisherId::value()`, low 64 bits first). The hub ties the agent id to it and
    /// to the client that said hello, and drops actions and requests in that agent's name
    /// from any other port.
    pub actions_publisher: [u64; 2],
    /// The robot (with `RegisterKind::Robot`).
    pub robot: RobotRegistration,
}
const _: () = assert!(core::mem::size_of::<RegisterRequest>() == 688);
const _: () = assert!(core::mem::align_of::<RegisterRequest>() == 8);

/// What a register request asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RegisterKind {
    /// A new agent process says hello and gets an agent id.
    Hello = 0,
    /// An agent registers one robot.
    Robot = 1,
    /// An agent says it has registered all its robots and is ready for tick 0.
    Ready = 2,
    /// An agent leaves; its robots are removed.
    Bye = 3,
}

impl RegisterKind {
    /// The kind a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Hello),
            1 => Some(Self::Robot),
            2 => Some(Self::Ready),
            3 => Some(Self::Bye),
            _ => None,
        }
    }
}

/// Why a registration was refused (`RegisterResponse::status`); 0 is accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Refusal {
    /// Accepted.
    Accepted = 0,
    /// The requested id is taken.
    DuplicateId = 1,
    /// The requested id is past the grid.
    NoSuchSlot = 2,
    /// No free grid slot and no pose given.
    GridFull = 3,
    /// A parameter is out of range or not a number (see `detail`).
    BadParameters = 4,
    /// The hub holds `MAX_ROBOTS` robots, or `MAX_AGENTS` agents.
    Capacity = 5,
    /// The agent id is unknown (no hello, or the agent was dropped).
    UnknownAgent = 6,
    /// The run has started and takes no new robots.
    RunStarted = 7,
    /// The request was malformed (unknown kind, bad name).
    Malformed = 8,
    /// The request names an agent id that another process's port said hello for.
    NotYours = 9,
    /// A Real robot (whose agent pushes its pose) the hub was not told to expect: only the
    /// names given to `iwsim hub --real NAME` (a scenario's real chairs) may be Real.
    NotAllowed = 10,
}

impl Refusal {
    /// The reason a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Accepted),
            1 => Some(Self::DuplicateId),
            2 => Some(Self::NoSuchSlot),
            3 => Some(Self::GridFull),
            4 => Some(Self::BadParameters),
            5 => Some(Self::Capacity),
            6 => Some(Self::UnknownAgent),
            7 => Some(Self::RunStarted),
            8 => Some(Self::Malformed),
            9 => Some(Self::NotYours),
            10 => Some(Self::NotAllowed),
            _ => None,
        }
    }
}

/// The hub's answer to a register request.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::RegisterResponse.v1")]
pub struct RegisterResponse {
    /// [`Refusal`] as u32; 0 = accepted.
    pub status: u32,
    /// The agent id (hello) or the agent's id (robot).
    pub agent_id: u32,
    /// The robot's id (robot).
    pub robot_id: u32,
    /// Proximity sensors the robot got.
    pub sensor_count: u32,
    /// The hub's process id (agents watch it to notice the hub's death).
    pub hub_pid: u32,
    /// The current tick.
    pub tick: u32,
    /// A short human-readable reason when refused (e.g. "com = 1.2 is out of range").
    pub detail: [u8; 64],
}
const _: () = assert!(core::mem::size_of::<RegisterResponse>() == 88);
const _: () = assert!(core::mem::align_of::<RegisterResponse>() == 4);

impl RegisterResponse {
    /// The detail text (empty when accepted).
    pub fn detail(&self) -> &str {
        let len = self.detail.iter().position(|&b| b == 0).unwrap_or(self.detail.len());
        core::str::from_utf8(&self.detail[..len]).unwrap_or("")
    }

    /// Sets the detail text, cut at 63 bytes on a character boundary.
    pub fn set_detail(&mut self, text: &str) {
        let mut end = text.len().min(self.detail.len() - 1);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.detail = [0; 64];
        self.detail[..end].copy_from_slice(&text.as_bytes()[..end]);
    }
}

/// Run control commands (`ControlRequest::command`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Command {
    /// Start (or resume) stepping.
    Start = 0,
    /// Pause stepping.
    Pause = 1,
    /// Step once while paused or waiting.
    Step = 2,
    /// End the run; the hub shuts down.
    Stop = 3,
    /// Remove robot `robot_id`.
    RemoveRobot = 4,
    /// The operator resumes physical chair `robot_id` after a latched stop: its adapter drives
    /// it again only on this word (or with `--auto-resume`), once every cause has cleared.
    ResumeChair = 5,
}

impl Command {
    /// The command a wire value names.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Start),
            1 => Some(Self::Pause),
            2 => Some(Self::Step),
            3 => Some(Self::Stop),
            4 => Some(Self::RemoveRobot),
            5 => Some(Self::ResumeChair),
            _ => None,
        }
    }
}

/// A run control request.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::ControlRequest.v1")]
pub struct ControlRequest {
    /// [`Command`] as u32.
    pub command: u32,
    /// Robot for `RemoveRobot`.
    pub robot_id: u32,
}
const _: () = assert!(core::mem::size_of::<ControlRequest>() == 8);
const _: () = assert!(core::mem::align_of::<ControlRequest>() == 4);

/// The hub's answer to a control request.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::ControlResponse.v1")]
pub struct ControlResponse {
    /// 0 = done, 1 = unknown command, 2 = unknown robot, 3 = not possible now.
    pub status: u32,
    /// [`RunState`] after the command.
    pub run_state: u32,
    /// The tick after the command.
    pub tick: u64,
}
const _: () = assert!(core::mem::size_of::<ControlResponse>() == 16);
const _: () = assert!(core::mem::align_of::<ControlResponse>() == 8);

/// The run's parameters as the hub has them (the UDP bridge reports them to Ciber-Rato
/// clients in its registration reply).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::HubParams.v3")]
pub struct HubParams {
    /// Proximity noise, metres.
    pub noise_proximity_m: f64,
    /// Beacon noise, degrees.
    pub noise_beacon_deg: f64,
    /// Compass noise, degrees.
    pub noise_compass_deg: f64,
    /// GPS position noise, metres.
    pub noise_gps_pos_m: f64,
    /// GPS heading noise, degrees.
    pub noise_gps_heading_deg: f64,
    /// Motor noise, percent.
    pub noise_motors_pct: f64,
    /// Beacon aperture (half-angle), radians.
    pub beacon_aperture_rad: f64,
    /// Run length in ticks (0: none).
    pub sim_time_ticks: u64,
    /// Lock-step deadline, milliseconds.
    pub deadline_ms: u32,
    /// 1 when the hub steps in lock-step.
    pub lockstep: u32,
    /// `SENSOR_*` bits of the sensors switched on.
    pub sensors_on: u32,
    /// `SENSOR_*` bits of the sensors sent only on request.
    pub requestable: u32,
    /// Sensor requests honoured per cycle.
    pub requests_per_cycle: u32,
    /// Latencies in ticks: proximity, beacon, ground, compass, collision, GPS.
    pub latency: [u32; 6],
    /// The Ciber-Rato scoring mode (`--scoring N`: 0 competitive, 1 control, 2 mapping,
    /// 3 planning, 4 line control 2022, 5 line mapping, 6 line planning, 7 line control 2023).
    pub scoring_mode: u32,
    /// Wheel-encoder ticks per metre of wheel travel (odometry needs it with the track, which
    /// is the robot's `height_m`).
    pub encoder_ticks_per_m: f64,
    /// Ciber-Rato's `KeyTime`, ticks.
    pub key_time_ticks: u64,
    /// Ciber-Rato's scoring values, in its reply's order: `ReturnTimePenalty`,
    /// `ArrivalTimePenalty`, `CollisionWallPenalty`, `CollisionRobotPenalty`, `TargetReward`,
    /// `HomeReward`.
    pub scoring: [u32; 6],
    /// `ObstacleRange` when the parameters give one, metres; 0 when they do not (sensors then
    /// get the hub's default range, and the UDP bridge gives Ciber-Rato robots the longest).
    pub obstacle_range_m: f64,
}
const _: () = assert!(core::mem::size_of::<HubParams>() == 160);
const _: () = assert!(core::mem::align_of::<HubParams>() == 8);

/// `HubParams` sensor bit: GPS.
pub const SENSOR_GPS: u32 = 1;
/// `HubParams` sensor bit: beacon sensor.
pub const SENSOR_BEACON: u32 = 1 << 1;
/// `HubParams` sensor bit: compass.
pub const SENSOR_COMPASS: u32 = 1 << 2;
/// `HubParams` sensor bit: proximity (obstacle) sensors.
pub const SENSOR_OBSTACLE: u32 = 1 << 3;
/// `HubParams` sensor bit: ground.
pub const SENSOR_GROUND: u32 = 1 << 4;
/// `HubParams` sensor bit: collision.
pub const SENSOR_COLLISION: u32 = 1 << 5;
/// `HubParams` sensor bit: the score sensor (Ciber-Rato's `ScoreSensor`).
pub const SENSOR_SCORE: u32 = 1 << 6;

/// The header of the map.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Default)]
#[type_name("iwsim::MapHeader.v5")]
pub struct MapHeader {
    /// Lab width, metres.
    pub width_m: f64,
    /// Lab height, metres.
    pub height_m: f64,
    /// Items in the slice.
    pub item_count: u32,
    /// Walls.
    pub wall_count: u32,
    /// Beacons.
    pub beacon_count: u32,
    /// Targets.
    pub target_count: u32,
    /// Grid start poses.
    pub grid_count: u32,
    /// Real-time tick period, milliseconds.
    pub cycle_ms: u32,
    /// Lab name.
    pub name: FixedName,
    /// The run's parameters.
    pub params: HubParams,
}
const _: () = assert!(core::mem::size_of::<MapHeader>() == 456);
const _: () = assert!(core::mem::align_of::<MapHeader>() == 8);

/// `MapItem::kind`: a wall starts; `a` = height in metres, `b` = corner count, `c` = 1 for a
/// scenario's obstacle (a static body placed by the run, not part of the map file), else 0;
/// `index` = wall number. Its corners follow as `MAP_CORNER` items.
pub const MAP_WALL: u32 = 1;
/// `MapItem::kind`: a wall corner; `a`, `b` = x, y metres.
pub const MAP_CORNER: u32 = 2;
/// `MapItem::kind`: a beacon; `a`, `b` = x, y, `c` = height, metres.
pub const MAP_BEACON: u32 = 3;
/// `MapItem::kind`: a target; `a`, `b` = x, y, `c` = radius, metres.
pub const MAP_TARGET: u32 = 4;
/// `MapItem::kind`: a grid start pose; `a`, `b` = x, y metres, `c` = heading degrees.
pub const MAP_GRID: u32 = 5;
/// `MapItem::kind`: a scenario checkpoint; `a`, `b` = x, y, `c` = radius, metres. Checkpoints
/// are drawn and logged; unlike targets they are not seen by the ground sensor.
pub const MAP_CHECKPOINT: u32 = 6;

/// One item of the map, so agents and viewers never parse map files.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::MapItem.v1")]
pub struct MapItem {
    /// `MAP_*`.
    pub kind: u32,
    /// Index of the wall, beacon, target or grid slot.
    pub index: u32,
    /// First value (see the kind).
    pub a: f64,
    /// Second value.
    pub b: f64,
    /// Third value.
    pub c: f64,
}
const _: () = assert!(core::mem::size_of::<MapItem>() == 32);
const _: () = assert!(core::mem::align_of::<MapItem>() == 8);

/// Bytes of a [`Ping`] after its header, so a ping is as large as a [`SensorBlock`].
pub const PING_PAYLOAD_BYTES: usize = 848;

/// The sample of `iwsim bench latency`'s raw iceoryx2 ping-pong, the baseline the hub's
/// latency is compared with. Only the benchmark sends it; it is as large as a sensor block so
/// both measurements move the same bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("iwsim::bench::Ping.v5")]
pub struct Ping {
    /// Sequence number; the peer answers with it.
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the driver published the ping.
    pub t_pub_ns: u64,
    /// Filler.
    pub payload: [u8; PING_PAYLOAD_BYTES],
}
const _: () = assert!(core::mem::size_of::<Ping>() == 864);
const _: () = assert!(core::mem::align_of::<Ping>() == 8);
const _: () = assert!(core::mem::size_of::<Ping>() == core::mem::size_of::<SensorBlock>());

/// The iceoryx2 type name of a payload type (as other processes must spell it).
pub fn type_name_of<T: ZeroCopySend>() -> &'static str {
    // The derive's `type_name` is an `unsafe fn` only because a wrong manual implementation
    // could lie about layout; the derived one just returns the attribute's string.
    #[allow(unsafe_code)]
    // SAFETY: calling the derived type_name has no preconditions; it returns a constant.
    unsafe {
        <T as ZeroCopySend>::type_name()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_payload_has_a_versioned_type_name() {
        assert_eq!(type_name_of::<WorldHeader>(), "iwsim::WorldHeader.v1");
        assert_eq!(type_name_of::<RobotState>(), "iwsim::RobotState.v5");
        assert_eq!(type_name_of::<RobotRegistration>(), "iwsim::RobotRegistration.v3");
        assert_eq!(type_name_of::<RobotInfo>(), "iwsim::RobotInfo.v1");
        assert_eq!(type_name_of::<SensorBlock>(), "iwsim::SensorBlock.v5");
        assert_eq!(type_name_of::<ActionBlock>(), "iwsim::ActionBlock.v2");
        assert_eq!(type_name_of::<ChairState>(), "iwsim::ChairState.v1");
        assert_eq!(type_name_of::<RegisterRequest>(), "iwsim::RegisterRequest.v4");
        assert_eq!(type_name_of::<MapItem>(), "iwsim::MapItem.v1");
        assert_eq!(type_name_of::<Ping>(), "iwsim::bench::Ping.v5");
        assert_eq!(type_name_of::<HubParams>(), "iwsim::HubParams.v3");
        assert_eq!(type_name_of::<MapHeader>(), "iwsim::MapHeader.v5");
    }

    #[test]
    fn names_round_trip_and_reject_what_does_not_fit() {
        let n = FixedName::new("chair-7").expect("fits");
        assert_eq!(n.as_str(), Some("chair-7"));
        assert!(FixedName::new(&"a".repeat(255)).is_some());
        assert!(FixedName::new(&"a".repeat(256)).is_none());
        assert!(FixedName::new("a\0b").is_none());
        let junk = FixedName { bytes: [0xff; NAME_BYTES] };
        assert_eq!(junk.as_str(), None);
        // Registration cuts long names at a character boundary.
        let r = RobotRegistration::new(&"é".repeat(128)); // 256 bytes
        assert_eq!(r.name.as_str(), Some("é".repeat(127).as_str()));
    }

    #[test]
    fn a_robots_info_is_found_at_its_index_or_by_search() {
        let info = |id, name: &str| RobotInfo {
            robot_id: id,
            name: FixedName::new(name).expect("fits"),
            ..Zeroable::zeroed()
        };
        let infos = [info(1, "a"), info(4, "b"), info(9, "c")];
        assert_eq!(RobotInfo::find(&infos, 1, 4).map(|i| i.name), Some(infos[1].name));
        // Out of step with the snapshot (a robot came or left between the two): searched.
        assert_eq!(RobotInfo::find(&infos, 0, 9).map(|i| i.robot_id), Some(9));
        assert_eq!(RobotInfo::find(&infos, 7, 1).map(|i| i.robot_id), Some(1));
        assert!(RobotInfo::find(&infos, 2, 5).is_none());
    }

    #[test]
    fn inbox_messages_come_back_and_bad_offsets_are_skipped() {
        let mut b = SensorBlock::zeroed();
        b.inbox_bytes[..5].copy_from_slice(b"hello");
        b.inbox_bytes[5..7].copy_from_slice(b"hi");
        b.inbox[0] = InboxEntry { from_id: 3, offset: 0, len: 5 };
        b.inbox[1] = InboxEntry { from_id: 9, offset: 5, len: 2 };
        b.inbox[2] = InboxEntry { from_id: 1, offset: 399, len: 50 };
        b.inbox_count = 3;
        let got: [(u32, &[u8]); 2] = [(3, b"hello"), (9, b"hi")];
        assert!(b.messages().eq(got.iter().copied()));
        // A count from outside is bounded by the array; the out-of-range entry is still skipped.
        b.inbox_count = 1000;
        assert_eq!(b.messages().count(), MAX_INBOX_MESSAGES - 1);
    }

    #[test]
    fn says_longer_than_a_hundred_bytes_are_refused() {
        let mut a = ActionBlock::motors(1, 0.5, 0.5);
        assert!(a.with_say(&[b'x'; 100]));
        assert!(!a.with_say(&[b'x'; 101]));
        assert_eq!(a.say_len, 100);
    }

    #[test]
    fn a_disc_registration_carries_its_flag_and_diameter() {
        let d = RobotRegistration::new("plain").disc(1.0).at(Some([3.0, 4.0, 90.0]));
        assert_eq!(d.flags, REG_DISC | REG_HAS_POSE);
        assert_eq!((d.width_m, d.height_m, d.com), (1.0, 1.0, 0.5));
        // Giving a rectangle afterwards makes it a rectangle again.
        let r = d.body(1.2, 0.7, 0.8);
        assert_eq!(r.flags, REG_HAS_POSE);
        // The flags do not collide with each other.
        assert_eq!(REG_DISC & REG_HAS_POSE, 0);
        assert_eq!(ROBOT_DISC & (ROBOT_COLLISION | ROBOT_FROZEN | ROBOT_LAGGING), 0);
    }

    #[test]
    fn wire_codes_round_trip() {
        for k in [RobotKind::Simulated, RobotKind::Real, RobotKind::Door] {
            assert_eq!(RobotKind::from_u32(k as u32), Some(k));
        }
        assert_eq!(RobotKind::from_u32(7), None);
        for c in 0..5 {
            assert_eq!(Command::from_u32(c).map(|c| c as u32), Some(c));
        }
        for r in 0..9 {
            assert_eq!(Refusal::from_u32(r).map(|r| r as u32), Some(r));
        }
        assert_eq!(RunState::from_u32(4), None);
    }
}
