//! Scalars, poses and angles for the world model.
//!
//! The world model computes in `f64` with nalgebra; parry2d (which speaks `f32` and glam) is only
//! met in the crate's boundary module. Angles are radians inside the code and degrees on every
//! wire and file; `sim_model`'s [`wrap_rad`] and [`wire_deg`] are the one place that wraps them.

use nalgebra::{Isometry2, Point2, Vector2};

/// The world model's scalar.
pub type Real = f64;

pub use sim_model::{wire_deg, wrap_rad};

/// A planar pose: the centre of movement (x, y) in metres and the heading θ in radians,
/// 0 along +x, counter-clockwise positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// x, metres.
    pub x: Real,
    /// y, metres.
    pub y: Real,
    /// Heading, radians, kept in (−π, π].
    pub theta: Real,
}

impl Pose {
    /// A pose from metres and radians (the heading is normalised).
    pub fn new(x: Real, y: Real, theta: Real) -> Self {
        Self { x, y, theta: wrap_rad(theta) }
    }

    /// A pose from metres and a heading in degrees (the unit files and wires use).
    pub fn from_deg(x: Real, y: Real, heading_deg: Real) -> Self {
        Self::new(x, y, heading_deg.to_radians())
    }

    /// The position as a point.
    #[inline]
    pub fn position(&self) -> Point2<Real> {
        Point2::new(self.x, self.y)
    }

    /// The heading in degrees, normalised to (−180, 180].
    pub fn heading_deg(&self) -> Real {
        wire_deg(self.theta)
    }

    /// The body-to-world transform.
    pub fn isometry(&self) -> Isometry2<Real> {
        Isometry2::new(Vector2::new(self.x, self.y), self.theta)
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

// The shared model's pose carries the same three numbers; the world keeps its own type for the
// nalgebra views its hot loop uses. Both conversions copy the fields as they are (no wrap).
impl From<sim_model::Pose> for Pose {
    #[inline]
    fn from(p: sim_model::Pose) -> Self {
        Self { x: p.x_m, y: p.y_m, theta: p.heading_rad }
    }
}

impl From<Pose> for sim_model::Pose {
    #[inline]
    fn from(p: Pose) -> Self {
        Self::new(p.x, p.y, p.theta)
    }
}

/// 2D cross product (z of the 3D cross product).
#[inline]
pub(crate) fn cross(a: Vector2<Real>, b: Vector2<Real>) -> Real {
    a.x * b.y - a.y * b.x
}

/// Rotates a body-frame vector by a heading given as (cos θ, sin θ).
#[inline]
pub(crate) fn rotate(v: Vector2<Real>, c: Real, s: Real) -> Vector2<Real> {
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn poses_convert_degrees_on_the_way_in() {
        let p = Pose::from_deg(1.0, 2.0, 270.0);
        assert!((p.theta + PI / 2.0).abs() < 1e-12);
        assert!((p.heading_deg() + 90.0).abs() < 1e-9);
    }
}
