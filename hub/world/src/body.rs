//! Robot bodies: what a robot is made of (its [`RobotSpec`]) and the geometry derived from it.

use nalgebra::{Isometry2, Point2, Vector2};
use thiserror::Error;

use crate::geom::PlacedBody;
use crate::math::{Pose, Real};

/// At most this many proximity sensors per robot (thesis §4.3.5).
pub const MAX_PROXIMITY: usize = 8;
/// Longest robot name, in bytes.
pub const MAX_NAME_LEN: usize = 255;

/// The longest side of a robot's body, metres (`Width` and `Height` alike).
///
/// The largest things that move on their own in a building are a hospital bed (about 2.2 m)
/// and a wide sliding door (a door is a robot here); 5 m holds both with room to spare. The
/// bound matters because every robot's body sizes the broad-phase queries of its neighbours:
/// one 10 km "robot" would touch every cell of the robot index and make each tick quadratic.
/// A proximity sensor's mount point must also lie within this distance of the centre of
/// movement on each axis.
pub const MAX_BODY_M: Real = 5.0;

/// The highest top speed, m/s (18 km/h).
///
/// Powered wheelchairs are limited to about 3.3–3.6 m/s (12 km/h in most of Europe, 8 mph in
/// the UK); 5 m/s leaves room for a fast test robot while keeping a robot's travel in one
/// 100 ms tick (0.5 m) well under one cell of the robot index (2 m), which is what the
/// collision phase assumes when it looks only at neighbouring cells.
pub const MAX_SPEED_MPS: Real = 5.0;

/// The longest travel in one tick at top speed, metres, for ticks shorter than 100 ms: there
/// the top speed may exceed [`MAX_SPEED_MPS`] as long as one tick's travel stays within this
/// (what the robot index needs). A plain Ciber-Rato robot moves 0.15 m per cycle whatever the
/// cycle, so at a 20 ms cycle its top speed is 7.5 m/s.
pub const MAX_STEP_M: Real = 0.5;

/// The top speed allowed in a world whose tick lasts `dt_s` seconds: [`MAX_SPEED_MPS`], or
/// more on ticks shorter than 100 ms, up to [`MAX_STEP_M`] per tick.
pub fn max_speed_mps(dt_s: Real) -> Real {
    if dt_s > 0.0 { MAX_SPEED_MPS.max(MAX_STEP_M / dt_s) } else { MAX_SPEED_MPS }
}

/// The longest proximity-sensor range, metres.
/// ([`sim_model::MAX_SENSOR_RANGE_M`]: the UDP bridge gives Ciber-Rato robots this range.)
pub const MAX_SENSOR_RANGE_M: Real = sim_model::MAX_SENSOR_RANGE_M;

/// How a robot moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotKind {
    /// The world moves it from its motor powers.
    Simulated,
    /// A physical chair: its agent pushes its pose every tick; it is never blocked, its
    /// collisions are reported (mixed reality).
    Real,
    /// A door: a rectangle driven by a door agent like any robot; no special rules.
    Door,
}

/// The outline of a robot's body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BodyShape {
    /// A rectangle `width_m` × `height_m` whose wheel axis sits at `com` of its length (the
    /// Intellwheels body, thesis Table 4.1). Its footprint turns with the heading.
    #[default]
    Rectangle,
    /// A disc of diameter `width_m` (= `height_m`, the wheel track) centred on its centre of
    /// movement (`com` = 0.5): a Ciber-Rato robot. Its footprint does not change with the
    /// heading, so it can always turn in place.
    Disc,
}

/// One proximity sensor, in the body frame of the robot (origin at the centre of movement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProximitySpec {
    /// Position along the heading, metres.
    pub x_m: Real,
    /// Position across the heading (left positive), metres.
    pub y_m: Real,
    /// Direction relative to the heading, radians.
    pub angle_rad: Real,
    /// Full opening of the cone, radians, in (0, 2π].
    pub cone_rad: Real,
    /// Readings are capped at this distance, metres; `None` takes the world's default.
    pub range_m: Option<Real>,
}

impl ProximitySpec {
    /// A sensor from metres and degrees, with the world's default range.
    pub fn deg(x_m: Real, y_m: Real, angle_deg: Real, cone_deg: Real) -> Self {
        Self { x_m, y_m, angle_rad: angle_deg.to_radians(), cone_rad: cone_deg.to_radians(), range_m: None }
    }
}

/// Everything a robot is registered with (thesis Tables 4.3 and 4.4).
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSpec {
    /// Name, at most [`MAX_NAME_LEN`] bytes.
    pub name: String,
    /// How it moves.
    pub kind: RobotKind,
    /// Rectangle or disc.
    pub shape: BodyShape,
    /// Length along the heading, metres (`Width`); a disc's diameter.
    pub width_m: Real,
    /// Size across the heading, metres (`Height`); also the wheel track.
    pub height_m: Real,
    /// Where the wheel axis sits along the length, in (0, 1) (`COM`).
    pub com: Real,
    /// Speed at full power on both wheels, m/s (`MaxSpeed`).
    pub max_speed_mps: Real,
    /// The motor filter's `c` in [0, 1) (`AccelerationCurve`).
    pub accel_curve: Real,
    /// Start pose (centre of movement).
    pub pose: Pose,
    /// Proximity sensors; empty means the four defaults of thesis Table 4.5.
    pub sensors: Vec<ProximitySpec>,
}

impl RobotSpec {
    /// A simulated 1 m × 1 m robot with the thesis defaults (COM 0.5, 0.5 m/s, curve 0.5) at a
    /// pose given in metres and degrees.
    pub fn at(x_m: Real, y_m: Real, heading_deg: Real) -> Self {
        Self {
            name: String::from("robot"),
            kind: RobotKind::Simulated,
            shape: BodyShape::Rectangle,
            width_m: 1.0,
            height_m: 1.0,
            com: 0.5,
            max_speed_mps: 0.5,
            accel_curve: 0.5,
            pose: Pose::from_deg(x_m, y_m, heading_deg),
            sensors: Vec::new(),
        }
    }

    /// Sets a rectangular body's size and centre of movement.
    pub fn body(mut self, width_m: Real, height_m: Real, com: Real) -> Self {
        self.shape = BodyShape::Rectangle;
        self.width_m = width_m;
        self.height_m = height_m;
        self.com = com;
        self
    }

    /// Makes the body a disc of `diameter_m` centred on the centre of movement; the wheel track
    /// is the diameter (Ciber-Rato: `rot = (outR − outL) / diameter`).
    pub fn disc(mut self, diameter_m: Real) -> Self {
        self.shape = BodyShape::Disc;
        (self.width_m, self.height_m, self.com) = (diameter_m, diameter_m, 0.5);
        self
    }

    /// Sets the top speed and acceleration curve.
    pub fn motors(mut self, max_speed_mps: Real, accel_curve: Real) -> Self {
        self.max_speed_mps = max_speed_mps;
        self.accel_curve = accel_curve;
        self
    }

    /// Sets the kind.
    pub fn kind(mut self, kind: RobotKind) -> Self {
        self.kind = kind;
        self
    }

    /// Sets the name.
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.to_owned();
        self
    }

    /// Sets the proximity sensors.
    pub fn sensors(mut self, sensors: Vec<ProximitySpec>) -> Self {
        self.sensors = sensors;
        self
    }

    /// The four default sensors of thesis Table 4.5 for this body: front (COM·W, 0, 0°),
    /// left (0, H/2, 90°), right (0, −H/2, −90°), back (−(1−COM)·W, 0, 180°), all 60° cones.
    pub fn default_sensors(&self) -> Vec<ProximitySpec> {
        let (w, h, c) = (self.width_m, self.height_m, self.com);
        vec![
            ProximitySpec::deg(c * w, 0.0, 0.0, 60.0),
            ProximitySpec::deg(0.0, 0.5 * h, 90.0, 60.0),
            ProximitySpec::deg(0.0, -0.5 * h, -90.0, 60.0),
            ProximitySpec::deg(-(1.0 - c) * w, 0.0, 180.0, 60.0),
        ]
    }

    /// The body's corners in the body frame, thesis Table 4.1 order: front-left, front-right,
    /// rear-left, rear-right (for a disc, those of the square around it).
    pub fn corners_body(&self) -> [Point2<Real>; 4] {
        let (w, h, c) = (self.width_m, self.height_m, self.com);
        [
            Point2::new(c * w, h / 2.0),
            Point2::new(c * w, -h / 2.0),
            Point2::new(-(1.0 - c) * w, h / 2.0),
            Point2::new(-(1.0 - c) * w, -h / 2.0),
        ]
    }

    /// Checks every parameter at the default 100 ms tick; the world refuses a robot for the
    /// first one that fails.
    pub fn validate(&self) -> Result<(), AddRobotError> {
        self.validate_at(0.1)
    }

    /// Checks every parameter for a world whose tick lasts `dt_s` seconds (the top speed's
    /// bound depends on it, see [`max_speed_mps`]).
    pub fn validate_at(&self, dt_s: Real) -> Result<(), AddRobotError> {
        let finite = |field: &'static str, v: Real| {
            if v.is_finite() { Ok(()) } else { Err(AddRobotError::NotFinite { field }) }
        };
        finite("width", self.width_m)?;
        finite("height", self.height_m)?;
        finite("com", self.com)?;
        finite("max_speed", self.max_speed_mps)?;
        finite("accel_curve", self.accel_curve)?;
        finite("x", self.pose.x)?;
        finite("y", self.pose.y)?;
        finite("heading", self.pose.theta)?;
        if self.name.len() > MAX_NAME_LEN {
            return Err(AddRobotError::NameTooLong { len: self.name.len(), max: MAX_NAME_LEN });
        }
        // The `expected` texts spell out MAX_BODY_M, MAX_SPEED_MPS and MAX_SENSOR_RANGE_M; a test
        // keeps them in step.
        if !(self.width_m > 0.0 && self.width_m <= MAX_BODY_M) {
            return Err(AddRobotError::OutOfRange { field: "width", value: self.width_m, expected: "in (0, 5] m" });
        }
        if !(self.height_m > 0.0 && self.height_m <= MAX_BODY_M) {
            return Err(AddRobotError::OutOfRange { field: "height", value: self.height_m, expected: "in (0, 5] m" });
        }
        if !(self.com > 0.0 && self.com < 1.0) {
            return Err(AddRobotError::OutOfRange { field: "com", value: self.com, expected: "in (0, 1)" });
        }
        // A disc has one size and turns about its centre: the other two fields must agree, so
        // that every user of width, height (the track) and COM reads the same body.
        if self.shape == BodyShape::Disc {
            if self.height_m != self.width_m {
                return Err(AddRobotError::OutOfRange {
                    field: "height",
                    value: self.height_m,
                    expected: "equal to the width (the diameter) for a disc",
                });
            }
            if self.com != 0.5 {
                return Err(AddRobotError::OutOfRange { field: "com", value: self.com, expected: "0.5 for a disc" });
            }
        }
        if !(self.max_speed_mps > 0.0 && self.max_speed_mps <= max_speed_mps(dt_s)) {
            return Err(AddRobotError::OutOfRange {
                field: "max_speed",
                value: self.max_speed_mps,
                expected: if dt_s >= 0.1 { "in (0, 5] m/s" } else { "in (0, 5] m/s, or up to 0.5 m per tick" },
            });
        }
        if !(0.0..1.0).contains(&self.accel_curve) {
            return Err(AddRobotError::OutOfRange {
                field: "accel_curve",
                value: self.accel_curve,
                expected: "in [0, 1)",
            });
        }
        if self.sensors.len() > MAX_PROXIMITY {
            return Err(AddRobotError::TooManySensors { count: self.sensors.len(), max: MAX_PROXIMITY });
        }
        for (index, s) in self.sensors.iter().enumerate() {
            for (field, v) in
                [("sensor x", s.x_m), ("sensor y", s.y_m), ("sensor angle", s.angle_rad), ("sensor cone", s.cone_rad)]
            {
                if !v.is_finite() {
                    return Err(AddRobotError::BadSensor { index, field, value: v, expected: "a finite number" });
                }
            }
            for (field, v) in [("sensor x", s.x_m), ("sensor y", s.y_m)] {
                if v.abs() > MAX_BODY_M {
                    return Err(AddRobotError::BadSensor { index, field, value: v, expected: "in [-5, 5] m" });
                }
            }
            if !(s.cone_rad > 0.0 && s.cone_rad <= std::f64::consts::TAU + 1e-12) {
                return Err(AddRobotError::BadSensor {
                    index,
                    field: "sensor cone",
                    value: s.cone_rad.to_degrees(),
                    expected: "in (0°, 360°]",
                });
            }
            if let Some(r) = s.range_m
                && !(r.is_finite() && r > 0.0 && r <= MAX_SENSOR_RANGE_M)
            {
                return Err(AddRobotError::BadSensor {
                    index,
                    field: "sensor range",
                    value: r,
                    expected: "in (0, 20] m",
                });
            }
        }
        Ok(())
    }
}

/// Why the world refused a robot.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AddRobotError {
    /// A parameter was NaN or infinite.
    #[error("{field} is not a finite number")]
    NotFinite {
        /// Which parameter.
        field: &'static str,
    },
    /// A parameter was outside its range.
    #[error("{field} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// Which parameter.
        field: &'static str,
        /// The value given.
        value: Real,
        /// The allowed range.
        expected: &'static str,
    },
    /// More than [`MAX_PROXIMITY`] sensors.
    #[error("{count} proximity sensors registered; at most {max} are allowed")]
    TooManySensors {
        /// Sensors given.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// A proximity sensor's parameter was invalid.
    #[error("{field} = {value} on sensor {index}: expected {expected}")]
    BadSensor {
        /// The sensor's index in the spec.
        index: usize,
        /// Which parameter.
        field: &'static str,
        /// The value given.
        value: Real,
        /// The allowed range.
        expected: &'static str,
    },
    /// The name is too long.
    #[error("name is {len} bytes long; at most {max} are allowed")]
    NameTooLong {
        /// Length given.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// The world already holds its maximum number of robots.
    #[error("the world is full: it holds at most {max} robots")]
    Full {
        /// The capacity.
        max: usize,
    },
    /// The start pose's centre of movement lies outside the lab's rectangle.
    #[error("start position ({x}, {y}) lies outside the lab: expected 0 <= x <= {width} and 0 <= y <= {height}")]
    OutsideLab {
        /// Start x, metres.
        x: Real,
        /// Start y, metres.
        y: Real,
        /// Lab width, metres.
        width: Real,
        /// Lab height, metres.
        height: Real,
    },
}

/// A proximity sensor prepared for fast evaluation: its origin and the unit vectors of its cone
/// edges in the body frame, so a tick rotates them instead of calling sin/cos.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PreparedSensor {
    pub origin: Vector2<Real>,
    /// Right edge of the cone (angle − cone/2).
    pub edge_right: Vector2<Real>,
    /// Left edge of the cone (angle + cone/2).
    pub edge_left: Vector2<Real>,
    /// Direction of the axis; splits cones wider than 180° into two convex halves.
    pub axis: Vector2<Real>,
    /// Cone wider than 180°.
    pub wide: bool,
    pub range: Real,
}

impl PreparedSensor {
    pub(crate) fn new(s: &ProximitySpec, default_range: Real) -> Self {
        let half = s.cone_rad / 2.0;
        let unit = |a: Real| Vector2::new(a.cos(), a.sin());
        Self {
            origin: Vector2::new(s.x_m, s.y_m),
            edge_right: unit(s.angle_rad - half),
            edge_left: unit(s.angle_rad + half),
            axis: unit(s.angle_rad),
            wide: s.cone_rad > std::f64::consts::PI,
            range: s.range_m.unwrap_or(default_range),
        }
    }
}

/// The body geometry a tick needs, derived once from the spec.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BodyGeom {
    /// Centre of the rectangle relative to the centre of movement, along the heading (0 for a
    /// disc).
    pub centre_offset: Real,
    /// Half extents; a disc's are its radius twice.
    pub half: Vector2<Real>,
    /// Radius of the circle around the centre of movement that holds the whole body.
    pub bound_radius: Real,
    /// The body is a disc of radius `half.x`.
    pub disc: bool,
}

impl BodyGeom {
    pub(crate) fn new(spec: &RobotSpec) -> Self {
        let half = Vector2::new(spec.width_m / 2.0, spec.height_m / 2.0);
        if spec.shape == BodyShape::Disc {
            return Self { centre_offset: 0.0, half, bound_radius: half.x, disc: true };
        }
        let front = spec.com * spec.width_m;
        let rear = (1.0 - spec.com) * spec.width_m;
        Self {
            centre_offset: (spec.com - 0.5) * spec.width_m,
            half,
            bound_radius: front.max(rear).hypot(half.y),
            disc: false,
        }
    }

    /// The body placed at a pose.
    pub(crate) fn placed(&self, pose: &Pose) -> PlacedBody {
        let (s, c) = pose.theta.sin_cos();
        self.placed_cs(pose, c, s)
    }

    /// The body placed at a pose whose heading's cosine and sine are known.
    pub(crate) fn placed_cs(&self, pose: &Pose, c: Real, s: Real) -> PlacedBody {
        let centre = Vector2::new(pose.x + c * self.centre_offset, pose.y + s * self.centre_offset);
        PlacedBody { iso: Isometry2::new(centre, pose.theta), half: self.half, disc: self.disc }
    }

    /// The four corners in world coordinates, counter-clockwise starting front-right (for a
    /// disc, those of the square around it, turned with the heading).
    pub(crate) fn corners_ccw(&self, pose: &Pose, c: Real, s: Real) -> [Point2<Real>; 4] {
        let fx = self.centre_offset + self.half.x;
        let rx = self.centre_offset - self.half.x;
        let hy = self.half.y;
        let p = |x: Real, y: Real| Point2::new(pose.x + c * x - s * y, pose.y + s * x + c * y);
        [p(fx, -hy), p(fx, hy), p(rx, hy), p(rx, -hy)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_follow_thesis_table_4_1_for_com_0_5_and_0_8() {
        let half = RobotSpec::at(0.0, 0.0, 0.0).body(1.0, 0.6, 0.5);
        assert_eq!(
            half.corners_body(),
            [Point2::new(0.5, 0.3), Point2::new(0.5, -0.3), Point2::new(-0.5, 0.3), Point2::new(-0.5, -0.3)]
        );
        let rear_axle = RobotSpec::at(0.0, 0.0, 0.0).body(1.2, 0.7, 0.8);
        let c = rear_axle.corners_body();
        let expect = [(0.96, 0.35), (0.96, -0.35), (-0.24, 0.35), (-0.24, -0.35)];
        for (got, want) in c.iter().zip(expect) {
            assert!((got.x - want.0).abs() < 1e-12 && (got.y - want.1).abs() < 1e-12, "{got} vs {want:?}");
        }
    }

    #[test]
    fn world_corners_are_the_table_corners_rotated_about_the_centre_of_movement() {
        let spec = RobotSpec::at(3.0, 4.0, 90.0).body(1.2, 0.7, 0.8);
        let shape = BodyGeom::new(&spec);
        let (s, c) = spec.pose.theta.sin_cos();
        let world = shape.corners_ccw(&spec.pose, c, s);
        // Heading +y: front-right (0.96, −0.35) goes to (3 + 0.35, 4 + 0.96).
        assert!((world[0].x - 3.35).abs() < 1e-12 && (world[0].y - 4.96).abs() < 1e-12);
        // rear-left (−0.24, 0.35) goes to (3 − 0.35, 4 − 0.24).
        assert!((world[2].x - 2.65).abs() < 1e-12 && (world[2].y - 3.76).abs() < 1e-12);
        // The placed box agrees: its centre is 0.36 m ahead of the axle.
        let b = shape.placed(&spec.pose);
        assert!((b.iso.translation.vector.y - 4.36).abs() < 1e-12);
    }

    #[test]
    fn default_sensors_follow_thesis_table_4_5() {
        for com in [0.5, 0.8] {
            let spec = RobotSpec::at(0.0, 0.0, 0.0).body(1.2, 0.7, com);
            let d = spec.default_sensors();
            let want =
                [(com * 1.2, 0.0, 0.0), (0.0, 0.35, 90.0), (0.0, -0.35, -90.0), (-(1.0 - com) * 1.2, 0.0, 180.0)];
            assert_eq!(d.len(), 4);
            for (s, (x, y, a)) in d.iter().zip(want) {
                assert!((s.x_m - x).abs() < 1e-12 && (s.y_m - y).abs() < 1e-12);
                assert!((s.angle_rad.to_degrees() - a).abs() < 1e-9);
                assert!((s.cone_rad.to_degrees() - 60.0).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn invalid_parameters_are_refused_with_the_field_named() {
        let ok = RobotSpec::at(1.0, 1.0, 0.0);
        assert_eq!(ok.validate(), Ok(()));
        assert!(matches!(
            ok.clone().body(0.0, 1.0, 0.5).validate(),
            Err(AddRobotError::OutOfRange { field: "width", .. })
        ));
        assert!(matches!(
            ok.clone().body(1.0, 1.0, 1.0).validate(),
            Err(AddRobotError::OutOfRange { field: "com", .. })
        ));
        assert!(matches!(
            ok.clone().motors(0.5, 1.0).validate(),
            Err(AddRobotError::OutOfRange { field: "accel_curve", .. })
        ));
        assert!(matches!(
            ok.clone().body(f64::NAN, 1.0, 0.5).validate(),
            Err(AddRobotError::NotFinite { field: "width" })
        ));
        let nine = vec![ProximitySpec::deg(0.0, 0.0, 0.0, 60.0); 9];
        assert!(matches!(ok.clone().sensors(nine).validate(), Err(AddRobotError::TooManySensors { count: 9, max: 8 })));
        let bad_cone = vec![ProximitySpec::deg(0.0, 0.0, 0.0, 0.0)];
        assert!(matches!(ok.clone().sensors(bad_cone).validate(), Err(AddRobotError::BadSensor { index: 0, .. })));
        let long = "x".repeat(256);
        assert!(matches!(ok.named(&long).validate(), Err(AddRobotError::NameTooLong { len: 256, .. })));
    }

    #[test]
    fn bodies_speeds_and_sensor_ranges_past_their_limits_are_refused() {
        let ok = RobotSpec::at(1.0, 1.0, 0.0);
        // The limits themselves are accepted.
        let edge =
            ok.clone().body(MAX_BODY_M, MAX_BODY_M, 0.5).motors(MAX_SPEED_MPS, 0.5).sensors(vec![ProximitySpec {
                range_m: Some(MAX_SENSOR_RANGE_M),
                ..ProximitySpec::deg(MAX_BODY_M, -MAX_BODY_M, 0.0, 60.0)
            }]);
        assert_eq!(edge.validate(), Ok(()));
        let refused = ok.clone().body(10_000.0, 1.0, 0.5).validate();
        assert_eq!(
            refused,
            Err(AddRobotError::OutOfRange { field: "width", value: 10_000.0, expected: "in (0, 5] m" })
        );
        assert_eq!(
            refused.map_err(|e| e.to_string()),
            Err("width = 10000 is out of range: expected in (0, 5] m".to_owned())
        );
        assert!(matches!(
            ok.clone().body(1.0, 5.01, 0.5).validate(),
            Err(AddRobotError::OutOfRange { field: "height", .. })
        ));
        assert_eq!(
            ok.clone().motors(5.5, 0.5).validate(),
            Err(AddRobotError::OutOfRange { field: "max_speed", value: 5.5, expected: "in (0, 5] m/s" })
        );
        let far = vec![ProximitySpec { range_m: Some(20.5), ..ProximitySpec::deg(0.0, 0.0, 0.0, 60.0) }];
        assert_eq!(
            ok.clone().sensors(far).validate(),
            Err(AddRobotError::BadSensor { index: 0, field: "sensor range", value: 20.5, expected: "in (0, 20] m" })
        );
        let off_body = vec![ProximitySpec::deg(0.0, 0.0, 0.0, 60.0), ProximitySpec::deg(0.0, 9.0, 90.0, 60.0)];
        assert_eq!(
            ok.sensors(off_body).validate(),
            Err(AddRobotError::BadSensor { index: 1, field: "sensor y", value: 9.0, expected: "in [-5, 5] m" })
        );
        // The refusals' texts name the constants' values.
        assert_eq!((MAX_BODY_M, MAX_SPEED_MPS, MAX_SENSOR_RANGE_M), (5.0, 5.0, 20.0));
        // On ticks shorter than 100 ms the bound is travel per tick: a plain Ciber-Rato robot
        // (0.15 m per cycle) at a 20 ms cycle goes 7.5 m/s; at 100 ms that is refused.
        let fast = RobotSpec::at(1.0, 1.0, 0.0).motors(7.5, 0.5);
        assert_eq!(fast.validate_at(0.02), Ok(()));
        assert!(matches!(fast.validate_at(0.1), Err(AddRobotError::OutOfRange { field: "max_speed", .. })));
        assert_eq!((max_speed_mps(0.02), max_speed_mps(0.1), max_speed_mps(1.0)), (25.0, 5.0, 5.0));
    }

    #[test]
    fn a_disc_is_bounded_by_its_diameter_and_keeps_its_sizes_in_step() {
        let ok = RobotSpec::at(1.0, 1.0, 0.0).disc(1.0);
        assert_eq!((ok.shape, ok.width_m, ok.height_m, ok.com), (BodyShape::Disc, 1.0, 1.0, 0.5));
        assert_eq!(ok.validate(), Ok(()));
        assert_eq!(RobotSpec::at(1.0, 1.0, 0.0).disc(MAX_BODY_M).validate(), Ok(()));
        assert!(matches!(
            RobotSpec::at(1.0, 1.0, 0.0).disc(5.5).validate(),
            Err(AddRobotError::OutOfRange { field: "width", .. })
        ));
        let squashed = RobotSpec { height_m: 0.6, ..ok.clone() };
        assert!(matches!(squashed.validate(), Err(AddRobotError::OutOfRange { field: "height", value: 0.6, .. })));
        let off_centre = RobotSpec { com: 0.8, ..ok.clone() };
        assert!(matches!(off_centre.validate(), Err(AddRobotError::OutOfRange { field: "com", value: 0.8, .. })));
        // A disc's geometry: centred, bounded by its radius.
        let g = BodyGeom::new(&ok.clone().disc(0.8));
        assert_eq!((g.centre_offset, g.bound_radius, g.disc), (0.0, 0.4, true));
        // `body` makes it a rectangle again.
        assert_eq!(ok.body(1.0, 0.6, 0.5).shape, BodyShape::Rectangle);
    }

    #[test]
    fn a_world_refuses_an_oversized_robot_and_an_oversized_default_sensor_range() {
        let map = crate::map::builtin::map("liacc").expect("built in");
        let mut world = crate::World::new(&map.lab, crate::map::Params::default(), 1).expect("valid");
        let huge = RobotSpec::at(10.0, 6.1, 0.0).body(10_000.0, 1.0, 0.5);
        assert!(matches!(world.add_robot(huge), Err(AddRobotError::OutOfRange { field: "width", .. })));
        assert!(world.is_empty());
        let params = crate::map::Params { proximity_range_m: Some(25.0), ..crate::map::Params::default() };
        assert!(matches!(
            crate::World::new(&map.lab, params, 1),
            Err(crate::WorldBuildError::BadParam { name: "proximity_range_m", .. })
        ));
    }
}
