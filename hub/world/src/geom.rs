//! The one boundary between the world model (nalgebra, f64) and parry2d (glam, f32).
//!
//! Everything parry sees is expressed relative to a local origin near the query (the moving
//! robot), so that f32 keeps sub-millimetre precision even on maps kilometres wide.

use nalgebra::{Isometry2, Point2, Vector2};
use parry2d::math::{Pose, Vec2};
use parry2d::query::details::{
    intersection_test_ball_ball, intersection_test_cuboid_cuboid, intersection_test_cuboid_triangle,
    intersection_test_point_query_ball,
};
use parry2d::shape::{Ball, Cuboid, Triangle};

/// A body placed in the world: a rectangle (its centre pose and half extents, metres) or a
/// disc (centred at the pose's translation, of radius `half.x`; its rotation is irrelevant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PlacedBody {
    pub iso: Isometry2<f64>,
    pub half: Vector2<f64>,
    pub disc: bool,
}

impl PlacedBody {
    /// The axis-aligned box (min, max) that holds the body. A disc's does not turn with its
    /// heading, so spinning in place never widens its broad-phase box.
    pub(crate) fn aabb(&self) -> (Point2<f64>, Point2<f64>) {
        let e = if self.disc {
            Vector2::new(self.half.x, self.half.x)
        } else {
            let c = self.iso.rotation.re.abs();
            let s = self.iso.rotation.im.abs();
            Vector2::new(c * self.half.x + s * self.half.y, s * self.half.x + c * self.half.y)
        };
        let t = Point2::from(self.iso.translation.vector);
        (t - e, t + e)
    }
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

fn ball(a: &PlacedBody) -> Ball {
    Ball::new(a.half.x as f32)
}

/// Whether two placed bodies overlap (touching or one inside the other counts).
pub(crate) fn bodies_intersect(a: &PlacedBody, b: &PlacedBody) -> bool {
    let origin = Point2::from(a.iso.translation.vector);
    let pa = to_local_pose(&a.iso, origin);
    let pb = to_local_pose(&b.iso, origin);
    match (a.disc, b.disc) {
        (false, false) => intersection_test_cuboid_cuboid(&pa.inv_mul(&pb), &cuboid(a.half), &cuboid(b.half)),
        (true, true) => intersection_test_ball_ball(pb.translation - pa.translation, &ball(a), &ball(b)),
        // The disc's centre in the rectangle's frame against the rectangle.
        (false, true) => intersection_test_point_query_ball(&pa.inv_mul(&pb), &cuboid(a.half), &ball(b)).intersecting,
        (true, false) => intersection_test_point_query_ball(&pb.inv_mul(&pa), &cuboid(b.half), &ball(a)).intersecting,
    }
}

/// Whether a placed body overlaps a triangle given in world coordinates.
pub(crate) fn body_hits_triangle(a: &PlacedBody, tri: &[Point2<f64>; 3]) -> bool {
    let origin = Point2::from(a.iso.translation.vector);
    let pa = to_local_pose(&a.iso, origin);
    let t = Triangle::new(local_point(tri[0], origin), local_point(tri[1], origin), local_point(tri[2], origin));
    if a.disc {
        // The triangle's frame is the local one, where the disc sits at the origin.
        return intersection_test_point_query_ball(&Pose::new(Vec2::ZERO, 0.0), &t, &ball(a)).intersecting;
    }
    // The triangle is already in the local frame, so its pose relative to the box is the
    // inverse of the box pose.
    intersection_test_cuboid_triangle(&pa.inverse(), &cuboid(a.half), &t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(x: f64, y: f64, theta: f64, hx: f64, hy: f64) -> PlacedBody {
        PlacedBody { iso: Isometry2::new(Vector2::new(x, y), theta), half: Vector2::new(hx, hy), disc: false }
    }

    fn disc(x: f64, y: f64, r: f64) -> PlacedBody {
        PlacedBody { iso: Isometry2::new(Vector2::new(x, y), 0.7), half: Vector2::new(r, r), disc: true }
    }

    #[test]
    fn a_box_fully_inside_another_intersects_it() {
        let big = placed(1000.0, 1000.0, 0.3, 2.0, 2.0);
        let small = placed(1000.1, 999.9, 1.0, 0.2, 0.1);
        assert!(bodies_intersect(&big, &small));
        assert!(bodies_intersect(&small, &big));
    }

    #[test]
    fn rotated_boxes_near_each_other_are_told_apart() {
        // A unit square at the origin and a square rotated 45° whose corner stops 1 cm short.
        let a = placed(0.0, 0.0, 0.0, 0.5, 0.5);
        let d = 0.5 + 0.5 * 2f64.sqrt();
        let near = placed(d + 0.01, 0.0, std::f64::consts::FRAC_PI_4, 0.5, 0.5);
        let touching = placed(d - 0.01, 0.0, std::f64::consts::FRAC_PI_4, 0.5, 0.5);
        assert!(!bodies_intersect(&a, &near));
        assert!(bodies_intersect(&a, &touching));
    }

    #[test]
    fn triangles_are_tested_in_world_coordinates_far_from_the_origin() {
        let tri = [Point2::new(5000.0, 5000.0), Point2::new(5002.0, 5000.0), Point2::new(5000.0, 5002.0)];
        assert!(body_hits_triangle(&placed(5000.5, 5000.5, 0.0, 0.1, 0.1), &tri));
        assert!(!body_hits_triangle(&placed(5001.6, 5001.6, 0.0, 0.1, 0.1), &tri));
        // A triangle wholly inside the box.
        assert!(body_hits_triangle(&placed(5001.0, 5001.0, 0.0, 5.0, 5.0), &tri));
    }

    #[test]
    fn discs_meet_discs_boxes_and_triangles_by_their_circle() {
        // Two discs of radius 0.5 whose centres are 1 m apart touch; 1.02 m apart they do not.
        assert!(bodies_intersect(&disc(3000.0, 10.0, 0.5), &disc(3001.0, 10.0, 0.5)));
        assert!(!bodies_intersect(&disc(3000.0, 10.0, 0.5), &disc(3001.02, 10.0, 0.5)));
        // A disc 1 cm off a unit square's corner along the diagonal: its bounding box overlaps
        // the square, its circle does not.
        let square = placed(0.0, 0.0, 0.0, 0.5, 0.5);
        let diag = 0.5 + 0.51 / 2f64.sqrt();
        assert!(!bodies_intersect(&square, &disc(diag, diag, 0.5)));
        assert!(!bodies_intersect(&disc(diag, diag, 0.5), &square));
        assert!(bodies_intersect(&square, &disc(0.99, 0.0, 0.5)));
        assert!(bodies_intersect(&disc(0.99, 0.0, 0.5), &square));
        // A disc inside a rotated box.
        assert!(bodies_intersect(&placed(5.0, 5.0, 0.4, 2.0, 2.0), &disc(5.2, 4.9, 0.3)));
        let tri = [Point2::new(5000.0, 5000.0), Point2::new(5002.0, 5000.0), Point2::new(5000.0, 5002.0)];
        assert!(body_hits_triangle(&disc(5001.0, 4999.6, 0.5), &tri));
        assert!(!body_hits_triangle(&disc(5001.0, 4999.4, 0.5), &tri));
        // The triangle wholly inside the disc, and the disc wholly inside the triangle.
        assert!(body_hits_triangle(&disc(5000.5, 5000.5, 5.0), &tri));
        assert!(body_hits_triangle(&disc(5000.3, 5000.3, 0.1), &tri));
        // A disc's box does not grow as it turns; a square's does.
        let (lo, hi) = disc(1.0, 2.0, 0.5).aabb();
        assert_eq!((lo, hi), (Point2::new(0.5, 1.5), Point2::new(1.5, 2.5)));
        let (lo, _) = placed(1.0, 2.0, std::f64::consts::FRAC_PI_4, 0.5, 0.5).aabb();
        assert!((lo.x - (1.0 - 0.5 * 2f64.sqrt())).abs() < 1e-12);
    }
}
