//! The iwsim world model: maps, differential-drive bodies (rectangles or discs) with motors, collisions,
//! sensors, noise and robot-to-robot messages, stepped deterministically.
//!
//! The world is pure: it does no I/O, reads no clock and owns its only random generator, which
//! is seeded when the world is built. Time enters as the duration of each step. The one place
//! that reads a file is [`map::xml::read_text`].
//!
//! ```
//! use world::map::builtin;
//! use world::{Action, RobotSpec, World};
//!
//! let map = builtin::map("liacc").expect("built in");
//! let mut world = World::new(&map.lab, world::map::Params::default(), 7).expect("valid lab");
//! let chair = world.add_robot(RobotSpec::at(10.0, 6.1, 0.0)).expect("free start");
//! for _ in 0..10 {
//!     world.step(&[Action::motors(chair, 1.0, 1.0)], 0.1);
//! }
//! assert!(world.robot(chair).expect("alive").pose.x > 10.0);
//! ```
//!
//! The world: robots on a lab, stepped by [`World::step`] with the tick's actions and duration.
//!
//! A tick runs in phases over all robots in slot order, so the result never depends on the
//! order actions arrive in, and a seed fixes every random draw:
//!
//! 1. actions: motor inputs, pushed poses (Real robots), messages to say;
//! 2. motors and kinematics: the filtered powers give each robot its *next* pose;
//! 3. collisions: a next pose that meets a wall or another body (at its current or next pose)
//!    is refused and the robot stays put; Real robots are never refused, only flagged;
//! 4. commit, messages, then sensors (with noise and latency) on the new poses.

#![warn(missing_docs)]

pub mod challenge;
mod geom;
pub mod map;
pub mod math;
pub mod rng;

mod body;
mod collide;
mod grid;
mod readings;
mod sensors;

use std::collections::VecDeque;

use nalgebra::{Point2, Vector2};
use thiserror::Error;

pub use body::{
    AddRobotError, BodyShape, MAX_BODY_M, MAX_NAME_LEN, MAX_PROXIMITY, MAX_SENSOR_RANGE_M, MAX_SPEED_MPS, MAX_STEP_M,
    ProximitySpec, RobotKind, RobotSpec, max_speed_mps,
};
pub use grid::StaticBuildError;
pub use readings::{
    GpsReading, Heard, LINE_ELEMENTS, MAX_BEACONS, MAX_INBOX_BYTES, MAX_MESSAGE_BYTES, Message, MessageTooLong,
    SensorReadings, line_element,
};

use crate::geom::PlacedBody;
use crate::map::{Lab, Params};
use crate::math::{Pose, Real};
use crate::rng::{Draw, Rng};
use body::{BodyGeom, PreparedSensor};
use grid::{DynGrid, GridSpec, StaticIndex};

/// How many robots a world holds unless told otherwise (the hub's capacity).
pub const DEFAULT_CAPACITY: usize = 10_000;

/// The largest lab side, metres (10 km).
///
/// Far beyond any building (the largest benchmark world, 10,000 chairs on tiled LIACC floors,
/// is about 650 m a side), and small enough that f64 positions keep a resolution near 2 pm,
/// well inside the 1 nm tolerances the geometry uses; the robot index stays below 2^32 cells.
/// A lab file asking for more is refused with its line and column.
pub const MAX_LAB_SIZE_M: Real = 10_000.0;

/// Cell size of the wall index, metres (the smallest; large labs get larger cells so that the
/// index stays within its entry budget, see `grid::StaticIndex::build`).
const STATIC_CELL_M: Real = 4.0;
/// Cell size of the robot index, metres (about one chair).
const DYN_CELL_M: Real = 2.0;

/// A robot in a world: an index and a generation, so a handle to a removed robot never
/// reaches the robot that later takes its slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RobotHandle {
    index: u32,
    generation: u32,
}

impl RobotHandle {
    /// The slot index (dense, reused after removal).
    pub fn index(&self) -> u32 {
        self.index
    }

    /// The slot's generation.
    pub fn generation(&self) -> u32 {
        self.generation
    }
}

/// What a robot's controller asks for in one tick. Fields left `None` keep their last value
/// (motor inputs persist until changed, as in Ciber-Rato).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Action {
    /// The robot.
    pub robot: RobotHandle,
    /// Left and right motor powers in [−1, 1] (clamped; NaN counts as 0).
    pub motors: Option<[Real; 2]>,
    /// The pose of a Real robot, measured by the chair itself.
    pub pose: Option<Pose>,
    /// A message to say this tick.
    pub say: Option<Message>,
}

impl Action {
    /// Sets the motor powers.
    pub fn motors(robot: RobotHandle, left: Real, right: Real) -> Self {
        Self { robot, motors: Some([left, right]), pose: None, say: None }
    }

    /// Pushes the pose of a Real robot.
    pub fn pose(robot: RobotHandle, pose: Pose) -> Self {
        Self { robot, motors: None, pose: Some(pose), say: None }
    }

    /// Says a message.
    pub fn say(robot: RobotHandle, message: Message) -> Self {
        Self { robot, motors: None, pose: None, say: Some(message) }
    }
}

/// What a tick did, for logs and counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepStats {
    /// Robots whose move was refused or that overlap something.
    pub colliding: u32,
    /// Actions naming a robot that is not in the world (ignored).
    pub unknown_robot_actions: u32,
    /// Actions with non-finite values (those values were ignored).
    pub bad_values: u32,
    /// Messages not delivered to some robot because its inbox was full.
    pub dropped_messages: u32,
    /// Poses pushed for Real robots that their bodies could not have reached since their last
    /// pose (refused: the robot stays where it was).
    pub refused_poses: u32,
}

/// How far past its top speed a Real robot's pushed pose may be (a pose measured on a physical
/// chair lags and bunches: its adapter may report two ticks' motion in one).
const PUSH_SLACK: Real = 1.5;
/// What a pushed pose may move beyond that, for odometry's own jitter.
const PUSH_MARGIN_M: Real = 0.05;
/// What a pushed heading may turn beyond that (radians, 5°).
const PUSH_MARGIN_RAD: Real = 0.087;

/// Whether a Real robot at `from` could be at `to` after `ticks` ticks of `dt` seconds: its
/// body moves at most its top speed, and turns at most as fast as its wheels at top speed in
/// opposite directions turn it. This bounds what an agent pushing poses can probe: without
/// it, a "real" robot teleported about the lab would map obstacles and other chairs with its
/// collision flag and proximity readings.
pub fn reachable_push(spec: &RobotSpec, from: &Pose, to: &Pose, ticks: u64, dt: Real) -> bool {
    let t = ticks.max(1) as Real * dt * PUSH_SLACK;
    let v = spec.max_speed_mps.max(0.0);
    let omega = 2.0 * v / spec.width_m.max(0.1);
    let turn = (to.theta - from.theta).sin().atan2((to.theta - from.theta).cos()).abs();
    (to.x - from.x).hypot(to.y - from.y) <= v * t + PUSH_MARGIN_M && turn <= omega * t + PUSH_MARGIN_RAD
}

/// Why a world could not be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum WorldBuildError {
    /// The lab's geometry is unusable.
    #[error(transparent)]
    Static(#[from] StaticBuildError),
    /// More beacons than the beacon sensor reports.
    #[error("the lab has {count} beacons; at most {max} are supported")]
    TooManyBeacons {
        /// Beacons in the lab.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// A parameter is out of range.
    #[error("parameter {name} = {value} is out of range: expected {expected}")]
    BadParam {
        /// Which parameter.
        name: &'static str,
        /// The value.
        value: Real,
        /// The allowed range.
        expected: &'static str,
    },
}

/// A robot's state as the world keeps it.
#[derive(Debug, Clone)]
pub struct Robot {
    /// What it was registered with (the start pose is in `spec.pose`).
    pub spec: RobotSpec,
    /// Current pose.
    pub pose: Pose,
    /// Motor inputs in [−1, 1], left and right.
    pub motor_in: [Real; 2],
    /// Motor outputs after the acceleration filter (and noise), left and right.
    pub motor_out: [Real; 2],
    /// The last tick's move was refused (Real robots: it overlaps something).
    pub collision: bool,
    /// This tick's refused move met a wall or the lab's border.
    pub collision_wall: bool,
    /// This tick's refused move met another body.
    pub collision_robot: bool,
    /// Rising edges of `collision`: contacts so far.
    pub collision_count: u64,
    /// The sensor readings reported this tick.
    pub readings: SensorReadings,
    /// Messages heard this tick, in the order of the speakers' slots.
    pub inbox: Vec<Heard>,
    /// A frozen robot does not move and its motors read zero (its controller is gone); it
    /// is still an obstacle and still senses.
    pub frozen: bool,
    shape: BodyGeom,
    sensors: [PreparedSensor; MAX_PROXIMITY],
    sensor_count: usize,
    /// Radius around the centre of movement that every sensor's cone stays within.
    reach: Real,
    /// Radius around the centre of movement that every sensor's origin lies within.
    sensor_radius: Real,
    /// Whether some sensor's cone is wider than 180° (measured on the scalar path, which
    /// reads the candidate segments in f64).
    any_wide: bool,
    encoder_travel: [Real; 2],
    history: VecDeque<SensorReadings>,
    say: Option<Message>,
    pushed: Option<Pose>,
    /// The tick of the robot's last accepted pushed pose (or of its arrival).
    pushed_at: u64,
}

impl Robot {
    /// The robot's rectangle corners in world coordinates, counter-clockwise from front-right
    /// (a disc's: those of the square around it, turned with the heading).
    pub fn corners(&self) -> [Point2<Real>; 4] {
        let (s, c) = self.pose.theta.sin_cos();
        self.shape.corners_ccw(&self.pose, c, s)
    }

    /// Speeds implied by the motor outputs: linear (m/s) and angular (rad/s), thesis eqs.
    /// 4.5–4.6.
    pub fn velocity(&self) -> (Real, Real) {
        sim_model::velocity(self.spec.max_speed_mps, self.spec.height_m, self.motor_out)
    }
}

#[derive(Debug, Clone)]
struct Slot {
    generation: u32,
    robot: Option<Robot>,
}

/// Per-slot data the collision phase reads for every neighbour: kept apart from `Robot` so the
/// hot loops touch a small, dense array.
#[derive(Debug, Clone, Copy)]
struct Motion {
    alive: bool,
    moving: bool,
    real: bool,
    cur: PlacedBody,
    next: PlacedBody,
    cur_min: Point2<Real>,
    cur_max: Point2<Real>,
    next_min: Point2<Real>,
    next_max: Point2<Real>,
    next_pose: Pose,
    /// Cosine and sine of the next heading.
    next_cs: (Real, Real),
}

/// Per-slot committed geometry the sensors read for every neighbour.
#[derive(Debug, Clone, Copy)]
struct Geo {
    alive: bool,
    centre: Point2<Real>,
    bound_radius: Real,
    /// A disc's radius (its centre is `centre`); 0 for a rectangle, whose edges follow.
    disc_radius: Real,
    corners: [Point2<Real>; 4],
    /// Outward normals of the edges front, left, rear, right; `normals[0]` is the heading's
    /// (cos θ, sin θ).
    normals: [Vector2<Real>; 4],
    /// 1/length² of the front/rear and the side edges.
    inv_len2: [Real; 2],
}

const DEAD_BOX: PlacedBody = PlacedBody {
    iso: nalgebra::Isometry2 {
        rotation: nalgebra::UnitComplex::new_unchecked(nalgebra::Complex { re: 1.0, im: 0.0 }),
        translation: nalgebra::Translation2 { vector: Vector2::new(0.0, 0.0) },
    },
    half: Vector2::new(0.0, 0.0),
    disc: false,
};

impl Motion {
    const DEAD: Motion = Motion {
        alive: false,
        moving: false,
        real: false,
        cur: DEAD_BOX,
        next: DEAD_BOX,
        cur_min: Point2::new(0.0, 0.0),
        cur_max: Point2::new(0.0, 0.0),
        next_min: Point2::new(0.0, 0.0),
        next_max: Point2::new(0.0, 0.0),
        next_pose: Pose { x: 0.0, y: 0.0, theta: 0.0 },
        next_cs: (1.0, 0.0),
    };
}

impl Geo {
    const DEAD: Geo = Geo {
        alive: false,
        centre: Point2::new(0.0, 0.0),
        bound_radius: 0.0,
        disc_radius: 0.0,
        corners: [Point2::new(0.0, 0.0); 4],
        normals: [Vector2::new(0.0, 0.0); 4],
        inv_len2: [0.0; 2],
    };

    fn of(robot: &Robot) -> Geo {
        let (s, c) = robot.pose.theta.sin_cos();
        Self::of_cs(robot, c, s)
    }

    /// The geometry of a robot whose heading's cosine and sine are known.
    fn of_cs(robot: &Robot, c: Real, s: Real) -> Geo {
        let heading = Vector2::new(c, s);
        let left = Vector2::new(-s, c);
        Geo {
            alive: true,
            centre: robot.pose.position(),
            bound_radius: robot.shape.bound_radius,
            disc_radius: if robot.shape.disc { robot.shape.half.x } else { 0.0 },
            corners: robot.shape.corners_ccw(&robot.pose, c, s),
            // Outward normals of the edges front, left, rear, right (corner i → i+1).
            normals: [heading, left, -heading, -left],
            inv_len2: [
                1.0 / (4.0 * robot.shape.half.y * robot.shape.half.y),
                1.0 / (4.0 * robot.shape.half.x * robot.shape.half.x),
            ],
        }
    }
}

/// Reused buffers, so a warm tick allocates nothing.
#[derive(Debug, Clone, Default)]
struct Scratch {
    /// One sensing scratch per chunk of robots (see [`World::chunking`]).
    sense: Vec<SenseScratch>,
    blocked: Vec<(u8, bool)>,
    deliveries: Vec<(u32, Real, Heard)>,
    speakers: Vec<u32>,
    listeners: Vec<u32>,
}

/// Buffers one chunk of robots is measured with.
#[derive(Debug, Clone, Default)]
struct SenseScratch {
    segments: Vec<grid::Segment>,
    local: Vec<sensors::LocalSegment>,
    /// Discs some sensor may see: centre and radius.
    discs: Vec<(Point2<Real>, Real)>,
}

/// Below this many robots a step runs on the calling thread: handing out work to threads
/// costs a few microseconds a phase, more than a small world's whole step.
pub const PARALLEL_MIN_ROBOTS: usize = 256;

/// Chunks per thread in a parallel phase: more than one, so a thread whose robots sit in an
/// empty corner takes another chunk instead of idling while a crowded one finishes.
const CHUNKS_PER_THREAD: usize = 4;

/// The most threads a world steps on (and so the most chunks a phase has).
pub const MAX_THREADS: usize = 256;
const MAX_CHUNKS: usize = MAX_THREADS * CHUNKS_PER_THREAD;

/// The key a robot's noise streams are drawn under: its slot and the slot's generation, so a
/// robot that takes a freed slot never replays its predecessor's noise.
#[inline]
fn stream_key(index: usize, generation: u32) -> u64 {
    (index as u64) << 32 | generation as u64
}

/// The noise stream of a robot's priming measurement (before the first step), from what the
/// robot is (its name and start pose), not from its slot: slots follow the order in which the
/// agents happened to register until the hub settles them at the first step, and a draw keyed
/// by slot would make one seed give two runs. The high bit keeps it apart from slot keys.
fn prime_key(r: &Robot) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |b: u8| h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    r.spec.name.bytes().for_each(&mut eat);
    for v in [r.pose.x, r.pose.y, r.pose.theta] {
        v.to_bits().to_le_bytes().into_iter().for_each(&mut eat);
    }
    h | 1 << 63
}

/// Runs `f` on matching chunks of `a` and `b` (and one scratch per chunk): on the calling thread
/// as one chunk when `pool` is `None`, else in parallel chunks of `len`. `f` gets the index of
/// its chunk's first element.
fn run_chunks<A: Send, B: Send, S: Send>(
    pool: &Chunking,
    a: &mut [A],
    b: &mut [B],
    scratch: &mut [S],
    f: impl Fn(usize, &mut [A], &mut [B], &mut S) + Sync,
) {
    debug_assert_eq!(a.len(), b.len());
    match pool {
        None => f(0, a, b, &mut scratch[0]),
        Some((pool, len)) => {
            use rayon::prelude::*;
            let len = *len;
            pool.install(|| {
                a.par_chunks_mut(len)
                    .zip(b.par_chunks_mut(len))
                    .zip(scratch.par_iter_mut())
                    .enumerate()
                    .for_each(|(k, ((a, b), s))| f(k * len, a, b, s))
            })
        }
    }
}

/// Runs `f`, a sequential part of a parallel step (on one of the pool's threads), while the
/// pool's other threads spin instead of going to sleep: a sleeping thread takes tens of
/// microseconds to wake for the next phase on a VM whose idle vCPU halts, which at 1,000 robots
/// cost a quarter of what the second thread saves.
fn sequential<R: Send>(chunking: &Chunking, f: impl FnOnce() -> R + Send) -> R {
    let Some((pool, _)) = chunking else { return f() };
    let done = std::sync::atomic::AtomicBool::new(false);
    let spin = || {
        while !done.load(std::sync::atomic::Ordering::Acquire) {
            std::hint::spin_loop();
        }
    };
    pool.install(|| {
        let (r, ()) = rayon::join(
            || {
                let r = f();
                done.store(true, std::sync::atomic::Ordering::Release);
                r
            },
            spin,
        );
        r
    })
}

/// How a step's per-robot phases are split: `None` on the calling thread, else the pool and
/// the slots per chunk (see [`World::chunking`]).
type Chunking = Option<(std::sync::Arc<rayon::ThreadPool>, usize)>;

/// Box corners (min, max) of a placed body.
fn aabb(b: &PlacedBody) -> (Point2<Real>, Point2<Real>) {
    b.aabb()
}

#[inline]
fn overlaps(amin: Point2<Real>, amax: Point2<Real>, bmin: Point2<Real>, bmax: Point2<Real>) -> bool {
    amin.x <= bmax.x && bmin.x <= amax.x && amin.y <= bmax.y && bmin.y <= amax.y
}

/// The world model: a lab, its robots, the seed of their noise, and the clock.
#[derive(Debug, Clone)]
pub struct World {
    lab: Lab,
    params: Params,
    statics: StaticIndex,
    dyn_grid: DynGrid,
    slots: Vec<Slot>,
    motion: Vec<Motion>,
    geo: Vec<Geo>,
    free: Vec<u32>,
    live: usize,
    capacity: usize,
    /// Every random draw is a function of this, the robot, the tick and the draw's purpose.
    seed: u64,
    /// Threads a step may use (1: the calling thread only) and the pool that runs them, shared
    /// by clones of the world.
    threads: usize,
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
    parallel_min: usize,
    tick: u64,
    time_s: Real,
    scratch: Scratch,
}

impl World {
    /// A world on `lab` with `params`, whose every random draw follows from `seed`.
    pub fn new(lab: &Lab, params: Params, seed: u64) -> Result<Self, WorldBuildError> {
        if lab.beacons.len() > MAX_BEACONS {
            return Err(WorldBuildError::TooManyBeacons { count: lab.beacons.len(), max: MAX_BEACONS });
        }
        let positive = |name: &'static str, value: Real| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(WorldBuildError::BadParam { name, value, expected: "> 0" })
            }
        };
        positive("proximity_range_m", params.proximity_range())?;
        // The default range is every default sensor's range: bounded like a registered one.
        if params.proximity_range() > MAX_SENSOR_RANGE_M {
            return Err(WorldBuildError::BadParam {
                name: "proximity_range_m",
                value: params.proximity_range(),
                expected: "in (0, 20] m",
            });
        }
        positive("message_range_m", params.message_range_m)?;
        positive("wheel_radius_m", params.wheel_radius_m)?;
        positive("encoder_ticks_per_rev", params.encoder_ticks_per_rev as Real)?;
        let n = &params.noise;
        for (name, value) in [
            ("noise.proximity_m", n.proximity_m),
            ("noise.beacon_deg", n.beacon_deg),
            ("noise.compass_deg", n.compass_deg),
            ("noise.gps_pos_m", n.gps_pos_m),
            ("noise.gps_heading_deg", n.gps_heading_deg),
            ("noise.motor_frac", n.motor_frac),
            ("noise.encoder_slip_frac", n.encoder_slip_frac),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(WorldBuildError::BadParam { name, value, expected: ">= 0" });
            }
        }
        let statics = StaticIndex::build(lab, STATIC_CELL_M)?;
        let dyn_spec = GridSpec::covering(
            statics.spec.min,
            statics.spec.min
                + Vector2::new(
                    statics.spec.nx as Real * statics.spec.cell,
                    statics.spec.ny as Real * statics.spec.cell,
                ),
            DYN_CELL_M,
        );
        let scratch = Scratch { sense: vec![SenseScratch::default()], ..Scratch::default() };
        Ok(Self {
            lab: lab.clone(),
            params,
            statics,
            dyn_grid: DynGrid::new(dyn_spec),
            slots: Vec::new(),
            motion: Vec::new(),
            geo: Vec::new(),
            free: Vec::new(),
            live: 0,
            capacity: DEFAULT_CAPACITY,
            seed,
            threads: 1,
            pool: None,
            parallel_min: PARALLEL_MIN_ROBOTS,
            tick: 0,
            time_s: 0.0,
            scratch,
        })
    }

    /// Changes how many robots the world accepts.
    pub fn set_capacity(&mut self, capacity: usize) {
        self.capacity = capacity;
    }

    /// Lets a step use `threads` threads (at least 1, at most [`MAX_THREADS`]). The outcome of
    /// a step never depends on it: each robot's noise is its own and each robot's phase writes
    /// only that robot. Returns the number of threads the world will use (1 when a pool cannot
    /// be started).
    pub fn set_threads(&mut self, threads: usize) -> usize {
        let threads = threads.clamp(1, MAX_THREADS);
        if threads == self.threads {
            return threads;
        }
        self.pool = None;
        self.threads = 1;
        if threads > 1 {
            match rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|k| format!("iwsim-world-{k}"))
                .build()
            {
                Ok(pool) => {
                    self.pool = Some(std::sync::Arc::new(pool));
                    self.threads = threads;
                }
                Err(e) => tracing::warn!("stepping on one thread: cannot start {threads} threads: {e}"),
            }
        }
        self.scratch.sense.resize_with(self.threads * CHUNKS_PER_THREAD, SenseScratch::default);
        self.threads
    }

    /// Steps with `other`'s threads (sharing its pool rather than starting another).
    pub fn use_threads_of(&mut self, other: &World) {
        self.pool = other.pool.clone();
        self.threads = other.threads;
        self.parallel_min = other.parallel_min;
        self.scratch.sense.resize_with(self.threads * CHUNKS_PER_THREAD, SenseScratch::default);
    }

    /// Threads a step may use.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The fewest robots a step spreads over threads (default [`PARALLEL_MIN_ROBOTS`]; 0: any
    /// world, as tests of the parallel path use).
    pub fn set_parallel_min_robots(&mut self, robots: usize) {
        self.parallel_min = robots;
    }

    /// Whether the next step spreads over threads (else it runs on the calling thread).
    pub fn steps_on_threads(&self) -> bool {
        self.pool.is_some() && self.live >= self.parallel_min.max(1)
    }

    /// How this step's per-robot phases are split: `None` on the calling thread, else the pool
    /// and the slots per chunk.
    fn chunking(&self) -> Chunking {
        if !self.steps_on_threads() {
            return None;
        }
        let pool = self.pool.as_ref()?;
        let chunks = self.threads * CHUNKS_PER_THREAD;
        Some((pool.clone(), self.slots.len().div_ceil(chunks).max(1)))
    }

    /// The lab.
    pub fn lab(&self) -> &Lab {
        &self.lab
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Whether the segment a→b crosses no wall higher than the floor (the lab's border
    /// included); lines on the floor do not count.
    pub fn segment_clear(&self, a: Point2<Real>, b: Point2<Real>) -> bool {
        !self.statics.segment_blocked(a, b, 0.0)
    }

    /// Ticks stepped so far.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// Simulated seconds so far (the sum of the steps' durations).
    pub fn time_s(&self) -> Real {
        self.time_s
    }

    /// Robots in the world.
    pub fn len(&self) -> usize {
        self.live
    }

    /// Whether the world has no robots.
    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// Adds a robot at its spec's pose. The pose is not checked for room: see
    /// [`World::is_free`].
    pub fn add_robot(&mut self, spec: RobotSpec) -> Result<RobotHandle, AddRobotError> {
        spec.validate_at(self.params.cycle_ms.max(1) as Real / 1000.0)?;
        // A robot placed off the lab would drive outside its border wall for good.
        let (x, y, width, height) = (spec.pose.x, spec.pose.y, self.lab.width_m, self.lab.height_m);
        if !((0.0..=width).contains(&x) && (0.0..=height).contains(&y)) {
            return Err(AddRobotError::OutsideLab { x, y, width, height });
        }
        if self.live >= self.capacity {
            return Err(AddRobotError::Full { max: self.capacity });
        }
        let shape = BodyGeom::new(&spec);
        let specs = if spec.sensors.is_empty() { spec.default_sensors() } else { spec.sensors.clone() };
        let mut sensors = [PreparedSensor::new(&specs[0], 1.0); MAX_PROXIMITY];
        let (mut reach, mut sensor_radius): (Real, Real) = (0.0, 0.0);
        for (k, s) in specs.iter().enumerate() {
            sensors[k] = PreparedSensor::new(s, self.params.proximity_range());
            reach = reach.max(sensors[k].origin.norm() + sensors[k].range);
            sensor_radius = sensor_radius.max(sensors[k].origin.norm());
        }
        let readings = SensorReadings {
            proximity_count: specs.len() as u8,
            beacon_count: self.lab.beacons.len() as u8,
            ..SensorReadings::EMPTY
        };
        let robot = Robot {
            pose: Pose::new(spec.pose.x, spec.pose.y, spec.pose.theta),
            spec,
            motor_in: [0.0; 2],
            motor_out: [0.0; 2],
            collision: false,
            collision_wall: false,
            collision_robot: false,
            collision_count: 0,
            readings,
            inbox: Vec::new(),
            frozen: false,
            shape,
            sensors,
            sensor_count: specs.len(),
            reach,
            sensor_radius,
            any_wide: sensors[..specs.len()].iter().any(|s| s.wide),
            encoder_travel: [0.0; 2],
            history: VecDeque::new(),
            say: None,
            pushed: None,
            pushed_at: self.tick,
        };
        let geo = Geo::of(&robot);
        let index = match self.free.pop() {
            Some(i) => i,
            None => {
                self.slots.push(Slot { generation: 0, robot: None });
                self.motion.push(Motion::DEAD);
                self.geo.push(Geo::DEAD);
                (self.slots.len() - 1) as u32
            }
        };
        let slot = &mut self.slots[index as usize];
        slot.robot = Some(robot);
        self.geo[index as usize] = geo;
        self.live += 1;
        Ok(RobotHandle { index, generation: slot.generation })
    }

    /// Removes a robot; returns false when the handle names no robot.
    pub fn remove_robot(&mut self, handle: RobotHandle) -> bool {
        let Some(slot) = self.slots.get_mut(handle.index as usize) else { return false };
        if slot.generation != handle.generation || slot.robot.is_none() {
            return false;
        }
        slot.robot = None;
        slot.generation = slot.generation.wrapping_add(1);
        self.geo[handle.index as usize] = Geo::DEAD;
        self.motion[handle.index as usize] = Motion::DEAD;
        self.free.push(handle.index);
        self.live -= 1;
        true
    }

    /// Freezes (or thaws) a robot; returns false when the handle names no robot.
    pub fn set_frozen(&mut self, handle: RobotHandle, frozen: bool) -> bool {
        match self.slots.get_mut(handle.index as usize) {
            Some(Slot { generation, robot: Some(r) }) if *generation == handle.generation => {
                r.frozen = frozen;
                true
            }
            _ => false,
        }
    }

    /// The robot a handle names.
    pub fn robot(&self, handle: RobotHandle) -> Option<&Robot> {
        let slot = self.slots.get(handle.index as usize)?;
        if slot.generation != handle.generation {
            return None;
        }
        slot.robot.as_ref()
    }

    /// Every robot, in slot order.
    pub fn robots(&self) -> impl Iterator<Item = (RobotHandle, &Robot)> {
        self.slots.iter().enumerate().filter_map(|(i, s)| {
            s.robot.as_ref().map(|r| (RobotHandle { index: i as u32, generation: s.generation }, r))
        })
    }

    /// Whether a robot of this spec, at the spec's pose, would touch no wall and no robot.
    pub fn is_free(&self, spec: &RobotSpec) -> bool {
        let placed = BodyGeom::new(spec).placed(&spec.pose);
        if self.body_hits_wall(&placed) {
            return false;
        }
        let (min, max) = aabb(&placed);
        // Every robot, not the grid: the grid was built at the last step and misses robots
        // added since. A bounding-circle test keeps the parry calls to near neighbours.
        self.slots.iter().zip(&self.geo).all(|(slot, g)| {
            let Some(other) = &slot.robot else { return true };
            let r = g.bound_radius;
            let far =
                g.centre.x + r < min.x || g.centre.x - r > max.x || g.centre.y + r < min.y || g.centre.y - r > max.y;
            far || !crate::geom::bodies_intersect(&placed, &other.shape.placed(&other.pose))
        })
    }

    /// Whether a robot of this spec, at the spec's pose, would touch no wall.
    pub fn is_clear_of_walls(&self, spec: &RobotSpec) -> bool {
        !self.body_hits_wall(&BodyGeom::new(spec).placed(&spec.pose))
    }

    /// Measures every robot where it stands, with the tick's noise and no latency (nothing
    /// earlier exists to delay), so readings exist before the first step: an agent's first
    /// sensor block is as noisy as every later one (an exact tick 0 would hand it its true
    /// start pose through GPS and compass). Stepping measures as usual afterwards.
    pub fn refresh_sensors(&mut self) {
        for (i, slot) in self.slots.iter().enumerate() {
            let Some(r) = &slot.robot else { continue };
            let cur = r.shape.placed(&r.pose);
            let (min, max) = aabb(&cur);
            self.motion[i] = Motion {
                alive: true,
                moving: false,
                real: r.spec.kind == RobotKind::Real,
                cur,
                next: cur,
                cur_min: min,
                cur_max: max,
                next_min: min,
                next_max: max,
                next_pose: r.pose,
                next_cs: (self.geo[i].normals[0].x, self.geo[i].normals[0].y),
            };
        }
        let motion = &self.motion;
        self.dyn_grid.rebuild(motion.iter().enumerate().filter(|(_, m)| m.alive).map(|(i, m)| {
            let centre = nalgebra::center(&m.cur_min, &m.cur_max);
            let half = (m.cur_max.x - m.cur_min.x).max(m.cur_max.y - m.cur_min.y) / 2.0;
            (i as u32, centre, half)
        }));
        let chunking = self.chunking();
        self.sense_with(true, &chunking);
    }

    /// Advances the world by one tick of `dt_s` simulated seconds with this tick's actions.
    pub fn step(&mut self, actions: &[Action], dt_s: Real) -> StepStats {
        let mut stats = StepStats::default();
        let dt = if dt_s.is_finite() && dt_s > 0.0 { dt_s } else { 0.0 };
        self.tick += 1;
        self.time_s += dt;
        let chunking = self.chunking();
        match &chunking {
            // The whole step runs on one of the pool's threads, so its phases hand work to the
            // others without a trip through the pool's queue each (one per step instead of four).
            Some((pool, _)) => pool.install(|| self.phases(actions, dt, &mut stats, &chunking)),
            None => self.phases(actions, dt, &mut stats, &chunking),
        }
        stats
    }

    fn phases(&mut self, actions: &[Action], dt: Real, stats: &mut StepStats, chunking: &Chunking) {
        self.apply_actions(actions, dt, stats);
        self.drive(dt, chunking);
        self.resolve_collisions(stats, chunking);
        self.commit(dt, chunking);
        sequential(chunking, || self.deliver_messages(stats));
        self.sense_with(false, chunking);
    }

    fn apply_actions(&mut self, actions: &[Action], dt: Real, stats: &mut StepStats) {
        self.scratch.speakers.clear();
        for a in actions {
            let Some(slot) = self.slots.get_mut(a.robot.index as usize) else {
                stats.unknown_robot_actions += 1;
                continue;
            };
            let Some(r) = slot.robot.as_mut().filter(|_| slot.generation == a.robot.generation) else {
                stats.unknown_robot_actions += 1;
                continue;
            };
            if let Some([l, rr]) = a.motors {
                let clean = |p: Real| if p.is_nan() { 0.0 } else { p.clamp(-1.0, 1.0) };
                if !(l.is_finite() && rr.is_finite()) {
                    stats.bad_values += 1;
                }
                r.motor_in = [clean(l), clean(rr)];
            }
            if let Some(p) = a.pose {
                let p = Pose::new(p.x, p.y, p.theta);
                if !p.is_finite() {
                    stats.bad_values += 1;
                } else if r.spec.kind != RobotKind::Real {
                    // Only Real robots take pushed poses (drive drops it).
                    r.pushed = Some(p);
                } else if reachable_push(&r.spec, &r.pose, &p, self.tick - r.pushed_at, dt) {
                    r.pushed = Some(p);
                    r.pushed_at = self.tick;
                } else {
                    stats.refused_poses += 1;
                }
            }
            if a.say.is_some() {
                if r.say.is_none() {
                    self.scratch.speakers.push(a.robot.index);
                }
                r.say = a.say;
            }
        }
    }

    /// Motor filter (thesis eq. 4.4) and kinematics (eqs. 4.5–4.9, with 4.8's typo fixed):
    /// every robot's next pose.
    fn drive(&mut self, dt: Real, chunking: &Chunking) {
        let motor_noise = self.params.noise.motor_frac;
        let (seed, tick) = (self.seed, self.tick);
        let geo = &self.geo;
        let mut units = [(); MAX_CHUNKS];
        run_chunks(chunking, &mut self.slots, &mut self.motion, &mut units, |base, slots, motion, ()| {
            for (k, (slot, m)) in slots.iter_mut().zip(motion.iter_mut()).enumerate() {
                let i = base + k;
                let Some(r) = &mut slot.robot else { continue };
                *m = Self::drive_one(r, &geo[i], motor_noise, (seed, stream_key(i, slot.generation), tick), dt);
            }
        });
        // Index every robot by the box that holds both its current and its next pose: the
        // collision phase tests against both, and the sensors see the committed one, which is
        // one of the two.
        let (motion, dyn_grid) = (&self.motion, &mut self.dyn_grid);
        sequential(chunking, || {
            dyn_grid.rebuild(motion.iter().enumerate().filter(|(_, m)| m.alive).map(|(i, m)| {
                let min = Point2::new(m.cur_min.x.min(m.next_min.x), m.cur_min.y.min(m.next_min.y));
                let max = Point2::new(m.cur_max.x.max(m.next_max.x), m.cur_max.y.max(m.next_max.y));
                let centre = nalgebra::center(&min, &max);
                let half = (max.x - min.x).max(max.y - min.y) / 2.0;
                (i as u32, centre, half)
            }))
        });
    }

    /// One robot's motor filter and next pose, from its committed geometry `g`; `key` names
    /// its noise stream.
    fn drive_one(r: &mut Robot, g: &Geo, motor_noise: Real, key: (u64, u64, u64), dt: Real) -> Motion {
        // The heading's cosine and sine as of the last commit.
        let h = g.normals[0];
        let (co, s) = (h.x, h.y);
        let next = match r.spec.kind {
            _ if r.frozen => {
                r.pushed = None;
                r.motor_in = [0.0; 2];
                r.motor_out = [0.0; 2];
                r.pose
            }
            RobotKind::Real => {
                r.motor_out = [0.0; 2];
                r.pushed.take().unwrap_or(r.pose)
            }
            RobotKind::Simulated | RobotKind::Door => {
                // Only Real robots take pushed poses.
                r.pushed = None;
                let c = r.spec.accel_curve;
                let mut rng = (motor_noise > 0.0).then(|| Rng::stream(key.0, key.1, key.2, Draw::Motor));
                for w in 0..2 {
                    let out = sim_model::motor_filter(r.motor_in[w], r.motor_out[w], c);
                    r.motor_out[w] = match &mut rng {
                        Some(rng) => out * (1.0 + motor_noise * rng.gaussian()),
                        None => out,
                    };
                }
                let (v, omega) = r.velocity();
                sim_model::advance(r.pose.into(), v, omega, co, s, dt).into()
            }
        };
        let cur = r.shape.placed_cs(&r.pose, co, s);
        let moving = next != r.pose;
        let (next_cs, nb) = if !moving {
            ((co, s), cur)
        } else if next.theta == r.pose.theta {
            ((co, s), r.shape.placed_cs(&next, co, s))
        } else {
            let (ns, nc) = next.theta.sin_cos();
            ((nc, ns), r.shape.placed_cs(&next, nc, ns))
        };
        let (cur_min, cur_max) = aabb(&cur);
        let (next_min, next_max) = if moving { aabb(&nb) } else { (cur_min, cur_max) };
        Motion {
            alive: true,
            moving,
            real: r.spec.kind == RobotKind::Real,
            cur,
            next: nb,
            cur_min,
            cur_max,
            next_min,
            next_max,
            next_pose: next,
            next_cs,
        }
    }

    fn commit(&mut self, dt: Real, chunking: &Chunking) {
        let ticks_per_m =
            sim_model::encoder_ticks_per_m(self.params.encoder_ticks_per_rev as Real, self.params.wheel_radius_m);
        let slip = self.params.noise.encoder_slip_frac;
        let (seed, tick) = (self.seed, self.tick);
        let (motion, blocked) = (&self.motion, &self.scratch.blocked);
        let mut units = [(); MAX_CHUNKS];
        run_chunks(chunking, &mut self.slots, &mut self.geo, &mut units, |base, slots, geo, ()| {
            for (k, (slot, g)) in slots.iter_mut().zip(geo.iter_mut()).enumerate() {
                let i = base + k;
                let Some(r) = &mut slot.robot else { continue };
                let key = (seed, stream_key(i, slot.generation), tick);
                Self::commit_one(r, g, &motion[i], blocked[i], (slip, ticks_per_m, dt), key);
            }
        });
    }

    /// One robot's move (or refusal), encoders and contact count; `g` is its committed geometry.
    fn commit_one(
        r: &mut Robot,
        g: &mut Geo,
        m: &Motion,
        (hits, enforce): (u8, bool),
        (slip, ticks_per_m, dt): (Real, Real, Real),
        key: (u64, u64, u64),
    ) {
        let hit = hits != 0;
        let moved = m.moving && !(hit && enforce);
        // A chair's encoders count what its wheels turn, not where the body went: held by a
        // wall or another body, its driven wheels spin on the floor and keep counting, as a
        // real chair's do, and tyres slip. A door's encoder sits on its mechanism, which
        // neither slips nor turns while the leaf is held: it counts the leaf's own motion.
        let (counts, slips) = match r.spec.kind {
            RobotKind::Simulated => (m.moving, slip > 0.0),
            RobotKind::Door => (moved, false),
            RobotKind::Real => (false, false),
        };
        if counts {
            let mut rng = slips.then(|| Rng::stream(key.0, key.1, key.2, Draw::Slip));
            for w in 0..2 {
                let mut travel = r.spec.max_speed_mps * r.motor_out[w] * dt;
                if let Some(rng) = &mut rng
                    && travel != 0.0
                {
                    travel *= 1.0 + slip * rng.gaussian();
                }
                r.encoder_travel[w] += travel;
            }
            r.readings.encoder_ticks = [
                (r.encoder_travel[0] * ticks_per_m).floor() as i64,
                (r.encoder_travel[1] * ticks_per_m).floor() as i64,
            ];
        }
        if moved {
            r.pose = m.next_pose;
            *g = Geo::of_cs(r, m.next_cs.0, m.next_cs.1);
        } else if m.moving && r.spec.shape == BodyShape::Disc {
            // Ciber-Rato's rule: a refused move still turns the robot. A disc's footprint is
            // the same at every heading, so turning where it stands meets nothing new; without
            // this a disc held by a wall and steered on an arc (one wheel still) never turns away.
            r.pose = Pose::new(r.pose.x, r.pose.y, m.next_pose.theta);
            *g = Geo::of_cs(r, m.next_cs.0, m.next_cs.1);
        }
        if hit && !r.collision {
            r.collision_count += 1;
        }
        r.collision = hit;
        r.collision_wall = hits & collide::HIT_WALL != 0;
        r.collision_robot = hits & collide::HIT_ROBOT != 0;
    }

    fn deliver_messages(&mut self, stats: &mut StepStats) {
        // Last tick's listeners forget what they heard; only they have anything to forget.
        for &j in &self.scratch.listeners {
            if let Some(r) = self.slots[j as usize].robot.as_mut() {
                r.inbox.clear();
            }
        }
        self.scratch.listeners.clear();
        if self.scratch.speakers.is_empty() {
            return;
        }
        let range = self.params.message_range_m;
        let deliveries = &mut self.scratch.deliveries;
        deliveries.clear();
        self.scratch.speakers.sort_unstable();
        for &i in &self.scratch.speakers {
            let slot = &mut self.slots[i as usize];
            let Some(r) = slot.robot.as_mut() else { continue };
            let Some(message) = r.say.take() else { continue };
            let from = RobotHandle { index: i, generation: slot.generation };
            let c = self.geo[i as usize].centre;
            let e = Vector2::new(range, range);
            self.dyn_grid.query(c - e, c + e, |j| {
                let g = &self.geo[j as usize];
                let d2 = (g.centre - c).norm_squared();
                if j != i && g.alive && d2 <= range * range {
                    deliveries.push((j, d2, Heard { from, message }));
                }
            });
        }
        // Each listener hears its nearest speakers first (ties: the lower slot), so when its
        // inbox is full the farthest go unheard, not those in the highest slots: with 20
        // chairs in a corridor some chair was never heard by a near one, which then drove
        // into it. Sorted by listener, distance and speaker, the drops are deterministic.
        deliveries
            .sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.from.index.cmp(&b.2.from.index)));
        for &(j, _, heard) in deliveries.iter() {
            let Some(r) = self.slots[j as usize].robot.as_mut() else { continue };
            let used: usize = r.inbox.iter().map(|h| h.message.len()).sum();
            if used + heard.message.len() <= MAX_INBOX_BYTES {
                if r.inbox.is_empty() {
                    self.scratch.listeners.push(j);
                }
                r.inbox.push(heard);
            } else {
                stats.dropped_messages += 1;
            }
        }
    }

    /// A 64-bit FNV-1a hash of everything that evolves (and the seed it evolves from): clock, every robot's pose,
    /// motors, collisions, encoders and readings. Two runs agree on it only if they agree bit
    /// for bit.
    pub fn state_hash(&self) -> u64 {
        let mut h = Fnv::new();
        h.u64(self.tick);
        h.f64(self.time_s);
        h.u64(self.seed);
        for (i, slot) in self.slots.iter().enumerate() {
            let Some(r) = &slot.robot else { continue };
            h.u64(i as u64);
            h.u64(slot.generation as u64);
            // Only discs add a word, so every rectangle-only world keeps the hash it had.
            if r.spec.shape == BodyShape::Disc {
                h.u64(1);
                h.f64(r.spec.width_m);
            }
            for v in [r.pose.x, r.pose.y, r.pose.theta, r.motor_in[0], r.motor_in[1], r.motor_out[0], r.motor_out[1]] {
                h.f64(v);
            }
            h.u64(r.collision as u64);
            h.u64(r.collision_count);
            let rd = &r.readings;
            h.u64(rd.tick);
            for &d in rd.proximity() {
                h.f64(d);
            }
            h.f64(rd.compass_deg.unwrap_or(Real::NAN));
            if let Some(g) = rd.gps {
                h.f64(g.x_m);
                h.f64(g.y_m);
                h.f64(g.heading_deg);
            }
            for b in rd.beacons() {
                h.f64(b.unwrap_or(Real::NAN));
            }
            h.u64(rd.ground.map_or(u64::MAX, u64::from));
            h.u64(rd.encoder_ticks[0] as u64);
            h.u64(rd.encoder_ticks[1] as u64);
            for m in &r.inbox {
                h.u64(m.from.index as u64);
                h.bytes(m.message.as_bytes());
            }
        }
        h.finish()
    }
}

/// FNV-1a over 64-bit words (not bytes): the hub hashes every tick, and a word at a time is
/// eight times fewer multiplications for the same sensitivity to any changed bit.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, b: &[u8]) {
        for chunk in b.chunks(8) {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.u64(u64::from_le_bytes(w));
        }
        self.u64(b.len() as u64);
    }
    fn u64(&mut self, v: u64) {
        self.0 ^= v;
        self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        // Fold the high bits down, which FNV's multiply alone never reaches.
        self.0 ^= self.0 >> 29;
    }
    fn f64(&mut self, v: Real) {
        self.u64(v.to_bits());
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests;
