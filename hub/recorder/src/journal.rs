//! The replay journal: what a run started from ([`RunStart`]) and everything the hub did to its
//! world ([`Event`]), with a compact, exact, little-endian binary codec written by hand.
//!
//! Replay must reproduce a run bit for bit, so every `f64` is stored as its raw bits (NaN
//! payloads and −0 included) and nothing is rounded or reordered. Every message starts with
//! [`CODEC_VERSION`]; decoding never panics and names the byte offset of the first thing that
//! is wrong.
//!
//! Layout (all integers little-endian):
//!
//! | item | bytes |
//! | --- | --- |
//! | `bool` | 1 (0 or 1) |
//! | `u32`, `u64`, `f64` (bits) | 4, 8, 8 |
//! | `usize` | as `u64` |
//! | `Option<T>` | 1 (0 none, 1 some), then `T` |
//! | string, bytes | `u32` length, then the bytes (strings are UTF-8) |
//! | list | `u32` count, then the items |
//! | [`RunStart`] | version, then its fields in declaration order |
//! | [`Event`] | version, a tag (see [`Event`]), then the variant's fields in order |
//!
//! ```
//! use recorder::journal::{Event, decode_event, encode_event};
//!
//! let mut bytes = Vec::new();
//! encode_event(&Event::Freeze { id: 3, frozen: true }, &mut bytes);
//! assert_eq!(decode_event(&bytes)?, Event::Freeze { id: 3, frozen: true });
//! # Ok::<(), recorder::journal::JournalDecodeError>(())
//! ```

use places::Checkpoint;
use world::map::{
    Beacon, ChallengeParams, Grid, Lab, LatencyParams, NoiseParams, Params, RequestParams, SensorSwitches, StartPose,
    Target, Wall,
};
use world::math::Pose;
use world::{BodyShape, ProximitySpec, RobotKind, RobotSpec};

/// The first byte of every journal message. Bump it when the layout changes; readers refuse
/// versions they do not know rather than misread them.
pub const CODEC_VERSION: u8 = 4;
/// The oldest version this build still reads: version 2 differs only in having no
/// [`ChallengeParams`], version 3 in having no scoring mode (their runs read with the
/// defaults, as they ran).
pub const OLDEST_CODEC_VERSION: u8 = 2;

/// What a run starts from: enough to rebuild its world exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct RunStart {
    /// The iwsim version that recorded the run.
    pub iwsim_version: String,
    /// The world's seed.
    pub seed: u64,
    /// Simulated seconds per tick.
    pub dt_s: f64,
    /// Whether the hub stepped in lock-step.
    pub lockstep: bool,
    /// Run length in ticks (0: no limit).
    pub tick_limit: u64,
    /// Tick period, milliseconds (also the recording's clock: message times are tick × this).
    pub cycle_ms: u32,
    /// Lock-step deadline, milliseconds.
    pub deadline_ms: u32,
    /// The lab, scenario obstacles included (from [`RunStart::obstacle_from`] on).
    pub lab: Lab,
    /// The parameters the world was built with.
    pub params: Params,
    /// The start poses (grid) the hub served.
    pub grid: Grid,
    /// Walls at and after this index are scenario obstacles, not the lab's own.
    pub obstacle_from: usize,
    /// The scenario's checkpoints, in route order.
    pub checkpoints: Vec<Checkpoint>,
}

/// One robot's action as the hub applied it (after deadlines and clamping).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedAction {
    /// Robot id.
    pub id: u32,
    /// Motor powers, left and right.
    pub motors: Option<[f64; 2]>,
    /// A Real robot's pushed pose.
    pub pose: Option<Pose>,
    /// A message said this tick.
    pub say: Option<Vec<u8>>,
    /// LED bits.
    pub leds: u32,
}

/// Something the hub did to its world, in the order it did it. The tag byte of each variant
/// follows its name.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Tag 1: a robot joined; `spec` carries its resolved start pose.
    AddRobot {
        /// Robot id.
        id: u32,
        /// Owning agent's id.
        agent_id: u32,
        /// What it was registered with.
        spec: RobotSpec,
    },
    /// Tag 2: a robot left.
    RemoveRobot {
        /// Robot id.
        id: u32,
    },
    /// Tag 3: a robot was frozen (its agent died) or thawed.
    Freeze {
        /// Robot id.
        id: u32,
        /// Frozen or not.
        frozen: bool,
    },
    /// Tag 4: the hub re-ordered the world's slots before the first step.
    Settle,
    /// Tag 5: one step.
    Step {
        /// The tick before the step.
        tick: u64,
        /// The actions applied, in the order the hub passed them.
        actions: Vec<RecordedAction>,
        /// `world.state_hash()` after the step.
        hash: u64,
    },
    /// Tag 6: the run ended.
    Finish {
        /// The last tick.
        tick: u64,
        /// Why (time limit, stop command, …).
        reason: String,
    },
}

const TAG_ADD: u8 = 1;
const TAG_REMOVE: u8 = 2;
const TAG_FREEZE: u8 = 3;
const TAG_SETTLE: u8 = 4;
const TAG_STEP: u8 = 5;
const TAG_FINISH: u8 = 6;

/// Why journal bytes could not be decoded. Every variant names the byte offset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JournalDecodeError {
    /// The message is empty.
    #[error("empty journal message")]
    Empty,
    /// The first byte is a codec version this build does not read.
    #[error(
        "journal codec version {found} at byte 0; this build reads versions {OLDEST_CODEC_VERSION} to {CODEC_VERSION}"
    )]
    Version {
        /// The version found.
        found: u8,
    },
    /// The message ends before a field does.
    #[error("the message ends at byte {len} inside {what} starting at byte {offset}")]
    Truncated {
        /// Where the field starts.
        offset: usize,
        /// The message length.
        len: usize,
        /// The field.
        what: &'static str,
    },
    /// A tag or flag byte has a value that means nothing.
    #[error("bad {what} byte {value} at byte {offset}")]
    BadByte {
        /// Where.
        offset: usize,
        /// Which tag or flag.
        what: &'static str,
        /// The value found.
        value: u8,
    },
    /// A length or count promises more than the rest of the message holds.
    #[error("{what} at byte {offset} claims {count} items but only {left} bytes follow")]
    TooLong {
        /// Where the length is.
        offset: usize,
        /// Which list or string.
        what: &'static str,
        /// The length written.
        count: u64,
        /// Bytes left after the length.
        left: usize,
    },
    /// A string is not UTF-8.
    #[error("{what} at byte {offset} is not UTF-8")]
    NotUtf8 {
        /// Where its bytes start.
        offset: usize,
        /// Which string.
        what: &'static str,
    },
    /// A `usize` field does not fit this machine.
    #[error("{what} at byte {offset} is {value}, beyond this machine's usize")]
    TooBig {
        /// Where.
        offset: usize,
        /// Which field.
        what: &'static str,
        /// The value written.
        value: u64,
    },
    /// Bytes are left after the message.
    #[error("{extra} bytes left over after the message ends at byte {offset}")]
    Trailing {
        /// Where the message ended.
        offset: usize,
        /// How many bytes follow.
        extra: usize,
    },
}

// ---------------------------------------------------------------------------------------------
// Encoding

/// Appends primitive values to a buffer.
struct Out<'a>(&'a mut Vec<u8>);

impl Out<'_> {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn bool(&mut self, v: bool) {
        self.0.push(u8::from(v));
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    fn usize(&mut self, v: usize) {
        self.u64(v as u64);
    }
    /// A length prefix. Lists and strings longer than u32::MAX cannot come from a world (its
    /// names, walls and robots are bounded far below), so saturating keeps the encoder total;
    /// the decoder would then report the message as truncated rather than misread it.
    fn len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }
    fn bytes(&mut self, b: &[u8]) {
        self.len(b.len());
        self.0.extend_from_slice(b);
    }
    fn str(&mut self, s: &str) {
        self.bytes(s.as_bytes());
    }
    fn point(&mut self, x: f64, y: f64) {
        self.f64(x);
        self.f64(y);
    }
    fn pose(&mut self, p: &Pose) {
        let Pose { x, y, theta } = *p;
        self.f64(x);
        self.f64(y);
        self.f64(theta);
    }
}

fn put_lab(o: &mut Out, lab: &Lab) {
    let Lab { name, width_m, height_m, walls, beacons, targets } = lab;
    o.str(name);
    o.f64(*width_m);
    o.f64(*height_m);
    o.len(walls.len());
    for Wall { height_m, corners } in walls {
        o.f64(*height_m);
        o.len(corners.len());
        for c in corners {
            o.point(c.x, c.y);
        }
    }
    o.len(beacons.len());
    for Beacon { pos, height_m } in beacons {
        o.point(pos.x, pos.y);
        o.f64(*height_m);
    }
    o.len(targets.len());
    for Target { pos, radius_m } in targets {
        o.point(pos.x, pos.y);
        o.f64(*radius_m);
    }
}

fn put_params(o: &mut Out, p: &Params) {
    let Params {
        sim_time_ticks,
        cycle_ms,
        noise,
        latency,
        sensors,
        requests,
        beacon_aperture_rad,
        proximity_range_m,
        message_range_m,
        encoder_ticks_per_rev,
        wheel_radius_m,
        challenge,
    } = p;
    let NoiseParams {
        proximity_m,
        beacon_deg,
        compass_deg,
        gps_pos_m,
        gps_heading_deg,
        motor_frac,
        encoder_slip_frac,
        line_flip_prob,
    } = noise;
    let LatencyParams { proximity, beacon, ground, compass, collision, gps } = latency;
    let SensorSwitches { gps: gps_on, beacon: beacon_on, compass: compass_on } = sensors;
    let RequestParams {
        per_cycle,
        obstacle: req_obstacle,
        beacon: req_beacon,
        ground: req_ground,
        compass: req_compass,
        collision: req_collision,
    } = requests;
    o.u64(*sim_time_ticks);
    o.u32(*cycle_ms);
    for v in [proximity_m, beacon_deg, compass_deg, gps_pos_m, gps_heading_deg, motor_frac, encoder_slip_frac] {
        o.f64(*v);
    }
    for v in [proximity, beacon, ground, compass, collision, gps] {
        o.u32(*v);
    }
    for v in [gps_on, beacon_on, compass_on] {
        o.bool(*v);
    }
    o.u32(*per_cycle);
    for v in [req_obstacle, req_beacon, req_ground, req_compass, req_collision] {
        o.bool(*v);
    }
    o.f64(*beacon_aperture_rad);
    o.bool(proximity_range_m.is_some());
    o.f64(proximity_range_m.unwrap_or(0.0));
    o.f64(*message_range_m);
    o.u32(*encoder_ticks_per_rev);
    o.f64(*wheel_radius_m);
    let ChallengeParams {
        key_time_ticks,
        score_sensor,
        return_time_penalty,
        arrival_time_penalty,
        collision_wall_penalty,
        collision_robot_penalty,
        target_reward,
        home_reward,
        scoring,
    } = challenge;
    o.u64(*key_time_ticks);
    o.bool(*score_sensor);
    for v in [
        return_time_penalty,
        arrival_time_penalty,
        collision_wall_penalty,
        collision_robot_penalty,
        target_reward,
        home_reward,
    ] {
        o.u32(*v);
    }
    o.f64(*line_flip_prob);
    o.u8(scoring.number() as u8);
}

fn kind_byte(kind: RobotKind) -> u8 {
    match kind {
        RobotKind::Simulated => 0,
        RobotKind::Real => 1,
        RobotKind::Door => 2,
    }
}

fn shape_byte(shape: BodyShape) -> u8 {
    match shape {
        BodyShape::Rectangle => 0,
        BodyShape::Disc => 1,
    }
}

fn put_spec(o: &mut Out, spec: &RobotSpec) {
    let RobotSpec { name, kind, shape, width_m, height_m, com, max_speed_mps, accel_curve, pose, sensors } = spec;
    o.str(name);
    o.u8(kind_byte(*kind));
    o.u8(shape_byte(*shape));
    for v in [width_m, height_m, com, max_speed_mps, accel_curve] {
        o.f64(*v);
    }
    o.pose(pose);
    o.len(sensors.len());
    for ProximitySpec { x_m, y_m, angle_rad, cone_rad, range_m } in sensors {
        for v in [x_m, y_m, angle_rad, cone_rad] {
            o.f64(*v);
        }
        o.bool(range_m.is_some());
        if let Some(r) = range_m {
            o.f64(*r);
        }
    }
}

fn put_action(o: &mut Out, a: &RecordedAction) {
    let RecordedAction { id, motors, pose, say, leds } = a;
    o.u32(*id);
    o.bool(motors.is_some());
    if let Some([l, r]) = motors {
        o.f64(*l);
        o.f64(*r);
    }
    o.bool(pose.is_some());
    if let Some(p) = pose {
        o.pose(p);
    }
    o.bool(say.is_some());
    if let Some(s) = say {
        o.bytes(s);
    }
    o.u32(*leds);
}

/// Appends the encoding of a [`RunStart`] to `out`.
pub fn encode_run_start(start: &RunStart, out: &mut Vec<u8>) {
    let RunStart {
        iwsim_version,
        seed,
        dt_s,
        lockstep,
        tick_limit,
        cycle_ms,
        deadline_ms,
        lab,
        params,
        grid,
        obstacle_from,
        checkpoints,
    } = start;
    let mut o = Out(out);
    o.u8(CODEC_VERSION);
    o.str(iwsim_version);
    o.u64(*seed);
    o.f64(*dt_s);
    o.bool(*lockstep);
    o.u64(*tick_limit);
    o.u32(*cycle_ms);
    o.u32(*deadline_ms);
    put_lab(&mut o, lab);
    put_params(&mut o, params);
    let Grid { poses } = grid;
    o.len(poses.len());
    for StartPose { pos, heading_deg } in poses {
        o.point(pos.x, pos.y);
        o.f64(*heading_deg);
    }
    o.usize(*obstacle_from);
    o.len(checkpoints.len());
    for Checkpoint { x, y, radius } in checkpoints {
        o.f64(*x);
        o.f64(*y);
        o.f64(*radius);
    }
}

/// Appends the encoding of an [`Event`] to `out` (the caller clears it to reuse a buffer).
pub fn encode_event(event: &Event, out: &mut Vec<u8>) {
    let mut o = Out(out);
    o.u8(CODEC_VERSION);
    match event {
        Event::AddRobot { id, agent_id, spec } => {
            o.u8(TAG_ADD);
            o.u32(*id);
            o.u32(*agent_id);
            put_spec(&mut o, spec);
        }
        Event::RemoveRobot { id } => {
            o.u8(TAG_REMOVE);
            o.u32(*id);
        }
        Event::Freeze { id, frozen } => {
            o.u8(TAG_FREEZE);
            o.u32(*id);
            o.bool(*frozen);
        }
        Event::Settle => o.u8(TAG_SETTLE),
        Event::Step { tick, actions, hash } => {
            o.u8(TAG_STEP);
            o.u64(*tick);
            o.len(actions.len());
            for a in actions {
                put_action(&mut o, a);
            }
            o.u64(*hash);
        }
        Event::Finish { tick, reason } => {
            o.u8(TAG_FINISH);
            o.u64(*tick);
            o.str(reason);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Decoding

/// Reads primitive values, tracking the offset for error messages.
struct In<'a> {
    buf: &'a [u8],
    pos: usize,
    /// The message's codec version.
    version: u8,
}

type R<T> = Result<T, JournalDecodeError>;

impl<'a> In<'a> {
    /// Starts a message: checks the version byte.
    fn start(buf: &'a [u8]) -> R<Self> {
        match buf.first() {
            None => Err(JournalDecodeError::Empty),
            Some(&version) if (OLDEST_CODEC_VERSION..=CODEC_VERSION).contains(&version) => {
                Ok(Self { buf, pos: 1, version })
            }
            Some(&found) => Err(JournalDecodeError::Version { found }),
        }
    }

    fn take(&mut self, n: usize, what: &'static str) -> R<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        match end.and_then(|e| self.buf.get(self.pos..e)) {
            Some(s) => {
                self.pos += n;
                Ok(s)
            }
            None => Err(JournalDecodeError::Truncated { offset: self.pos, len: self.buf.len(), what }),
        }
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> R<[u8; N]> {
        let s = self.take(N, what)?;
        let mut a = [0; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    fn u8(&mut self, what: &'static str) -> R<u8> {
        Ok(self.array::<1>(what)?[0])
    }
    fn bool(&mut self, what: &'static str) -> R<bool> {
        let offset = self.pos;
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            value => Err(JournalDecodeError::BadByte { offset, what, value }),
        }
    }
    fn u32(&mut self, what: &'static str) -> R<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    fn u64(&mut self, what: &'static str) -> R<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    fn f64(&mut self, what: &'static str) -> R<f64> {
        Ok(f64::from_bits(self.u64(what)?))
    }
    fn usize(&mut self, what: &'static str) -> R<usize> {
        let offset = self.pos;
        let value = self.u64(what)?;
        usize::try_from(value).map_err(|_| JournalDecodeError::TooBig { offset, what, value })
    }
    /// A count of items at least `min_item` bytes each, checked against what is left so that a
    /// corrupt count cannot make the decoder allocate gigabytes.
    fn count(&mut self, what: &'static str, min_item: usize) -> R<usize> {
        let offset = self.pos;
        let count = self.u32(what)?;
        let left = self.buf.len() - self.pos;
        let n = count as usize;
        if n.saturating_mul(min_item.max(1)) > left {
            return Err(JournalDecodeError::TooLong { offset, what, count: u64::from(count), left });
        }
        Ok(n)
    }
    fn bytes(&mut self, what: &'static str) -> R<Vec<u8>> {
        let n = self.count(what, 1)?;
        Ok(self.take(n, what)?.to_vec())
    }
    fn string(&mut self, what: &'static str) -> R<String> {
        let n = self.count(what, 1)?;
        let offset = self.pos;
        let b = self.take(n, what)?;
        std::str::from_utf8(b).map(str::to_owned).map_err(|_| JournalDecodeError::NotUtf8 { offset, what })
    }
    /// A lab point's coordinates.
    fn xy(&mut self, what: &'static str) -> R<(f64, f64)> {
        Ok((self.f64(what)?, self.f64(what)?))
    }
    fn pose(&mut self, what: &'static str) -> R<Pose> {
        // Built field by field, not with Pose::new, which would re-wrap the heading.
        Ok(Pose { x: self.f64(what)?, y: self.f64(what)?, theta: self.f64(what)? })
    }
    fn end(self) -> R<()> {
        let extra = self.buf.len() - self.pos;
        if extra == 0 { Ok(()) } else { Err(JournalDecodeError::Trailing { offset: self.pos, extra }) }
    }
}

/// A lab point. `Pose::position` builds the world's point type, so this crate need not name (or
/// depend on) the linear-algebra crate behind it; x and y are copied unchanged.
macro_rules! point {
    ($i:expr, $what:expr) => {{
        let (x, y) = $i.xy($what)?;
        Pose { x, y, theta: 0.0 }.position()
    }};
}

fn get_lab(i: &mut In) -> R<Lab> {
    let name = i.string("lab name")?;
    let width_m = i.f64("lab width")?;
    let height_m = i.f64("lab height")?;
    let n = i.count("wall list", 12)?;
    let mut walls = Vec::with_capacity(n);
    for _ in 0..n {
        let height_m = i.f64("wall height")?;
        let m = i.count("wall corners", 16)?;
        let mut corners = Vec::with_capacity(m);
        for _ in 0..m {
            corners.push(point!(i, "wall corner"));
        }
        walls.push(Wall { height_m, corners });
    }
    let n = i.count("beacon list", 24)?;
    let mut beacons = Vec::with_capacity(n);
    for _ in 0..n {
        beacons.push(Beacon { pos: point!(i, "beacon position"), height_m: i.f64("beacon height")? });
    }
    let n = i.count("target list", 24)?;
    let mut targets = Vec::with_capacity(n);
    for _ in 0..n {
        targets.push(Target { pos: point!(i, "target position"), radius_m: i.f64("target radius")? });
    }
    Ok(Lab { name, width_m, height_m, walls, beacons, targets })
}

fn get_params(i: &mut In) -> R<Params> {
    let sim_time_ticks = i.u64("sim time")?;
    let cycle_ms = i.u32("cycle time")?;
    let noise = NoiseParams {
        proximity_m: i.f64("noise")?,
        beacon_deg: i.f64("noise")?,
        compass_deg: i.f64("noise")?,
        gps_pos_m: i.f64("noise")?,
        gps_heading_deg: i.f64("noise")?,
        motor_frac: i.f64("noise")?,
        encoder_slip_frac: i.f64("noise")?,
        // Read after the challenge parameters (version 3 on); no line sensor before.
        line_flip_prob: 0.0,
    };
    let latency = LatencyParams {
        proximity: i.u32("latency")?,
        beacon: i.u32("latency")?,
        ground: i.u32("latency")?,
        compass: i.u32("latency")?,
        collision: i.u32("latency")?,
        gps: i.u32("latency")?,
    };
    let sensors = SensorSwitches {
        gps: i.bool("sensor switch")?,
        beacon: i.bool("sensor switch")?,
        compass: i.bool("sensor switch")?,
    };
    let requests = RequestParams {
        per_cycle: i.u32("requests per cycle")?,
        obstacle: i.bool("request switch")?,
        beacon: i.bool("request switch")?,
        ground: i.bool("request switch")?,
        compass: i.bool("request switch")?,
        collision: i.bool("request switch")?,
    };
    let mut params = Params {
        sim_time_ticks,
        cycle_ms,
        noise,
        latency,
        sensors,
        requests,
        beacon_aperture_rad: i.f64("beacon aperture")?,
        proximity_range_m: if i.version >= 3 {
            let given = i.bool("proximity range flag")?;
            let range = i.f64("proximity range")?;
            given.then_some(range)
        } else {
            // Version 2 always wrote the range, the default included.
            Some(i.f64("proximity range")?)
        },
        message_range_m: i.f64("message range")?,
        encoder_ticks_per_rev: i.u32("encoder ticks")?,
        wheel_radius_m: i.f64("wheel radius")?,
        challenge: if i.version >= 3 { get_challenge(i)? } else { ChallengeParams::default() },
    };
    if i.version >= 3 {
        params.noise.line_flip_prob = i.f64("line sensor noise")?;
    }
    if i.version >= 4 {
        let offset = i.pos;
        let value = i.u8("scoring mode")?;
        params.challenge.scoring = world::challenge::Scoring::from_number(u32::from(value))
            .map_err(|_| JournalDecodeError::BadByte { offset, what: "scoring mode", value })?;
    }
    Ok(params)
}

fn get_challenge(i: &mut In) -> R<ChallengeParams> {
    Ok(ChallengeParams {
        key_time_ticks: i.u64("key time")?,
        score_sensor: i.bool("score sensor switch")?,
        return_time_penalty: i.u32("scoring value")?,
        arrival_time_penalty: i.u32("scoring value")?,
        collision_wall_penalty: i.u32("scoring value")?,
        collision_robot_penalty: i.u32("scoring value")?,
        target_reward: i.u32("scoring value")?,
        home_reward: i.u32("scoring value")?,
        // Read last (version 4 on).
        scoring: world::challenge::Scoring::Competitive,
    })
}

fn get_spec(i: &mut In) -> R<RobotSpec> {
    let name = i.string("robot name")?;
    let offset = i.pos;
    let kind = match i.u8("robot kind")? {
        0 => RobotKind::Simulated,
        1 => RobotKind::Real,
        2 => RobotKind::Door,
        value => return Err(JournalDecodeError::BadByte { offset, what: "robot kind", value }),
    };
    let offset = i.pos;
    let shape = match i.u8("robot shape")? {
        0 => BodyShape::Rectangle,
        1 => BodyShape::Disc,
        value => return Err(JournalDecodeError::BadByte { offset, what: "robot shape", value }),
    };
    let width_m = i.f64("robot width")?;
    let height_m = i.f64("robot height")?;
    let com = i.f64("robot com")?;
    let max_speed_mps = i.f64("robot max speed")?;
    let accel_curve = i.f64("robot acceleration curve")?;
    let pose = i.pose("robot pose")?;
    let n = i.count("sensor list", 33)?;
    let mut sensors = Vec::with_capacity(n);
    for _ in 0..n {
        let x_m = i.f64("sensor")?;
        let y_m = i.f64("sensor")?;
        let angle_rad = i.f64("sensor")?;
        let cone_rad = i.f64("sensor")?;
        let range_m = if i.bool("sensor range flag")? { Some(i.f64("sensor range")?) } else { None };
        sensors.push(ProximitySpec { x_m, y_m, angle_rad, cone_rad, range_m });
    }
    Ok(RobotSpec { name, kind, shape, width_m, height_m, com, max_speed_mps, accel_curve, pose, sensors })
}

fn get_action(i: &mut In) -> R<RecordedAction> {
    let id = i.u32("action robot id")?;
    let motors = if i.bool("motors flag")? { Some([i.f64("motor")?, i.f64("motor")?]) } else { None };
    let pose = if i.bool("pose flag")? { Some(i.pose("pushed pose")?) } else { None };
    let say = if i.bool("message flag")? { Some(i.bytes("message")?) } else { None };
    let leds = i.u32("leds")?;
    Ok(RecordedAction { id, motors, pose, say, leds })
}

/// Decodes a [`RunStart`] written by [`encode_run_start`].
pub fn decode_run_start(buf: &[u8]) -> Result<RunStart, JournalDecodeError> {
    let mut i = In::start(buf)?;
    let iwsim_version = i.string("iwsim version")?;
    let seed = i.u64("seed")?;
    let dt_s = i.f64("dt")?;
    let lockstep = i.bool("lockstep flag")?;
    let tick_limit = i.u64("tick limit")?;
    let cycle_ms = i.u32("cycle time")?;
    let deadline_ms = i.u32("deadline")?;
    let lab = get_lab(&mut i)?;
    let params = get_params(&mut i)?;
    let n = i.count("grid", 24)?;
    let mut poses = Vec::with_capacity(n);
    for _ in 0..n {
        poses.push(StartPose { pos: point!(i, "grid position"), heading_deg: i.f64("grid heading")? });
    }
    let grid = Grid { poses };
    let obstacle_from = i.usize("obstacle index")?;
    let n = i.count("checkpoint list", 24)?;
    let mut checkpoints = Vec::with_capacity(n);
    for _ in 0..n {
        checkpoints.push(Checkpoint { x: i.f64("checkpoint")?, y: i.f64("checkpoint")?, radius: i.f64("checkpoint")? });
    }
    i.end()?;
    Ok(RunStart {
        iwsim_version,
        seed,
        dt_s,
        lockstep,
        tick_limit,
        cycle_ms,
        deadline_ms,
        lab,
        params,
        grid,
        obstacle_from,
        checkpoints,
    })
}

/// Decodes an [`Event`] written by [`encode_event`].
pub fn decode_event(buf: &[u8]) -> Result<Event, JournalDecodeError> {
    let mut i = In::start(buf)?;
    let offset = i.pos;
    let event = match i.u8("event tag")? {
        TAG_ADD => Event::AddRobot { id: i.u32("robot id")?, agent_id: i.u32("agent id")?, spec: get_spec(&mut i)? },
        TAG_REMOVE => Event::RemoveRobot { id: i.u32("robot id")? },
        TAG_FREEZE => Event::Freeze { id: i.u32("robot id")?, frozen: i.bool("frozen flag")? },
        TAG_SETTLE => Event::Settle,
        TAG_STEP => {
            let tick = i.u64("tick")?;
            // The smallest action is an id, three absent flags and the LEDs: 11 bytes.
            let n = i.count("action list", 11)?;
            let mut actions = Vec::with_capacity(n);
            for _ in 0..n {
                actions.push(get_action(&mut i)?);
            }
            Event::Step { tick, actions, hash: i.u64("state hash")? }
        }
        TAG_FINISH => Event::Finish { tick: i.u64("tick")?, reason: i.string("finish reason")? },
        value => return Err(JournalDecodeError::BadByte { offset, what: "event tag", value }),
    };
    i.end()?;
    Ok(event)
}
