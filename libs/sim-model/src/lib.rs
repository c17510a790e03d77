//! The formulas every iwsim process shares: the hub's world model steps robots with them, and a
//! client that models its own chair (the wheelchair agent's `real` mode, the navigator's
//! odometry, the UDP bridge's IR values) calls the same functions, so the two can never drift
//! apart. No dependencies, no state: plain functions of their inputs, and the one [`Pose`]
//! type (heading in radians) that clients pass them, degrees being only its wire form.
//!
//! ```
//! use sim_model::{Pose, advance, motor_filter, velocity, wrap_rad};
//!
//! // One 100 ms tick of a chair at rest given full power on both wheels (thesis eqs. 4.4–4.9).
//! let curve = 0.5;
//! let out = [motor_filter(1.0, 0.0, curve), motor_filter(1.0, 0.0, curve)];
//! let (v, omega) = velocity(0.5, 0.65, out);
//! let (s, c) = 0.0_f64.sin_cos();
//! let p = advance(Pose::default(), v, omega, c, s, 0.1);
//! assert_eq!(p, Pose::new(0.025, 0.0, 0.0));
//! assert_eq!(wrap_rad(3.0 * std::f64::consts::PI), std::f64::consts::PI);
//! ```
#![warn(missing_docs)]

use std::f64::consts::{PI, TAU};

/// The longest proximity-sensor range a robot may have, metres.
///
/// Infrared sensors read up to about 1.5 m and ultrasonic ones up to about 10 m; 20 m covers
/// both. A sensor's range sizes the region of walls and robots its cone is tested against
/// every tick, so the hub bounds it for the same reason as a body's size.
pub const MAX_SENSOR_RANGE_M: f64 = 20.0;

/// A robot's challenge states as Ciber-Rato names them, by number (its viewers accept exactly
/// these): the hub publishes the number, the UDP bridge writes the name.
pub const CHALLENGE_PHASES: [&str; 6] = ["Stopped", "Running", "Waiting", "Returning", "Finished", "Removed"];

/// Wraps an angle in radians to (−π, π]: the one angle convention of the project.
#[inline]
pub fn wrap_rad(a: f64) -> f64 {
    if a > -PI && a <= PI {
        return a;
    }
    let mut r = a % TAU; // now in (−2π, 2π)
    if r <= -PI {
        r += TAU;
    } else if r > PI {
        r -= TAU;
    }
    r
}

/// An angle in radians as degrees normalised to (−180, 180], as written on every wire and file.
#[inline]
pub fn wire_deg(a_rad: f64) -> f64 {
    let d = wrap_rad(a_rad).to_degrees();
    // Rounding in to_degrees can land exactly on −180 for an input just above −π.
    if d <= -180.0 { d + 360.0 } else { d }
}

/// Thesis eq. 4.4: a wheel's output after the acceleration filter,
/// `out = (1 − curve)·input + curve·previous`, with `curve` (AccelerationCurve) in [0, 1).
#[inline]
pub fn motor_filter(input: f64, previous: f64, curve: f64) -> f64 {
    (1.0 - curve) * input + curve * previous
}

/// Thesis eqs. 4.5–4.6: linear (m/s) and angular (rad/s) speed of a differential-drive body
/// whose wheels, `track_m` apart, output `[left, right]` (fractions of `max_speed_mps`).
#[inline]
pub fn velocity(max_speed_mps: f64, track_m: f64, [left, right]: [f64; 2]) -> (f64, f64) {
    (max_speed_mps * (right + left) / 2.0, max_speed_mps * (right - left) / track_m)
}

/// A pose in its wire and command-line form, `[x m, y m, heading °]`: x and y in metres and the
/// heading in degrees, as registrations, action blocks, `--pose X,Y,DEG`, scenario files,
/// summary.json and logs carry it. It is a plain triple because those formats are; nothing
/// computes with it except through [`Pose::from_wire_deg`], so a heading in degrees never meets
/// a formula that expects radians, and the name says which of the two a bare triple is.
pub type PoseDeg = [f64; 3];

/// A robot's pose in the lab frame: position in metres and heading in radians (0 along +x,
/// counter-clockwise positive). The units are in the field names so that a heading in degrees
/// cannot pass for one in radians; degrees appear only at the wire and the command line, as a
/// [`PoseDeg`], through [`Pose::from_wire_deg`] and [`Pose::to_wire_deg`].
///
/// ```
/// use sim_model::Pose;
///
/// let p = Pose::from_wire_deg([1.0, 2.0, 90.0]); // the CLI's "1,2,90"
/// assert_eq!(p.heading_rad, std::f64::consts::FRAC_PI_2);
/// assert_eq!(p.to_wire_deg(), [1.0, 2.0, 90.0]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, radians; not wrapped on construction (those who turn it wrap it).
    pub heading_rad: f64,
}

impl Pose {
    /// A pose from metres and a heading in radians, taken as given.
    #[inline]
    pub const fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self { x_m, y_m, heading_rad }
    }

    /// A pose from metres and a heading in degrees (`to_radians`, not wrapped).
    #[inline]
    pub fn from_deg(x_m: f64, y_m: f64, heading_deg: f64) -> Self {
        Self::new(x_m, y_m, heading_deg.to_radians())
    }

    /// The wire and command-line form `[x m, y m, heading °]` as a pose.
    #[inline]
    pub fn from_wire_deg([x_m, y_m, heading_deg]: PoseDeg) -> Self {
        Self::from_deg(x_m, y_m, heading_deg)
    }

    /// The wire form `[x m, y m, heading °]`, the heading normalised by [`wire_deg`] to
    /// (−180, 180] as every wire and file writes it.
    #[inline]
    pub fn to_wire_deg(&self) -> PoseDeg {
        [self.x_m, self.y_m, wire_deg(self.heading_rad)]
    }

    /// The heading in degrees, converted as it is (`to_degrees`, not normalised).
    #[inline]
    pub fn heading_deg(&self) -> f64 {
        self.heading_rad.to_degrees()
    }

    /// The position `[x, y]`, metres.
    #[inline]
    pub fn position(&self) -> [f64; 2] {
        [self.x_m, self.y_m]
    }

    /// Whether every component is finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.x_m.is_finite() && self.y_m.is_finite() && self.heading_rad.is_finite()
    }
}

/// Thesis eqs. 4.7–4.9 (4.8's typo fixed): the pose after `dt` seconds at speeds `v` (m/s),
/// `omega` (rad/s), moving along the *old* heading, whose cosine and sine the caller passes
/// (the hub keeps them from its last commit). The new heading is wrapped.
#[inline]
pub fn advance(p: Pose, v: f64, omega: f64, cos: f64, sin: f64, dt: f64) -> Pose {
    Pose::new(p.x_m + v * cos * dt, p.y_m + v * sin * dt, wrap_rad(p.heading_rad + omega * dt))
}

/// Ciber-Rato's obstacle-sensor value of a distance: 1/d rounded to 0.1, saturating at 100
/// when d ≤ 0.01 m (what `<IRSensor Value>` carries on the wire).
#[inline]
pub fn ir_value(distance_m: f64) -> f64 {
    if distance_m > 0.01 { ((1.0 / distance_m) * 10.0).round() / 10.0 } else { 100.0 }
}

/// Encoder ticks per metre of wheel travel for an encoder of `ticks_per_rev` on a wheel of
/// `wheel_radius_m`.
#[inline]
pub fn encoder_ticks_per_m(ticks_per_rev: f64, wheel_radius_m: f64) -> f64 {
    ticks_per_rev / (TAU * wheel_radius_m)
}

/// The range a proximity sensor reads off one wall segment `a`–`b`: the distance from the
/// sensor at `apex` to the segment's nearest point inside its cone (axis `axis_rad`, full
/// opening `cone_rad`), or `range_m` when no point of it is inside the cone and nearer. This
/// is the hub's proximity model (its world computes the same with prepared segments), here
/// for clients that predict readings from the map, such as the chair adapter's localiser.
pub fn cone_range(apex: [f64; 2], axis_rad: f64, cone_rad: f64, a: [f64; 2], b: [f64; 2], range_m: f64) -> f64 {
    let half = cone_rad / 2.0;
    if half > PI / 2.0 - 1e-9 {
        // A cone of 180° or more is not convex: take its two halves, which are.
        let quarter = half / 2.0;
        let one = cone_range(apex, axis_rad - quarter, half, a, b, range_m);
        return one.min(cone_range(apex, axis_rad + quarter, half, a, b, range_m));
    }
    let cross = |p: [f64; 2], q: [f64; 2]| p[0] * q[1] - p[1] * q[0];
    let (u1, u2) = ((axis_rad - half).sin_cos(), (axis_rad + half).sin_cos());
    let (u1, u2) = ([u1.1, u1.0], [u2.1, u2.0]);
    let w = [a[0] - apex[0], a[1] - apex[1]];
    let d = [b[0] - a[0], b[1] - a[1]];
    // The part of w + t·d (t in 0..=1) right of neither edge: each side keeps k0 + t·k1 ≥ 0.
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (k0, k1) in [(cross(u1, w), cross(u1, d)), (cross(w, u2), cross(d, u2))] {
        if k1 > 0.0 {
            t0 = t0.max(-k0 / k1);
        } else if k1 < 0.0 {
            t1 = t1.min(-k0 / k1);
        } else if k0 < 0.0 {
            return range_m;
        }
    }
    if t0 > t1 {
        return range_m;
    }
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t_star = if len2 > 0.0 { -(w[0] * d[0] + w[1] * d[1]) / len2 } else { 0.0 };
    let t = t_star.clamp(t0, t1);
    let q = [w[0] + d[0] * t, w[1] + d[1] * t];
    (q[0] * q[0] + q[1] * q[1]).sqrt().min(range_m)
}

/// The Intellwheels chair as the physical-chair pieces know it: the chair emulator simulates
/// this body and these sensors, the serial adapter registers them with the hub for the chair's
/// virtual twin, and the navigator's default body and sensor layout are the same (a test there
/// checks it), so that real and virtual readings of one index come from one place on the body.
pub mod chair {
    /// The body: length along the heading, width, and the wheel axle's place along the length
    /// (the navigator's `--body` default).
    pub const BODY: [f64; 3] = [1.1, 0.65, 0.8];
    /// Top speed, m/s (thesis §7.2).
    pub const MAX_SPEED_MPS: f64 = 0.49;
    /// The motor filter's coefficient (thesis §7.2).
    pub const ACCEL_CURVE: f64 = 0.83;
    /// Encoder counts per wheel revolution on the chair's board.
    pub const COUNTS_PER_REV: u32 = 2048;
    /// Drive wheel radius, metres. The wheel track is the body's width, `BODY[1]`.
    pub const WHEEL_RADIUS_M: f64 = 0.17;

    /// Which of the board's sensors a mount is.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Kind {
        /// An infrared ranger: a narrow beam, blind to dark surfaces.
        Ir,
        /// A sonar: a wide cone, fired in groups, with occasional spurious echoes.
        Sonar,
    }

    /// One proximity sensor on the chair, in the body frame (origin at the axle, x ahead,
    /// y left), and its id on the board.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Mount {
        /// Along the heading, metres.
        pub x_m: f64,
        /// Across the heading (left positive), metres.
        pub y_m: f64,
        /// Direction relative to the heading, degrees.
        pub angle_deg: f64,
        /// Full opening, degrees.
        pub cone_deg: f64,
        /// Range, metres.
        pub range_m: f64,
        /// IR or sonar.
        pub kind: Kind,
        /// Its id among its kind on the board (0..=7).
        pub board_id: u8,
    }

    /// The chair's eight sensors in the hub's order (index i of a sensor block is `SENSORS[i]`):
    /// three narrow IR beams ahead, five sonars around. Positions follow [`BODY`]: the front
    /// edge is 0.88 m ahead of the axle, the rear 0.22 m behind, the sides 0.325 m out.
    pub const SENSORS: [Mount; 8] = {
        let (front, rear, half) = (BODY[2] * BODY[0], (1.0 - BODY[2]) * BODY[0], BODY[1] / 2.0);
        let mid = (front - rear) / 2.0;
        [
            m(front, 0.0, 0.0, 2.0, Kind::Ir, 0),
            m(front, 0.6 * half, 25.0, 3.0, Kind::Ir, 1),
            m(front, -0.6 * half, -25.0, 3.0, Kind::Ir, 2),
            m(front, half, 60.0, 10.0, Kind::Sonar, 0),
            m(front, -half, -60.0, 10.0, Kind::Sonar, 1),
            m(mid, half, 90.0, 20.0, Kind::Sonar, 2),
            m(mid, -half, -90.0, 20.0, Kind::Sonar, 3),
            m(-rear, 0.0, 180.0, 30.0, Kind::Sonar, 4),
        ]
    };

    const fn m(x_m: f64, y_m: f64, angle_deg: f64, cone_deg: f64, kind: Kind, board_id: u8) -> Mount {
        Mount { x_m, y_m, angle_deg, cone_deg, range_m: 3.0, kind, board_id }
    }

    /// The hub index of the board's sensor `board_id` of `kind`.
    pub fn index_of(kind: Kind, board_id: u8) -> Option<usize> {
        SENSORS.iter().position(|s| s.kind == kind && s.board_id == board_id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_into_the_half_open_interval() {
        for (a, want) in [(PI, PI), (-PI, PI), (3.0 * PI, PI), (-7.0, -7.0 + TAU), (7.0, 7.0 - TAU), (0.5, 0.5)] {
            assert!((wrap_rad(a) - want).abs() < 1e-12, "{a} -> {}", wrap_rad(a));
        }
        assert_eq!(wire_deg(-PI), 180.0);
        assert_eq!(wire_deg(-PI + 1e-17), 180.0);
        assert!((wire_deg(-3.0 * PI / 2.0) - 90.0).abs() < 1e-9);
        assert!((wire_deg(190f64.to_radians()) + 170.0).abs() < 1e-9);
        assert!((wrap_rad(100.0 * TAU + 0.25) - 0.25).abs() < 1e-9);
    }

    #[test]
    fn the_filter_reaches_its_input_geometrically() {
        let mut out = 0.0;
        for _ in 0..10 {
            out = motor_filter(1.0, out, 0.5);
        }
        assert!((out - (1.0 - 0.5f64.powi(10))).abs() < 1e-15);
        assert_eq!(motor_filter(0.3, 0.9, 0.0), 0.3);
    }

    #[test]
    fn opposite_wheels_spin_on_the_spot() {
        let (v, omega) = velocity(0.5, 0.5, [-1.0, 1.0]);
        assert_eq!((v, omega), (0.0, 2.0));
        let p = advance(Pose::new(1.0, 2.0, 0.0), v, omega, 1.0, 0.0, 0.1);
        assert_eq!(p.position(), [1.0, 2.0]);
        assert!((p.heading_rad - 0.2).abs() < 1e-15);
    }

    #[test]
    fn a_pose_converts_degrees_exactly_as_to_radians_and_wire_deg_do() {
        for deg in [0.0, 90.0, -90.0, 179.9, 180.0, -180.0, 270.0, -15.8, 1e-9] {
            let p = Pose::from_deg(1.5, -2.0, deg);
            assert_eq!(p, Pose::new(1.5, -2.0, f64::to_radians(deg)), "{deg}");
            assert_eq!(Pose::from_wire_deg([1.5, -2.0, deg]), p, "{deg}");
            assert_eq!(p.heading_deg(), f64::to_radians(deg).to_degrees(), "{deg}");
            assert_eq!(p.to_wire_deg(), [1.5, -2.0, wire_deg(f64::to_radians(deg))], "{deg}");
            assert_eq!(p.position(), [1.5, -2.0]);
        }
        // The wire form is normalised; the heading itself is kept as given.
        assert_eq!(Pose::from_deg(0.0, 0.0, -180.0).to_wire_deg()[2], 180.0);
        assert_eq!(Pose::from_deg(0.0, 0.0, 270.0).heading_rad, f64::to_radians(270.0));
        assert!(!Pose::new(0.0, f64::NAN, 0.0).is_finite() && Pose::default().is_finite());
    }

    #[test]
    fn ir_values_follow_ciber_rato() {
        assert_eq!(ir_value(1.0), 1.0);
        assert_eq!(ir_value(0.5), 2.0);
        assert_eq!(ir_value(0.3), 3.3);
        assert_eq!(ir_value(0.01), 100.0);
        assert_eq!(ir_value(0.0), 100.0);
        assert_eq!(ir_value(3.0), 0.3);
        assert_eq!(ir_value(0.005), 100.0);
        assert!((encoder_ticks_per_m(1024.0, 0.17) - 958.67).abs() < 0.01);
    }
    #[test]
    fn a_cone_reads_the_nearest_point_of_a_wall_inside_it() {
        let wall = ([2.0, -5.0], [2.0, 5.0]);
        let read = |axis_deg: f64, cone_deg: f64| {
            cone_range([0.0, 0.0], axis_deg.to_radians(), cone_deg.to_radians(), wall.0, wall.1, 10.0)
        };
        assert!((read(0.0, 20.0) - 2.0).abs() < 1e-12, "the perpendicular foot");
        // Axis 30° off, cone 20°: the nearest point in the cone is on its edge at 20°.
        assert!((read(30.0, 20.0) - 2.0 / 20f64.to_radians().cos()).abs() < 1e-12);
        assert_eq!(read(180.0, 30.0), 10.0, "a wall behind is not seen");
        assert!((read(180.0, 360.0) - 2.0).abs() < 1e-12, "a full circle sees it");
        assert_eq!(cone_range([0.0, 0.0], 0.0, 0.1, wall.0, wall.1, 1.5), 1.5, "beyond reach");
        // A short segment beside the cone is not seen; the same segment in it is.
        let (a, b) = ([2.0, 1.0], [2.0, 2.0]);
        assert_eq!(cone_range([0.0, 0.0], 0.0, 0.2, a, b, 10.0), 10.0);
        assert!((cone_range([0.0, 0.0], 0.0, PI / 2.0, a, b, 10.0) - 5f64.sqrt()).abs() < 1e-12);
    }
}

/// Distance from `p` to the segment `a`–`b`, metres.
pub fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 { (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - (a[0] + t * d[0])).hypot(p[1] - (a[1] + t * d[1]))
}

/// Whether `p` lies inside the simple polygon `corners` (either winding; a point on an edge
/// may count either way).
pub fn point_in_polygon(p: [f64; 2], corners: &[[f64; 2]]) -> bool {
    let mut inside = false;
    for (i, a) in corners.iter().enumerate() {
        let b = corners[(i + 1) % corners.len()];
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            inside = !inside;
        }
    }
    inside
}

#[cfg(test)]
mod geometry_tests {
    use super::*;

    #[test]
    fn distances_to_a_segment_and_points_in_a_polygon() {
        assert_eq!(point_segment_distance([0.5, 1.0], [0.0, 0.0], [1.0, 0.0]), 1.0);
        assert_eq!(point_segment_distance([4.0, 4.0], [0.0, 0.0], [1.0, 0.0]), 5.0, "past the end: to the end");
        assert_eq!(point_segment_distance([3.0, 4.0], [0.0, 0.0], [0.0, 0.0]), 5.0, "a point segment");
        let l = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]];
        assert!(point_in_polygon([0.5, 1.5], &l) && point_in_polygon([1.5, 0.5], &l));
        assert!(!point_in_polygon([1.5, 1.5], &l), "the notch of the L");
        let mut cw = l;
        cw.reverse();
        assert!(point_in_polygon([0.5, 1.5], &cw) && !point_in_polygon([1.5, 1.5], &cw));
    }
}
