//! Maps: the Ciber-Rato lab (walls, beacons, targets), the start grid, and the simulation
//! parameters file, plus the built-in worlds.
//!
//! Everything here is plain data in SI units (metres, radians inside, degrees only where a file
//! says degrees). Parsing lives in [`xml`] (the one module that talks to quick-xml) and the
//! `<Row Pos Pattern>` maze shorthand in [`pattern`].

pub mod builtin;
pub mod pattern;
pub mod xml;

use nalgebra::Point2;

pub use xml::{MapLoadError, TextPos};

/// Height given to a wall that does not say its own (Ciber-Rato's `cbWall` default).
pub const DEFAULT_WALL_HEIGHT_M: f64 = 4.0;

/// A Ciber-Rato lab: the rectangle `[0, width] × [0, height]` and what stands in it.
///
/// The border of the rectangle is always a wall (Ciber-Rato adds it as wall 0); it is not listed
/// in [`Lab::walls`] and is not serialised back.
#[derive(Debug, Clone, PartialEq)]
pub struct Lab {
    /// `Name` attribute (Ciber-Rato's default is "NO NAMED LAB").
    pub name: String,
    /// Extent along x, metres.
    pub width_m: f64,
    /// Extent along y, metres.
    pub height_m: f64,
    /// Interior walls, each a simple polygon with its corners counter-clockwise.
    pub walls: Vec<Wall>,
    /// Beacons, in file order (the beacon sensor's ids follow this order).
    pub beacons: Vec<Beacon>,
    /// Target areas, in file order (the ground sensor reports this index).
    pub targets: Vec<Target>,
}

/// A wall: a simple polygon extruded to a height.
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Height in metres; beacons lower than a wall are hidden behind it.
    pub height_m: f64,
    /// At least 3 corners, counter-clockwise (the loader re-orders clockwise input).
    pub corners: Vec<Point2<f64>>,
}

impl Wall {
    /// An axis-aligned rectangle, corners counter-clockwise from the lower left.
    pub fn rectangle(x0: f64, y0: f64, x1: f64, y1: f64, height_m: f64) -> Self {
        Self {
            height_m,
            corners: vec![Point2::new(x0, y0), Point2::new(x1, y0), Point2::new(x1, y1), Point2::new(x0, y1)],
        }
    }
}

/// A beacon the beacon sensor can take bearings to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beacon {
    /// Position in the lab frame, metres.
    pub pos: Point2<f64>,
    /// Height in metres (Ciber-Rato default 0).
    pub height_m: f64,
}

/// A circular target area the ground sensor detects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Centre in the lab frame, metres.
    pub pos: Point2<f64>,
    /// Radius in metres (Ciber-Rato default 2.0).
    pub radius_m: f64,
}

/// One start pose of the grid file (`<Position X Y Dir/>`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartPose {
    /// Centre of movement, metres.
    pub pos: Point2<f64>,
    /// Heading in degrees, as written in the file.
    pub heading_deg: f64,
}

/// The start grid: robot id k (1-based) starts at `poses[k-1]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Grid {
    /// Start poses in file order.
    pub poses: Vec<StartPose>,
}

/// Standard deviations of the Gaussian noise on each sensor. Zero switches that noise off.
///
/// The default is [`NoiseParams::WHEELCHAIR`]: Ciber-Rato's sensor and motor noise, plus the
/// wheel slip a real chair's encoders see, so that odometry drifts as it does on a real floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseParams {
    /// Proximity distance, metres (`ObstacleNoise`).
    pub proximity_m: f64,
    /// Beacon bearing, degrees (`BeaconNoise`).
    pub beacon_deg: f64,
    /// Compass heading, degrees (`CompassNoise`).
    pub compass_deg: f64,
    /// GPS x and y, metres (`GPSLinNoise`).
    pub gps_pos_m: f64,
    /// GPS heading, degrees (`GPSDirNoise`).
    pub gps_heading_deg: f64,
    /// Motor output, multiplicative, as a fraction (`MotorsNoise` is in percent: 1.5 → 0.015).
    pub motor_frac: f64,
    /// Encoder slip, as a fraction (`EncoderNoise`, %): each tick, each turning wheel's counted
    /// travel is its commanded travel times (1 + this × a standard Gaussian draw), drawn apart
    /// for the two wheels, so the difference turns the odometry's heading as a random walk.
    /// Chairs' wheels slip (and spin when a wall holds the chair); doors' encoders, on their
    /// mechanism, do not.
    /// The draws are per tick: at a shorter cycle the same value drifts less per metre (the
    /// drift's standard deviation scales with the square root of the cycle).
    pub encoder_slip_frac: f64,
    /// The chance that each line-sensor element reads the opposite of the truth
    /// (`LineSensorTrueProb` is one minus this; Ciber-Rato's default 0.98 makes it 0.02).
    pub line_flip_prob: f64,
}

impl NoiseParams {
    /// Ciber-Rato's defaults (proximity 0.1, beacon 2°, compass 2°, GPS 0.5 / 5°, motors 1.5 %),
    /// encoder slip off.
    pub const CIBER_RATO: NoiseParams = NoiseParams {
        proximity_m: 0.1,
        beacon_deg: 2.0,
        compass_deg: 2.0,
        gps_pos_m: 0.5,
        gps_heading_deg: 5.0,
        motor_frac: 0.015,
        encoder_slip_frac: 0.0,
        // As `LineSensorTrueProb="0.98"` reads (1 − 0.98 is not exactly 0.02).
        line_flip_prob: 1.0 - 0.98,
    };
    /// What `noise = true` means in a scenario, and what `iwsim hub` uses without a parameters
    /// file: [`NoiseParams::CIBER_RATO`] plus 2 % encoder slip per 100 ms tick.
    ///
    /// Why 2 %: measured odometry on indoor differential-drive platforms is off by one to a few
    /// percent of the distance travelled (Borenstein and Feng's UMBmark, IEEE Trans. Robotics
    /// and Automation 12(6), 1996, found errors of the order of 0.1–0.3 m after a 16 m square
    /// on uncalibrated platforms), and a chair's pneumatic tyres and castors are no better. At
    /// a chair's cruise (0.5 m/s, 5 cm per wheel per 100 ms tick, wheels 0.65 m apart), 2 % per
    /// tick makes pure odometry's heading wander by about 2° (1σ) over 10 m and its position
    /// by about 2 % of the distance sideways, the heading error being, as on real chairs, what
    /// dominates. Systematic errors (unequal wheel diameters, an uncertain track) are not
    /// modelled: they would need a per-robot calibration error, which these parameters lack.
    pub const WHEELCHAIR: NoiseParams = NoiseParams { encoder_slip_frac: 0.02, ..NoiseParams::CIBER_RATO };
    /// Every noise switched off.
    pub const NONE: NoiseParams = NoiseParams {
        proximity_m: 0.0,
        beacon_deg: 0.0,
        compass_deg: 0.0,
        gps_pos_m: 0.0,
        gps_heading_deg: 0.0,
        motor_frac: 0.0,
        encoder_slip_frac: 0.0,
        line_flip_prob: 0.0,
    };
}

impl Default for NoiseParams {
    fn default() -> Self {
        Self::WHEELCHAIR
    }
}

/// Delay, in ticks, between measuring a sensor and reporting it (`XLatency` attributes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LatencyParams {
    /// Proximity sensors (`ObstacleLatency`).
    pub proximity: u32,
    /// Beacon sensor (`BeaconLatency`).
    pub beacon: u32,
    /// Ground sensor (`GroundLatency`).
    pub ground: u32,
    /// Compass (`CompassLatency`).
    pub compass: u32,
    /// Collision sensor (`CollisionLatency`, also read as `collisionLatency`).
    pub collision: u32,
    /// GPS (`GPSLatency`, an iwsim extension).
    pub gps: u32,
}

impl LatencyParams {
    /// The largest latency of any sensor.
    pub fn max(&self) -> u32 {
        [self.proximity, self.beacon, self.ground, self.compass, self.collision, self.gps]
            .into_iter()
            .max()
            .unwrap_or(0)
    }
}

/// Which sensors a run offers (`GPS`, `BeaconSensor`, `CompassSensor` switches).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorSwitches {
    /// GPS on (Ciber-Rato default Off).
    pub gps: bool,
    /// Beacon sensor on (Ciber-Rato default Off).
    pub beacon: bool,
    /// Compass on (Ciber-Rato default On).
    pub compass: bool,
}

impl Default for SensorSwitches {
    fn default() -> Self {
        Self { gps: false, beacon: false, compass: true }
    }
}

/// Which sensors are sent only on request, and how many requests a robot may make per tick.
/// The world computes every sensor; the bridges use these to decide what to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RequestParams {
    /// `NRequestsPerCycle`.
    pub per_cycle: u32,
    /// `ObstacleRequestable`.
    pub obstacle: bool,
    /// `BeaconRequestable`.
    pub beacon: bool,
    /// `GroundRequestable`.
    pub ground: bool,
    /// `CompassRequestable`.
    pub compass: bool,
    /// `CollisionRequestable`.
    pub collision: bool,
}

/// The Ciber-Rato challenge's parameters: what the real simulator reads for its scoring, with
/// its defaults (`SIMPARAM` and the statics of `simulator.cpp` in
/// ciberRatoTools). They reach Ciber-Rato clients in the registration reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChallengeParams {
    /// `KeyTime`, ticks (the real simulator's default 1350; its active scoring modes do not
    /// use it, but clients read it).
    pub key_time_ticks: u64,
    /// `ScoreSensor`: whether Measures carry the robot's score.
    pub score_sensor: bool,
    /// `ReturnTimePenalty` (25).
    pub return_time_penalty: u32,
    /// `ArrivalTimePenalty` (100).
    pub arrival_time_penalty: u32,
    /// `CollisionWallPenalty` (2): score per contact with a wall.
    pub collision_wall_penalty: u32,
    /// `CollisionRobotPenalty` (2): score per contact with another robot.
    pub collision_robot_penalty: u32,
    /// `TargetReward` (100).
    pub target_reward: u32,
    /// `HomeReward` (100).
    pub home_reward: u32,
    /// The scoring mode (the real simulator's `--scoring`, 0 by default; an iwsim parameter
    /// `Scoring`, or `iwsim hub --scoring`).
    pub scoring: crate::challenge::Scoring,
}

impl Default for ChallengeParams {
    fn default() -> Self {
        Self {
            key_time_ticks: 1350,
            score_sensor: false,
            return_time_penalty: 25,
            arrival_time_penalty: 100,
            collision_wall_penalty: 2,
            collision_robot_penalty: 2,
            target_reward: 100,
            home_reward: 100,
            scoring: crate::challenge::Scoring::Competitive,
        }
    }
}

/// Everything the Parameters XML file sets (root `<Parameters .../>`), with iwsim extensions.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Run length in ticks (`SimTime`); 0 means no limit.
    pub sim_time_ticks: u64,
    /// Real-time tick period in milliseconds (`CycleTime`); iwsim's default is 100.
    pub cycle_ms: u32,
    /// Sensor noise.
    pub noise: NoiseParams,
    /// Sensor latencies.
    pub latency: LatencyParams,
    /// Sensor switches.
    pub sensors: SensorSwitches,
    /// Requestable sensors (used by the UDP bridge).
    pub requests: RequestParams,
    /// Beacon aperture: half-angle in radians (`BeaconAperture`, default π).
    pub beacon_aperture_rad: f64,
    /// Default proximity sensor range in metres (`ObstacleRange`, iwsim extension), when the
    /// file gives one; see [`Params::proximity_range`].
    pub proximity_range_m: Option<f64>,
    /// Message delivery radius in metres (`MessageRange`, iwsim extension, default 8.0).
    pub message_range_m: f64,
    /// Encoder ticks per wheel revolution (`EncoderTicks`, iwsim extension, default 1024).
    pub encoder_ticks_per_rev: u32,
    /// Wheel radius in metres for the encoders (`WheelRadius`, iwsim extension, default 0.17).
    pub wheel_radius_m: f64,
    /// The Ciber-Rato challenge's scoring and line-sensor parameters.
    pub challenge: ChallengeParams,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            sim_time_ticks: 0,
            cycle_ms: 100,
            noise: NoiseParams::default(),
            latency: LatencyParams::default(),
            sensors: SensorSwitches::default(),
            requests: RequestParams::default(),
            beacon_aperture_rad: std::f64::consts::PI,
            proximity_range_m: None,
            message_range_m: 8.0,
            encoder_ticks_per_rev: 1024,
            wheel_radius_m: 0.17,
            challenge: ChallengeParams::default(),
        }
    }
}

/// The proximity range of sensors that give none when the parameters give none, metres.
pub const DEFAULT_PROXIMITY_RANGE_M: f64 = 3.0;

impl Params {
    /// The range of proximity sensors that give none: `ObstacleRange`, or
    /// [`DEFAULT_PROXIMITY_RANGE_M`]. (The UDP bridge gives Ciber-Rato robots, whose real
    /// simulator has no such limit, the longest range instead when the file is silent.)
    pub fn proximity_range(&self) -> f64 {
        self.proximity_range_m.unwrap_or(DEFAULT_PROXIMITY_RANGE_M)
    }
}

/// A lab together with its start grid: what the hub loads.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    /// Walls, beacons, targets.
    pub lab: Lab,
    /// Start poses.
    pub grid: Grid,
}
