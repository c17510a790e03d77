//! Scalars, poses and angles for the world model.
//!
//! The world model computes in `f64` with nalgebra; parry2d (which speaks `f32` and glam) is only
//! met in the crate's boundary module. Angles are radians inside the code and degrees on every
//! wire and file; [`normalize_angle`] and [`wire_deg`] are the one place that wraps them.

use nalgebra::{Isometry2, Point2, Vector2};
use std::f64::consts::{PI, TAU};

/// The world model's scalar.
pub type Real = f64;

/// Wraps an angle in radians to (−π, π].
#[inline]
pub fn normalize_angle(a: Real) -> Real {
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

/// An angle in radians as degrees normalised to (−180, 180], as written on the wire.
#[inline]
pub fn wire_deg(a_rad: Real) -> Real {
    let d = normalize_angle(a_rad).to_degrees();
    // Rounding in to_degrees can land exactly on −180 for an input just above −π.
    if d <= -180.0 { d + 360.0 } else { d }
}

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
        Self { x, y, theta: normalize_angle(theta) }
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

    #[test]
    fn angles_wrap_into_the_half_open_interval() {
        assert_eq!(normalize_angle(PI), PI);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-15);
        assert!((normalize_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((normalize_angle(-7.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert!((normalize_angle(100.0 * TAU + 0.25) - 0.25).abs() < 1e-9);
        assert_eq!(wire_deg(-PI), 180.0);
        assert!((wire_deg(190f64.to_radians()) + 170.0).abs() < 1e-9);
    }

    #[test]
    fn poses_convert_degrees_on_the_way_in() {
        let p = Pose::from_deg(1.0, 2.0, 270.0);
        assert!((p.theta + PI / 2.0).abs() < 1e-12);
        assert!((p.heading_deg() + 90.0).abs() < 1e-9);
    }
}
