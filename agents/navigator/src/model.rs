//! What the navigator knows of its surroundings: the known walls exactly (as segments), the
//! same walls rasterised, and the obstacles its sensors found; and the questions the planner
//! and the controller ask of them ("does the chair fit here?", "what should this sensor
//! read?").

use crate::geom::{BodyFrame, Cone, Footprint, Pose, Seg, V2};
use crate::grid::{Area, Buckets, EvidenceParams, GridSpec, Observation, SensedLayer, StaticRaster};
use crate::map::NavMap;

/// Cell side of the grids, metres.
pub const CELL_M: f64 = 0.05;
/// Bucket side of the segment and point indexes, metres.
const BUCKET_M: f64 = 0.5;
/// Farther than any proximity sensor reads, metres (the hub's cones reach a few metres).
const SENSOR_REACH_M: f64 = 10.0;
/// A sensed obstacle cell counts as a disc this wide around its centre.
pub const SENSED_RADIUS_M: f64 = CELL_M / 2.0;

/// The navigator's model of the lab.
#[derive(Debug, Clone)]
pub struct WorldModel {
    /// The map from the hub.
    pub map: NavMap,
    /// The part of the lab the grids cover.
    pub area: Area,
    /// The chair's rectangle.
    pub footprint: Footprint,
    segs: Vec<Seg>,
    seg_index: Buckets,
    /// Known walls, rasterised.
    pub statics: StaticRaster,
    /// Obstacles found by the sensors.
    pub sensed: SensedLayer,
    points: Vec<V2>,
    /// The cell of each point.
    point_cells: Vec<u32>,

    point_index: Buckets,
    /// Outline points of chairs parked for us (they said so), after the sensed points in
    /// `points`; they always count as obstacles.
    parked: Vec<V2>,
    /// The parked chairs' rectangles as last set, to see whether they changed.
    parked_bodies: Vec<(Pose, Footprint)>,
    /// `parked` changed since the points were last rebuilt.
    parked_changed: bool,
    /// Where the parked chairs' points begin in `points`, as of the last rebuild.
    parked_from: usize,
    /// Sensed cells count as obstacles for planning from this much evidence on.
    pub plan_evidence: f32,
    /// Extra margin kept from sensed obstacles (their extent beyond what was seen is
    /// unknown), on top of the margin asked of [`WorldModel::free`].
    pub sensed_extra: f64,
}

impl WorldModel {
    /// The model of a map for a chair of this footprint, with nothing sensed yet.
    pub fn new(map: NavMap, footprint: Footprint) -> Self {
        let area = Area::lab(map.width_m, map.height_m);
        Self::within(map, footprint, area)
    }

    /// As [`WorldModel::new`], with grids and indexes over `area` only (the chair stays in
    /// it: its edges are walls to the planner).
    pub fn within(map: NavMap, footprint: Footprint, area: Area) -> Self {
        // Long walls are cut into bucket-sized pieces, so a query meets only the pieces near
        // it, not the whole wall once per bucket.
        let segs: Vec<Seg> = map
            .known_segments()
            .into_iter()
            .flat_map(|s| {
                let n = ((s.b - s.a).norm() / BUCKET_M).ceil().max(1.0) as usize;
                (0..n).map(move |k| {
                    let t0 = k as f64 / n as f64;
                    let t1 = (k + 1) as f64 / n as f64;
                    Seg::new(s.a + (s.b - s.a) * t0, s.a + (s.b - s.a) * t1)
                })
            })
            // Pieces farther beyond the area than a sensor reaches matter to no query the
            // chair makes (it stays in the area).
            .filter(|s| {
                let grow = V2::new(SENSOR_REACH_M, SENSOR_REACH_M);
                area.meets(
                    V2::new(s.a.x.min(s.b.x), s.a.y.min(s.b.y)) - grow,
                    V2::new(s.a.x.max(s.b.x), s.a.y.max(s.b.y)) + grow,
                )
            })
            .collect();
        let seg_index = Buckets::build(&area, BUCKET_M, segs.len(), |k| {
            let s = segs[k];
            (V2::new(s.a.x.min(s.b.x), s.a.y.min(s.b.y)), V2::new(s.a.x.max(s.b.x), s.a.y.max(s.b.y)))
        });
        let statics = StaticRaster::within(&map, CELL_M, &area);
        let sensed = SensedLayer::new(statics.spec, EvidenceParams::default());
        let point_index = Buckets::build(&area, BUCKET_M, 0, |_| (V2::default(), V2::default()));
        let plan_evidence = sensed.params.occupied_above;
        Self {
            map,
            area,
            footprint,
            segs,
            seg_index,
            statics,
            sensed,
            points: Vec::new(),
            point_cells: Vec::new(),
            sensed_extra: 0.0,
            point_index,
            parked: Vec::new(),
            parked_bodies: Vec::new(),
            parked_changed: false,
            parked_from: 0,
            plan_evidence,
        }
    }

    /// The grid of the layers.
    pub fn spec(&self) -> GridSpec {
        self.statics.spec
    }

    /// The known walls' segments (and the border's).
    pub fn segments(&self) -> &[Seg] {
        &self.segs
    }

    /// Sensed obstacle cells as points (centres), then the outlines of parked chairs.
    pub fn sensed_points(&self) -> &[V2] {
        &self.points
    }

    /// Sets the chairs that stand still (they said so: parked for us, waiting, or arrived).
    /// Their rectangles, as said, are obstacles like sensed ones (the sensors only ever see
    /// a face of them); they take effect at the next [`WorldModel::refresh_sensed`]. Returns
    /// whether anything changed by more than a centimetre.
    pub fn set_parked(&mut self, bodies: &[(Pose, Footprint)]) -> bool {
        let same = bodies.len() == self.parked_bodies.len()
            && bodies.iter().zip(&self.parked_bodies).all(|((p, f), (q, g))| {
                f == g && (p.pos() - q.pos()).norm() < 0.01 && crate::geom::wrap_rad(p.theta - q.theta).abs() < 0.01
            });
        if same {
            return false;
        }
        self.parked_bodies = bodies.to_vec();
        self.parked.clear();
        for (pose, fp) in bodies {
            let c = fp.corners(pose, 0.0);
            for k in 0..4 {
                let (a, b) = (c[k], c[(k + 1) % 4]);
                let n = ((b - a).norm() / (CELL_M * 0.8)).ceil().max(1.0) as usize;
                self.parked.extend((0..n).map(|i| a + (b - a) * (i as f64 / n as f64)));
            }
        }
        self.parked_changed = true;
        true
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

    /// What a sensor with this cone would read if only the sensed obstacles stood.
    pub fn sensed_reading(&self, cone: &Cone, range: f64) -> f64 {
        let mut best = range;
        let r = V2::new(range, range);
        self.point_index.query(cone.apex - r, cone.apex + r, |k| {
            let p = self.points[k];
            if cone.contains(p) {
                best = best.min(((p - cone.apex).norm() - SENSED_RADIUS_M).max(0.0));
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

    /// Adds a reading that something known explains (another chair that says where it is):
    /// it clears the free space before it and marks nothing, so a chair that drives by leaves
    /// no ghost behind.
    pub fn observe_explained(&mut self, cone: Cone, distance: f64, range: f64, pose: &Pose) {
        let expected = self.expected_reading(&cone, range).min(distance);
        let obs = Observation { cone, distance, range, expected };
        self.sensed.observe(&self.statics, &obs, Some((pose, &self.footprint)));
    }

    /// Rebuilds the index of sensed points after the layer changed; returns whether it had.
    pub fn refresh_sensed(&mut self) -> bool {
        let sensed = self.sensed.take_changes();
        let parked = std::mem::take(&mut self.parked_changed);
        if !sensed && !parked {
            return false;
        }
        let spec = self.spec();
        self.point_cells = self.sensed.cells().to_vec();
        self.points = self
            .point_cells
            .iter()
            .map(|&i| {
                let (ix, iy) = spec.coords(i as usize);
                spec.center(ix, iy)
            })
            .collect();
        self.parked_from = self.points.len();
        for &p in &self.parked {
            let (ix, iy) = spec.clamp_cell(p);
            self.point_cells.push(spec.index(ix, iy) as u32);
            self.points.push(p);
        }
        let pts = &self.points;
        self.point_index = Buckets::build(&self.area, BUCKET_M, pts.len(), |k| (pts[k], pts[k]));
        true
    }

    /// Every sensed obstacle cell that counts for planning now, with its centre.
    pub fn planning_points(&self) -> impl Iterator<Item = (usize, V2)> + '_ {
        (0..self.points.len()).filter(|&k| self.counts(k)).map(|k| (self.point_cells[k] as usize, self.points[k]))
    }

    /// Whether the chair at `pose`, grown by `margin`, touches no known wall and no sensed
    /// obstacle.
    pub fn free(&self, pose: &Pose, margin: f64) -> bool {
        self.free_in(&pose.body_frame(), margin)
    }

    /// [`WorldModel::free`] for a pose whose frame is already computed (one sine and cosine
    /// for several margins).
    pub fn free_in(&self, frame: &BodyFrame, margin: f64) -> bool {
        self.fits_in(&self.footprint, frame, margin)
    }

    /// Whether a rectangle `fp` (another chair's, say) at `pose`, grown by `margin`, touches
    /// no known wall and no sensed obstacle.
    pub fn fits(&self, fp: &Footprint, pose: &Pose, margin: f64) -> bool {
        self.fits_in(fp, &pose.body_frame(), margin)
    }

    fn fits_in(&self, fp: &Footprint, frame: &BodyFrame, margin: f64) -> bool {
        let centre = frame.to_world(V2::new(fp.centre_offset(), 0.0));
        if !self.walls_clear(fp, frame, margin) {
            let reach = fp.centre_reach() + margin;
            let r = V2::new(reach, reach);
            let mut hit = false;
            self.seg_index.query(centre - r, centre + r, |k| {
                if !hit {
                    let s = self.segs[k];
                    hit = fp.meets_body_segment(frame.apply(s.a), frame.apply(s.b), margin);
                }
            });
            if hit {
                return false;
            }
        }
        if self.points.is_empty() {
            return true;
        }
        let mut hit = false;
        let grown = margin + self.sensed_extra + SENSED_RADIUS_M;
        let reach = fp.centre_reach() + grown;
        self.point_index.query_near(centre, reach, |k| {
            if !hit && self.counts(k) {
                hit = fp.contains_body(frame.apply(self.points[k]), grown);
            }
        });
        !hit
    }

    /// A quick, conservative answer from the walls' distance field: the rectangle grown by
    /// `margin` lies within three discs along its axis, each far enough from every wall.
    fn walls_clear(&self, fp: &Footprint, frame: &BodyFrame, margin: f64) -> bool {
        let len = fp.front + fp.rear;
        // sqrt, not hypot: this runs for every pose a search checks, and libm's hypot is slow.
        let radius = ((len / 6.0) * (len / 6.0) + fp.half * fp.half).sqrt() + margin;
        // Distances are between cell centres: allow for the point's and the wall's cells.
        let slack = self.spec().cell * std::f64::consts::SQRT_2;
        (0..3).all(|k| {
            let along = -fp.rear + len * (2 * k + 1) as f64 / 6.0;
            self.statics.distance_at(frame.to_world(V2::new(along, 0.0))) - slack > radius
        })
    }

    /// The chair's distance at `pose` to the nearest known wall or sensed obstacle, up to
    /// `cap` metres.
    pub fn clearance(&self, pose: &Pose, cap: f64) -> f64 {
        let fp = &self.footprint;
        let frame = pose.body_frame();
        let centre = frame.to_world(V2::new(fp.centre_offset(), 0.0));
        let reach = fp.centre_reach() + cap;
        let r = V2::new(reach, reach);
        let mut best = self.wall_clearance(pose, cap);
        self.point_index.query(centre - r, centre + r, |k| {
            if !self.counts(k) {
                return;
            }
            let p = frame.apply(self.points[k]);
            let d = fp.body_segment_distance(p, p) - SENSED_RADIUS_M - self.sensed_extra;
            best = best.min(d.max(0.0));
        });
        best
    }

    /// The chair's distance at `pose` to the nearest known wall, up to `cap` metres (0 when
    /// it overlaps one).
    pub fn wall_clearance(&self, pose: &Pose, cap: f64) -> f64 {
        let fp = &self.footprint;
        let frame = pose.body_frame();
        let centre = frame.to_world(V2::new(fp.centre_offset(), 0.0));
        let reach = fp.centre_reach() + cap;
        let r = V2::new(reach, reach);
        let mut best = cap;
        self.seg_index.query(centre - r, centre + r, |k| {
            let s = self.segs[k];
            best = best.min(fp.body_segment_distance(frame.apply(s.a), frame.apply(s.b)));
        });
        best
    }

    /// The chair's distance at `pose` to the nearest sensed obstacle (and parked chair), up
    /// to `cap` metres; negative when it overlaps one.
    pub fn sensed_clearance(&self, pose: &Pose, cap: f64) -> f64 {
        let fp = &self.footprint;
        let frame = pose.body_frame();
        let centre = frame.to_world(V2::new(fp.centre_offset(), 0.0));
        let mut best = cap;
        self.point_index.query_near(centre, fp.centre_reach() + cap, |k| {
            if self.counts(k) {
                let p = frame.apply(self.points[k]);
                best = best.min(fp.body_segment_distance(p, p) - SENSED_RADIUS_M - self.sensed_extra);
            }
        });
        best
    }

    /// Whether sensed point `k` counts as an obstacle for planning.
    fn counts(&self, k: usize) -> bool {
        k >= self.parked_from || self.sensed.evidence(self.point_cells[k] as usize) >= self.plan_evidence
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
        assert!(m.free(&Pose::from_deg(5.0, 1.9, 90.0), 0.0), "1.1 m long across 1.8 m: it fits…");
        assert!(!m.free(&Pose::from_deg(5.0, 2.0, 90.0), 0.0), "…but 0.1 m further the front hits");
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
        assert!(m.free(&Pose::from_deg(4.3, 1.9, 0.0), 0.05), "the front reaches 5.18 + 0.05");
        assert!(!m.free(&Pose::from_deg(4.6, 1.9, 0.0), 0.05), "the front would reach 5.48, past 5.38");
        assert!(m.free(&pose, 0.05));
    }
}
