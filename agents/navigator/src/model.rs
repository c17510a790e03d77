//! What the navigator knows of its surroundings: the known walls exactly (as segments), the
//! same walls rasterised, and the obstacles its sensors found; and the questions the planner
//! and the controller ask of them ("does the chair fit here?", "what should this sensor
//! read?").

use crate::geom::{Cone, Footprint, Pose, Seg, V2};
use crate::grid::{Buckets, EvidenceParams, GridSpec, Observation, SensedLayer, StaticRaster};
use crate::map::NavMap;

/// Cell side of the grids, metres.
pub const CELL_M: f64 = 0.05;
/// Bucket side of the segment and point indexes, metres.
const BUCKET_M: f64 = 0.5;
/// A sensed obstacle cell counts as a disc this wide around its centre.
pub const SENSED_RADIUS_M: f64 = CELL_M / 2.0;

/// The navigator's model of the lab.
#[derive(Debug, Clone)]
pub struct WorldModel {
    /// The map from the hub.
    pub map: NavMap,
    /// The chair's rectangle.
    pub footprint: Footprint,
    segs: Vec<Seg>,
    seg_index: Buckets,
    /// Known walls, rasterised.
    pub statics: StaticRaster,
    /// Obstacles found by the sensors.
    pub sensed: SensedLayer,
    points: Vec<V2>,
    point_index: Buckets,
}

impl WorldModel {
    /// The model of a map for a chair of this footprint, with nothing sensed yet.
    pub fn new(map: NavMap, footprint: Footprint) -> Self {
        let segs = map.known_segments();
        let seg_index = Buckets::build(map.width_m, map.height_m, BUCKET_M, segs.len(), |k| {
            let s = segs[k];
            (V2::new(s.a.x.min(s.b.x), s.a.y.min(s.b.y)), V2::new(s.a.x.max(s.b.x), s.a.y.max(s.b.y)))
        });
        let statics = StaticRaster::new(&map, CELL_M);
        let sensed = SensedLayer::new(statics.spec, EvidenceParams::default());
        let point_index = Buckets::build(map.width_m, map.height_m, BUCKET_M, 0, |_| (V2::default(), V2::default()));
        Self { map, footprint, segs, seg_index, statics, sensed, points: Vec::new(), point_index }
    }

    /// The grid of the layers.
    pub fn spec(&self) -> GridSpec {
        self.statics.spec
    }

    /// The known walls' segments (and the border's).
    pub fn segments(&self) -> &[Seg] {
        &self.segs
    }

    /// Sensed obstacle cells as points (centres).
    pub fn sensed_points(&self) -> &[V2] {
        &self.points
    }

    /// What a sensor with this cone and range would read if only the known walls stood.
    pub fn expected_reading(&self, cone: &Cone, range: f64) -> f64 {
        let mut best = range;
        let r = V2::new(range, range);
        self.seg_index.query(cone.apex - r, cone.apex + r, |k| {
            let s = self.segs[k];
            if let Some(d) = cone.distance_to_segment(s.a, s.b) {
                best = best.min(d);
            }
        });
        best
    }

    /// Adds one reading to the sensed layer; `pose` is where the chair was when it was taken.
    pub fn observe(&mut self, cone: Cone, distance: f64, range: f64, pose: &Pose) {
        let expected = self.expected_reading(&cone, range);
        let obs = Observation { cone, distance, range, expected };
        self.sensed.observe(&self.statics, &obs, Some((pose, &self.footprint)));
    }

    /// Rebuilds the index of sensed points after the layer changed; returns whether it had.
    pub fn refresh_sensed(&mut self) -> bool {
        if !self.sensed.take_changes() {
            return false;
        }
        let spec = self.spec();
        self.points = self
            .sensed
            .cells()
            .iter()
            .map(|&i| {
                let (ix, iy) = spec.coords(i as usize);
                spec.center(ix, iy)
            })
            .collect();
        let pts = &self.points;
        self.point_index = Buckets::build(self.map.width_m, self.map.height_m, BUCKET_M, pts.len(), |k| (pts[k], pts[k]));
        true
    }

    /// Whether the chair at `pose`, grown by `margin`, touches no known wall and no sensed
    /// obstacle.
    pub fn free(&self, pose: &Pose, margin: f64) -> bool {
        let fp = &self.footprint;
        let centre = fp.centre(pose);
        let reach = fp.centre_reach() + margin;
        // Far from every wall and every sensed point: nothing to test.
        let wall_clear = self.statics.distance_at(centre) - self.spec().cell * std::f64::consts::SQRT_2 > reach;
        let r = V2::new(reach, reach);
        if !wall_clear {
            let mut hit = false;
            self.seg_index.query(centre - r, centre + r, |k| {
                if !hit {
                    let s = self.segs[k];
                    hit = fp.meets_body_segment(pose.to_body(s.a), pose.to_body(s.b), margin);
                }
            });
            if hit {
                return false;
            }
        }
        let mut hit = false;
        let grown = margin + SENSED_RADIUS_M;
        self.point_index.query(centre - r, centre + r, |k| {
            if !hit {
                hit = fp.contains_body(pose.to_body(self.points[k]), grown);
            }
        });
        !hit
    }

    /// The chair's distance at `pose` to the nearest known wall or sensed obstacle, up to
    /// `cap` metres.
    pub fn clearance(&self, pose: &Pose, cap: f64) -> f64 {
        let fp = &self.footprint;
        let centre = fp.centre(pose);
        let reach = fp.centre_reach() + cap;
        let r = V2::new(reach, reach);
        let mut best = cap;
        self.seg_index.query(centre - r, centre + r, |k| {
            let s = self.segs[k];
            best = best.min(fp.body_segment_distance(pose.to_body(s.a), pose.to_body(s.b)));
        });
        self.point_index.query(centre - r, centre + r, |k| {
            let p = pose.to_body(self.points[k]);
            let d = fp.body_segment_distance(p, p) - SENSED_RADIUS_M;
            best = best.min(d.max(0.0));
        });
        best
    }

    /// Whether a point is within the chair at `pose` grown by `margin`.
    pub fn body_contains(&self, pose: &Pose, p: V2, margin: f64) -> bool {
        self.footprint.contains_body(pose.to_body(p), margin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::MapWall;

    fn corridor() -> WorldModel {
        // A corridor 1.8 m wide between walls at y = 1 and y = 2.8.
        let mut map = NavMap::empty(12.0, 4.0);
        map.walls.push(MapWall::rectangle(0.0, 0.9, 12.0, 1.0, false));
        map.walls.push(MapWall::rectangle(0.0, 2.8, 12.0, 2.9, false));
        WorldModel::new(map, Footprint::of_body(1.1, 0.65, 0.8))
    }

    #[test]
    fn the_chair_fits_in_the_corridor_but_not_across_it() {
        let m = corridor();
        assert!(m.free(&Pose::from_deg(5.0, 1.9, 0.0), 0.1));
        assert!(!m.free(&Pose::from_deg(5.0, 1.9, 0.0), 0.6), "1.8 m wide, the chair is 0.65 m");
        assert!(!m.free(&Pose::from_deg(5.0, 1.9, 90.0), 0.0), "1.1 m long across 1.8 m: the front hits");
        assert!(!m.free(&Pose::from_deg(5.0, 1.2, 0.0), 0.0));
        let c = m.clearance(&Pose::from_deg(5.0, 1.9, 0.0), 1.0);
        assert!((c - (0.9 - 0.325)).abs() < 1e-9, "{c}");
    }

    #[test]
    fn expected_readings_follow_the_known_walls() {
        let m = corridor();
        let cone = Cone { apex: V2::new(5.0, 1.9), dir: std::f64::consts::FRAC_PI_2, half: 0.1 };
        assert!((m.expected_reading(&cone, 3.0) - 0.9).abs() < 1e-9);
        let along = Cone { apex: V2::new(5.0, 1.9), dir: 0.0, half: 0.05 };
        assert_eq!(m.expected_reading(&along, 3.0), 3.0, "nothing within range straight along it");
    }

    #[test]
    fn sensed_obstacles_block_the_chair_once_confirmed() {
        let mut m = corridor();
        let pose = Pose::from_deg(3.0, 1.9, 0.0);
        let cone = Cone { apex: pose.to_world(V2::new(0.88, 0.0)), dir: 0.0, half: 0.05 };
        for _ in 0..4 {
            m.observe(cone, 1.5, 3.0, &pose);
        }
        assert!(m.refresh_sensed());
        assert!(!m.sensed_points().is_empty());
        assert!(!m.free(&Pose::from_deg(4.0, 1.9, 0.0), 0.05), "the front would reach 4.88 + 0.5");
        assert!(m.free(&pose, 0.05));
    }
}
