//! Plane geometry for the navigator: points, poses, the chair's rectangle and proximity cones.
//!
//! Angles are radians here and degrees only on the wire (the SDK's blocks and the command
//! line); `sim_model`'s [`wrap_rad`] is the one function that normalises them.

use std::ops::{Add, Mul, Neg, Sub};

pub use sim_model::wrap_rad;

/// A point or vector in the lab frame (metres).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct V2 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
}

impl V2 {
    /// A vector.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// The unit vector at angle `a` (radians).
    pub fn unit(a: f64) -> Self {
        let (s, c) = a.sin_cos();
        Self { x: c, y: s }
    }

    /// Dot product.
    pub fn dot(self, o: V2) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// z of the cross product.
    pub fn cross(self, o: V2) -> f64 {
        self.x * o.y - self.y * o.x
    }

    /// Squared length.
    pub fn norm2(self) -> f64 {
        self.dot(self)
    }

    /// Length.
    pub fn norm(self) -> f64 {
        self.norm2().sqrt()
    }

    /// Rotated counter-clockwise by the angle whose cosine and sine are given.
    pub fn rotate_cs(self, c: f64, s: f64) -> V2 {
        V2::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }

    /// Whether both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

impl Add for V2 {
    type Output = V2;
    fn add(self, o: V2) -> V2 {
        V2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for V2 {
    type Output = V2;
    fn sub(self, o: V2) -> V2 {
        V2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for V2 {
    type Output = V2;
    fn mul(self, k: f64) -> V2 {
        V2::new(self.x * k, self.y * k)
    }
}

impl Neg for V2 {
    type Output = V2;
    fn neg(self) -> V2 {
        V2::new(-self.x, -self.y)
    }
}

/// A pose: the chair's centre of movement (the wheel axle's midpoint) and its heading.
///
/// The planner's own pose, with the vector views its geometry uses ([`V2`], body frames); it
/// keeps the heading wrapped. Everything outside the navigator (the SDK's odometry, the
/// registration's wire form) speaks [`sim_model::Pose`]; the two convert with `From`, field for
/// field. Replacing this type by the shared one (its methods becoming an extension trait) is
/// left for a later change: it touches some 200 lines of the planner for no change in
/// behaviour.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// Heading, radians in (−π, π], 0 along +x, counter-clockwise positive.
    pub theta: f64,
}

impl Pose {
    /// A pose (the heading is wrapped).
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta: wrap_rad(theta) }
    }

    /// The pose after `dt` seconds at speed `v` (m/s) and turn rate `w` (rad/s), moved as the
    /// hub moves a chair in one tick ([`sim_model::advance`]: along the heading it starts with).
    pub fn advanced(&self, v: f64, w: f64, dt: f64) -> Pose {
        let p = sim_model::advance((*self).into(), v, w, self.theta.cos(), self.theta.sin(), dt);
        Self { x: p.x_m, y: p.y_m, theta: p.heading_rad }
    }

    /// A pose from metres and a heading in degrees.
    pub fn from_deg(x: f64, y: f64, heading_deg: f64) -> Self {
        Self::new(x, y, heading_deg.to_radians())
    }

    /// The position.
    pub fn pos(&self) -> V2 {
        V2::new(self.x, self.y)
    }

    /// A body-frame point in the lab frame.
    pub fn to_world(&self, p: V2) -> V2 {
        let (s, c) = self.theta.sin_cos();
        self.pos() + p.rotate_cs(c, s)
    }

    /// A lab-frame point in the body frame.
    pub fn to_body(&self, p: V2) -> V2 {
        let (s, c) = self.theta.sin_cos();
        (p - self.pos()).rotate_cs(c, -s)
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// The lab-to-body transform, with the heading's sine and cosine computed once.
    pub fn body_frame(&self) -> BodyFrame {
        let (s, c) = self.theta.sin_cos();
        BodyFrame { origin: self.pos(), c, s }
    }
}

impl From<sim_model::Pose> for Pose {
    /// The shared pose in the navigator's terms (the heading wrapped, as [`Pose::new`] does).
    fn from(p: sim_model::Pose) -> Self {
        Self::new(p.x_m, p.y_m, p.heading_rad)
    }
}

impl From<Pose> for sim_model::Pose {
    fn from(p: Pose) -> Self {
        Self::new(p.x, p.y, p.theta)
    }
}

/// A pose's lab-to-body transform, for many points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyFrame {
    origin: V2,
    c: f64,
    s: f64,
}

impl BodyFrame {
    /// The frame of a body at `origin` whose heading has cosine `c` and sine `s` (for callers
    /// that carry a heading's cosine and sine along rather than the angle).
    pub fn from_cos_sin(origin: V2, c: f64, s: f64) -> Self {
        Self { origin, c, s }
    }

    /// Where the body's origin is, lab coordinates.
    pub fn origin(&self) -> V2 {
        self.origin
    }

    /// A lab-frame point in the body frame.
    pub fn apply(&self, p: V2) -> V2 {
        (p - self.origin).rotate_cs(self.c, -self.s)
    }

    /// A body-frame point in the lab frame.
    pub fn to_world(&self, p: V2) -> V2 {
        self.origin + p.rotate_cs(self.c, self.s)
    }
}

/// A segment of a wall's outline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seg {
    /// One end.
    pub a: V2,
    /// The other end.
    pub b: V2,
}

impl Seg {
    /// A segment.
    pub fn new(a: V2, b: V2) -> Self {
        Self { a, b }
    }

    /// Distance from `p` to the segment.
    pub fn distance(&self, p: V2) -> f64 {
        point_segment_distance(p, self.a, self.b)
    }
}

/// Distance from `p` to the segment `a`–`b`.
pub fn point_segment_distance(p: V2, a: V2, b: V2) -> f64 {
    let d = b - a;
    let len2 = d.norm2();
    let t = if len2 > 0.0 { ((p - a).dot(d) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (a + d * t - p).norm()
}

/// The chair's rectangle relative to its centre of movement: `front` metres ahead, `rear`
/// metres behind, `half` metres to each side (thesis Table 4.1: front = COM·W,
/// rear = (1 − COM)·W, half = H/2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Length ahead of the axle, metres.
    pub front: f64,
    /// Length behind the axle, metres.
    pub rear: f64,
    /// Half the width, metres.
    pub half: f64,
}

impl Footprint {
    /// The rectangle of a body `width_m` long (along the heading), `height_m` wide, with its
    /// wheel axle at `com` of its length from the rear.
    pub fn of_body(width_m: f64, height_m: f64, com: f64) -> Self {
        Self { front: com * width_m, rear: (1.0 - com) * width_m, half: height_m / 2.0 }
    }

    /// Radius around the axle that holds the whole body.
    pub fn reach(&self) -> f64 {
        self.front.max(self.rear).hypot(self.half)
    }

    /// The body's centre relative to the axle, along the heading.
    pub fn centre_offset(&self) -> f64 {
        (self.front - self.rear) / 2.0
    }

    /// Radius around the body's centre that holds the whole body.
    pub fn centre_reach(&self) -> f64 {
        let along = (self.front + self.rear) / 2.0;
        // sqrt, not libm's slower hypot: every collision check of a search asks.
        (along * along + self.half * self.half).sqrt()
    }

    /// The body's centre at a pose.
    pub fn centre(&self, pose: &Pose) -> V2 {
        pose.to_world(V2::new(self.centre_offset(), 0.0))
    }

    /// The corners grown by `margin`, counter-clockwise from front-right, in the lab frame.
    pub fn corners(&self, pose: &Pose, margin: f64) -> [V2; 4] {
        let (f, r, h) = (self.front + margin, -(self.rear + margin), self.half + margin);
        [V2::new(f, -h), V2::new(f, h), V2::new(r, h), V2::new(r, -h)].map(|p| pose.to_world(p))
    }

    /// Whether this rectangle at `pose` comes within `margin` of rectangle `other` at
    /// `other_pose` (the other grown by `margin` as a rectangle, which is a little more than
    /// `margin` at its corners).
    pub fn meets(&self, pose: &Pose, other: &Footprint, other_pose: &Pose, margin: f64) -> bool {
        let c = self.corners(pose, 0.0);
        (0..4).any(|k| other.meets_body_segment(other_pose.to_body(c[k]), other_pose.to_body(c[(k + 1) % 4]), margin))
            || self.contains_body(pose.to_body(other.centre(other_pose)), margin)
    }

    /// Whether a body-frame point lies inside the rectangle grown by `margin`.
    pub fn contains_body(&self, p: V2, margin: f64) -> bool {
        p.x <= self.front + margin && p.x >= -(self.rear + margin) && p.y.abs() <= self.half + margin
    }

    /// Whether a body-frame segment meets the rectangle grown by `margin` (Liang–Barsky).
    pub fn meets_body_segment(&self, a: V2, b: V2, margin: f64) -> bool {
        let (x0, x1) = (-(self.rear + margin), self.front + margin);
        let (y0, y1) = (-(self.half + margin), self.half + margin);
        let d = b - a;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [(-d.x, a.x - x0), (d.x, x1 - a.x), (-d.y, a.y - y0), (d.y, y1 - a.y)] {
            if p == 0.0 {
                if q < 0.0 {
                    return false;
                }
            } else {
                let t = q / p;
                if p < 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    }

    /// Distance from the rectangle (not grown) to a body-frame segment; 0 when they meet.
    pub fn body_segment_distance(&self, a: V2, b: V2) -> f64 {
        if self.meets_body_segment(a, b, 0.0) {
            return 0.0;
        }
        let box_d = |p: V2| {
            let dx = (-self.rear - p.x).max(p.x - self.front).max(0.0);
            let dy = (p.y.abs() - self.half).max(0.0);
            dx.hypot(dy)
        };
        let (f, r, h) = (self.front, -self.rear, self.half);
        let corners = [V2::new(f, -h), V2::new(f, h), V2::new(r, h), V2::new(r, -h)];
        let mut best = box_d(a).min(box_d(b));
        for c in corners {
            best = best.min(point_segment_distance(c, a, b));
        }
        best
    }
}

/// A proximity sensor's cone in the lab frame: apex, axis direction and half-opening.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    /// The sensor's position.
    pub apex: V2,
    /// Direction of the axis, radians.
    pub dir: f64,
    /// Half the opening, radians (below π/2).
    pub half: f64,
}

impl Cone {
    /// Whether a point lies inside the cone (any distance).
    pub fn contains(&self, p: V2) -> bool {
        let v = p - self.apex;
        if v.norm2() == 0.0 {
            return true;
        }
        wrap_rad(v.y.atan2(v.x) - self.dir).abs() <= self.half
    }

    /// Distance from the apex to the part of the segment `a`–`b` inside the cone, if any of
    /// it is (what an exact proximity sensor reports for that segment). The geometry is
    /// `sim_model::cone_range`, the one that the hub's proximity kernel is tested against
    /// (`sim_models_cone_range_is_the_hubs_proximity`), so the navigator predicts readings
    /// as the world makes them.
    pub fn distance_to_segment(&self, a: V2, b: V2) -> Option<f64> {
        let d = sim_model::cone_range(
            [self.apex.x, self.apex.y],
            self.dir,
            2.0 * self.half,
            [a.x, a.y],
            [b.x, b.y],
            f64::INFINITY,
        );
        d.is_finite().then_some(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rear_axle_chair_has_most_of_its_body_ahead() {
        let fp = Footprint::of_body(1.1, 0.65, 0.8);
        assert!((fp.front - 0.88).abs() < 1e-12 && (fp.rear - 0.22).abs() < 1e-12);
        let pose = Pose::from_deg(10.0, 6.0, 90.0);
        let c = fp.corners(&pose, 0.0);
        // Front-right of a chair heading +y is at (+0.325, +0.88) from the axle.
        assert!((c[0].x - 10.325).abs() < 1e-9 && (c[0].y - 6.88).abs() < 1e-9);
        assert!(fp.contains_body(pose.to_body(V2::new(10.0, 6.8)), 0.0));
        assert!(!fp.contains_body(pose.to_body(V2::new(10.0, 5.7)), 0.0));
    }

    #[test]
    fn segments_meet_the_rectangle_only_when_they_cross_it() {
        let fp = Footprint { front: 1.0, rear: 1.0, half: 0.5 };
        assert!(fp.meets_body_segment(V2::new(-2.0, 0.0), V2::new(2.0, 0.0), 0.0));
        assert!(!fp.meets_body_segment(V2::new(-2.0, 0.6), V2::new(2.0, 0.6), 0.0));
        assert!(fp.meets_body_segment(V2::new(-2.0, 0.6), V2::new(2.0, 0.6), 0.15));
        assert!(fp.meets_body_segment(V2::new(0.0, 0.0), V2::new(0.1, 0.1), 0.0), "inside");
        assert!((fp.body_segment_distance(V2::new(-2.0, 0.8), V2::new(2.0, 0.8)) - 0.3).abs() < 1e-12);
        assert!((fp.body_segment_distance(V2::new(1.3, 0.9), V2::new(3.0, 3.0)) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_cone_sees_the_nearest_point_of_a_segment_inside_it() {
        let cone = Cone { apex: V2::new(0.0, 0.0), dir: 0.0, half: 10f64.to_radians() };
        // A wall across the axis at x = 2: the nearest point is straight ahead.
        let d = cone.distance_to_segment(V2::new(2.0, -5.0), V2::new(2.0, 5.0)).expect("seen");
        assert!((d - 2.0).abs() < 1e-12);
        // A wall parallel to the axis at y = 1 enters the cone at x = 1 / tan 10°.
        let d = cone.distance_to_segment(V2::new(0.0, 1.0), V2::new(20.0, 1.0)).expect("seen");
        assert!((d - 1.0 / 10f64.to_radians().sin()).abs() < 1e-9);
        // Behind the sensor, or beside the cone: not seen.
        assert_eq!(cone.distance_to_segment(V2::new(-2.0, -5.0), V2::new(-2.0, 5.0)), None);
        assert_eq!(cone.distance_to_segment(V2::new(0.0, 1.0), V2::new(3.0, 1.0)), None);
    }
}
