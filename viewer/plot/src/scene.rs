//! What is drawn under the trajectory: the lab, the scenario's obstacles and checkpoints, read
//! from the command line or from the run's `summary.json` (both forms are `records`'), and the
//! window of the floor shown.

pub use places::{Checkpoint, DEFAULT_CHECKPOINT_RADIUS_M, DEFAULT_OBSTACLE_HEIGHT_M, Obstacle, PlaceError};
pub use run_records::summary::{SummaryReadError, SummaryScene};
use world::map::Lab;

/// Floor shown around the trajectory, metres.
pub const MARGIN_M: f64 = 1.5;

/// Everything drawn under the trajectory.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// The lab (outline, walls, beacons, targets), if one is known.
    pub lab: Option<Lab>,
    /// Scenario obstacles, drawn with letters A, B, … in this order.
    pub obstacles: Vec<Obstacle>,
    /// Scenario checkpoints, numbered 1, 2, … in this order.
    pub checkpoints: Vec<Checkpoint>,
}

/// A window of the floor, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Left edge.
    pub x0: f64,
    /// Right edge.
    pub x1: f64,
    /// Bottom edge.
    pub y0: f64,
    /// Top edge.
    pub y1: f64,
}

impl View {
    /// Width, metres.
    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    /// Height, metres.
    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    /// Whether a point lies inside (edges included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    /// The window to draw: the bounding box of `points` and of the checkpoints, plus
    /// [`MARGIN_M`], kept inside the lab (unless the points themselves leave it).
    pub fn around(points: impl IntoIterator<Item = (f64, f64)>, scene: &Scene) -> Self {
        let mut v = View { x0: f64::INFINITY, x1: f64::NEG_INFINITY, y0: f64::INFINITY, y1: f64::NEG_INFINITY };
        let mut grow = |x: f64, y: f64| {
            v.x0 = v.x0.min(x);
            v.x1 = v.x1.max(x);
            v.y0 = v.y0.min(y);
            v.y1 = v.y1.max(y);
        };
        for (x, y) in points {
            grow(x, y);
        }
        for c in &scene.checkpoints {
            grow(c.x - c.radius, c.y - c.radius);
            grow(c.x + c.radius, c.y + c.radius);
        }
        if !v.x0.is_finite() {
            v = View { x0: 0.0, x1: 0.0, y0: 0.0, y1: 0.0 };
        }
        let bounds = v.bounds(scene);
        let mut v = View { x0: v.x0 - MARGIN_M, x1: v.x1 + MARGIN_M, y0: v.y0 - MARGIN_M, y1: v.y1 + MARGIN_M };
        if let Some(b) = bounds {
            v = v.clamped(&b);
        }
        v
    }

    /// How far a view may reach: the lab, or further where this window leaves it; `None`
    /// without a lab.
    pub fn bounds(&self, scene: &Scene) -> Option<View> {
        scene.lab.as_ref().map(|lab| View {
            x0: self.x0.min(0.0),
            x1: self.x1.max(lab.width_m),
            y0: self.y0.min(0.0),
            y1: self.y1.max(lab.height_m),
        })
    }

    /// The window grown to `width` × `height` about its centre, shifted to stay inside
    /// `bounds` and cut where `bounds` is smaller.
    pub fn grown_to(&self, width: f64, height: f64, bounds: Option<&View>) -> Self {
        let grow = |lo: f64, hi: f64, size: f64, b: Option<(f64, f64)>| -> (f64, f64) {
            let extra = (size - (hi - lo)).max(0.0) / 2.0;
            let (mut lo, mut hi) = (lo - extra, hi + extra);
            if let Some((blo, bhi)) = b {
                if lo < blo {
                    hi += blo - lo;
                    lo = blo;
                }
                if hi > bhi {
                    lo -= hi - bhi;
                    hi = bhi;
                }
                lo = lo.max(blo);
            }
            (lo, hi)
        };
        let (x0, x1) = grow(self.x0, self.x1, width, bounds.map(|b| (b.x0, b.x1)));
        let (y0, y1) = grow(self.y0, self.y1, height, bounds.map(|b| (b.y0, b.y1)));
        View { x0, x1, y0, y1 }
    }

    fn clamped(&self, b: &View) -> Self {
        View { x0: self.x0.max(b.x0), x1: self.x1.min(b.x1), y0: self.y0.max(b.y0), y1: self.y1.min(b.y1) }
    }

    /// The part of a simple polygon inside the window (Sutherland–Hodgman against each edge);
    /// empty when nothing is inside. The drawing backend does not clip, so every filled shape
    /// goes through here.
    pub fn clip_polygon(&self, polygon: &[(f64, f64)]) -> Vec<(f64, f64)> {
        let mut out: Vec<(f64, f64)> = polygon.to_vec();
        // Each edge: a point is inside when `f(p) >= 0`; `cut` finds where a segment crosses.
        let edges: [(usize, f64, f64); 4] =
            [(0, self.x0, 1.0), (0, self.x1, -1.0), (1, self.y0, 1.0), (1, self.y1, -1.0)];
        for (axis, at, sign) in edges {
            let coord = |p: (f64, f64)| if axis == 0 { p.0 } else { p.1 };
            let inside = |p: (f64, f64)| sign * (coord(p) - at) >= 0.0;
            let input = std::mem::take(&mut out);
            for (k, &p) in input.iter().enumerate() {
                let q = input[(k + 1) % input.len()];
                let cross = || {
                    let t = (at - coord(p)) / (coord(q) - coord(p));
                    (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1))
                };
                match (inside(p), inside(q)) {
                    (true, true) => out.push(q),
                    (true, false) => out.push(cross()),
                    (false, true) => {
                        out.push(cross());
                        out.push(q);
                    }
                    (false, false) => {}
                }
            }
            if out.is_empty() {
                break;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lab(width_m: f64, height_m: f64) -> Lab {
        Lab { name: "t".into(), width_m, height_m, walls: vec![], beacons: vec![], targets: vec![] }
    }

    #[test]
    fn the_view_is_the_trajectory_plus_margin_kept_inside_the_lab() {
        let scene = Scene { lab: Some(lab(44.0, 17.75)), ..Default::default() };
        let v = View::around([(0.5, 6.0), (8.0, 7.0)], &scene);
        assert_eq!(v, View { x0: 0.0, x1: 9.5, y0: 4.5, y1: 8.5 });
        let v = View::around([(0.5, 6.0), (8.0, 7.0)], &Scene::default());
        assert_eq!(v, View { x0: -1.0, x1: 9.5, y0: 4.5, y1: 8.5 });
    }

    #[test]
    fn growing_the_view_shifts_it_back_into_the_lab() {
        let b = View { x0: 0.0, x1: 44.0, y0: 0.0, y1: 17.75 };
        let v = View { x0: 0.0, x1: 9.5, y0: 4.5, y1: 8.5 }.grown_to(9.5, 6.0, Some(&b));
        assert_eq!(v, View { x0: 0.0, x1: 9.5, y0: 3.5, y1: 9.5 });
        let v = View { x0: 1.0, x1: 3.0, y0: 16.0, y1: 17.0 }.grown_to(4.0, 30.0, Some(&b));
        assert_eq!(v, View { x0: 0.0, x1: 4.0, y0: 0.0, y1: 17.75 });
    }

    #[test]
    fn clipping_keeps_the_part_of_a_polygon_inside_the_view() {
        let v = View { x0: 0.0, x1: 10.0, y0: 0.0, y1: 10.0 };
        let inside = [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)];
        assert_eq!(v.clip_polygon(&inside), [(2.0, 1.0), (2.0, 2.0), (1.0, 1.0)]);
        let across = [(-5.0, 4.0), (5.0, 4.0), (5.0, 6.0), (-5.0, 6.0)];
        let clipped = v.clip_polygon(&across);
        assert!(clipped.iter().all(|&(x, y)| v.contains(x, y)), "{clipped:?}");
        let area: f64 = (0..clipped.len())
            .map(|k| {
                let (p, q) = (clipped[k], clipped[(k + 1) % clipped.len()]);
                p.0 * q.1 - q.0 * p.1
            })
            .sum::<f64>()
            / 2.0;
        assert!((area.abs() - 10.0).abs() < 1e-9, "{area}");
        assert!(v.clip_polygon(&[(20.0, 20.0), (21.0, 20.0), (21.0, 21.0)]).is_empty());
    }
}
