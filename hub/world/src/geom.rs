//! The one boundary between the world model (nalgebra, f64) and parry2d (glam, f32).
//!
//! Everything parry sees is expressed relative to a local origin near the query (the moving
//! robot), so that f32 keeps sub-millimetre precision even on maps kilometres wide.

use nalgebra::{Isometry2, Point2, Vector2};
use parry2d::math::{Pose, Vec2};
use parry2d::query::details::{intersection_test_cuboid_cuboid, intersection_test_cuboid_triangle};
use parry2d::shape::{Cuboid, Triangle};

/// A rectangle placed in the world: its centre pose and half extents (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PlacedBox {
    pub iso: Isometry2<f64>,
    pub half: Vector2<f64>,
}

fn to_local_pose(iso: &Isometry2<f64>, origin: Point2<f64>) -> Pose {
    let t = iso.translation.vector - origin.coords;
    Pose::new(Vec2::new(t.x as f32, t.y as f32), iso.rotation.angle() as f32)
}

fn cuboid(half: Vector2<f64>) -> Cuboid {
    Cuboid::new(Vec2::new(half.x as f32, half.y as f32))
}

fn local_point(p: Point2<f64>, origin: Point2<f64>) -> Vec2 {
    Vec2::new((p.x - origin.x) as f32, (p.y - origin.y) as f32)
}

/// Whether two placed rectangles overlap (touching or one inside the other counts).
pub(crate) fn boxes_intersect(a: &PlacedBox, b: &PlacedBox) -> bool {
    let origin = Point2::from(a.iso.translation.vector);
    let pa = to_local_pose(&a.iso, origin);
    let pb = to_local_pose(&b.iso, origin);
    intersection_test_cuboid_cuboid(&pa.inv_mul(&pb), &cuboid(a.half), &cuboid(b.half))
}

/// Whether a placed rectangle overlaps a triangle given in world coordinates.
pub(crate) fn box_hits_triangle(a: &PlacedBox, tri: &[Point2<f64>; 3]) -> bool {
    let origin = Point2::from(a.iso.translation.vector);
    let pa = to_local_pose(&a.iso, origin);
    let t = Triangle::new(local_point(tri[0], origin), local_point(tri[1], origin), local_point(tri[2], origin));
    // The triangle is already in the local frame, so its pose relative to the box is the
    // inverse of the box pose.
    intersection_test_cuboid_triangle(&pa.inverse(), &cuboid(a.half), &t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(x: f64, y: f64, theta: f64, hx: f64, hy: f64) -> PlacedBox {
        PlacedBox { iso: Isometry2::new(Vector2::new(x, y), theta), half: Vector2::new(hx, hy) }
    }

    #[test]
    fn a_box_fully_inside_another_intersects_it() {
        let big = placed(1000.0, 1000.0, 0.3, 2.0, 2.0);
        let small = placed(1000.1, 999.9, 1.0, 0.2, 0.1);
        assert!(boxes_intersect(&big, &small));
        assert!(boxes_intersect(&small, &big));
    }

    #[test]
    fn rotated_boxes_near_each_other_are_told_apart() {
        // A unit square at the origin and a square rotated 45° whose corner stops 1 cm short.
        let a = placed(0.0, 0.0, 0.0, 0.5, 0.5);
        let d = 0.5 + 0.5 * 2f64.sqrt();
        let near = placed(d + 0.01, 0.0, std::f64::consts::FRAC_PI_4, 0.5, 0.5);
        let touching = placed(d - 0.01, 0.0, std::f64::consts::FRAC_PI_4, 0.5, 0.5);
        assert!(!boxes_intersect(&a, &near));
        assert!(boxes_intersect(&a, &touching));
    }

    #[test]
    fn triangles_are_tested_in_world_coordinates_far_from_the_origin() {
        let tri = [Point2::new(5000.0, 5000.0), Point2::new(5002.0, 5000.0), Point2::new(5000.0, 5002.0)];
        assert!(box_hits_triangle(&placed(5000.5, 5000.5, 0.0, 0.1, 0.1), &tri));
        assert!(!box_hits_triangle(&placed(5001.6, 5001.6, 0.0, 0.1, 0.1), &tri));
        // A triangle wholly inside the box.
        assert!(box_hits_triangle(&placed(5001.0, 5001.0, 0.0, 5.0, 5.0), &tri));
    }
}
