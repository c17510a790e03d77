//! The sensor phase: proximity cones, compass, GPS, beacons, ground, collision and encoders,
//! each with its noise and latency.

use nalgebra::{Point2, Vector2};

use super::body::PreparedSensor;
use super::grid::{DynGrid, StaticIndex};
use super::{Geo, Robot, SensorReadings, World};
use crate::map::{Lab, Params};
use crate::math::{Real, cross, normalize_angle, rotate, wire_deg};
use crate::rng::Rng;

/// What the measuring of one robot reads (borrowed apart from the mutable generator).
struct Scene<'a> {
    statics: &'a StaticIndex,
    dyn_grid: &'a DynGrid,
    geo: &'a [Geo],
    lab: &'a Lab,
    params: &'a Params,
}

/// Candidate lists for one robot's proximity sensors.
struct Candidates<'a> {
    edge_stamp: &'a mut Vec<u32>,
    stamp: &'a mut u32,
    /// Copies of the wall and body edges some sensor may see, dense for the per-sensor loops.
    edges: &'a mut Vec<Segment>,
}

/// A segment with its outward normal.
#[derive(Debug, Clone, Copy)]
pub(super) struct Segment {
    a: Point2<Real>,
    b: Point2<Real>,
    normal: Vector2<Real>,
}

impl Segment {
    /// Whether any sensor of a robot at `centre`, whose sensors sit within `inner` of it and
    /// see `reach − inner` far, could read this segment: not when every sensor is behind its
    /// face, and not when it is out of reach.
    #[inline]
    fn visible_from(&self, centre: Point2<Real>, inner: Real, reach: Real) -> bool {
        let w = self.a - centre;
        let h = -self.normal.dot(&w);
        if h < -inner || h > reach {
            return false;
        }
        let d = self.b - self.a;
        let dd = d.norm_squared();
        let t = if dd > 0.0 { (-w.dot(&d) / dd).clamp(0.0, 1.0) } else { 0.0 };
        (w + d * t).norm_squared() <= reach * reach
    }
}

impl World {
    pub(super) fn sense(&mut self) {
        let World { statics, dyn_grid, geo, lab, params, slots, rng, scratch, tick, .. } = self;
        let scene = Scene { statics, dyn_grid, geo, lab, params };
        let mut measured = std::mem::take(&mut scratch.measured);
        measured.clear();
        measured.resize(slots.len(), SensorReadings::EMPTY);
        let mut cands = Candidates {
            edge_stamp: &mut scratch.edge_stamp,
            stamp: &mut scratch.stamp,
            edges: &mut scratch.edges,
        };
        for (i, slot) in slots.iter().enumerate() {
            if let Some(r) = &slot.robot {
                measured[i] = scene.measure(i, r, &mut cands, rng, *tick);
            }
        }
        let lat = params.latency;
        let depth = lat.max() as usize;
        for (i, slot) in slots.iter_mut().enumerate() {
            let Some(r) = &mut slot.robot else { continue };
            let now = measured[i];
            if depth == 0 {
                r.readings = now;
                continue;
            }
            r.history.push_front(now);
            r.history.truncate(depth + 1);
            let past = |l: u32| r.history.get(l as usize);
            let mut out = now;
            match past(lat.proximity) {
                Some(p) => out.proximity_m = p.proximity_m,
                None => {
                    for k in 0..r.sensor_count {
                        out.proximity_m[k] = r.sensors[k].range;
                    }
                }
            }
            out.compass_deg = past(lat.compass).and_then(|p| p.compass_deg);
            out.gps = past(lat.gps).and_then(|p| p.gps);
            out.beacons_deg = past(lat.beacon).map_or([None; super::MAX_BEACONS], |p| p.beacons_deg);
            out.ground = past(lat.ground).and_then(|p| p.ground);
            out.collision = past(lat.collision).is_some_and(|p| p.collision);
            r.readings = out;
        }
        scratch.measured = measured;
    }
}

impl Scene<'_> {
    fn measure(&self, i: usize, r: &Robot, cands: &mut Candidates<'_>, rng: &mut Rng, tick: u64) -> SensorReadings {
        let noise = &self.params.noise;
        let pos = r.pose.position();
        let mut out = SensorReadings {
            tick,
            proximity_count: r.sensor_count as u8,
            beacon_count: self.lab.beacons.len() as u8,
            collision: r.collision,
            encoder_ticks: r.readings.encoder_ticks,
            ..SensorReadings::EMPTY
        };

        self.gather(i, r, cands);
        let (s, c) = r.pose.theta.sin_cos();
        for k in 0..r.sensor_count {
            let d = Self::proximity(&r.sensors[k], pos, c, s, cands);
            out.proximity_m[k] = if noise.proximity_m > 0.0 { rng.noisy(d, noise.proximity_m).max(0.0) } else { d };
        }

        if self.params.sensors.compass {
            out.compass_deg = Some(noisy_deg(rng, r.pose.theta, noise.compass_deg));
        }
        if self.params.sensors.gps {
            out.gps = Some(super::GpsReading {
                x_m: rng.noisy(r.pose.x, noise.gps_pos_m),
                y_m: rng.noisy(r.pose.y, noise.gps_pos_m),
                heading_deg: noisy_deg(rng, r.pose.theta, noise.gps_heading_deg),
            });
        }
        if self.params.sensors.beacon {
            for (b, beacon) in self.lab.beacons.iter().enumerate() {
                let v = beacon.pos - pos;
                let bearing = normalize_angle(v.y.atan2(v.x) - r.pose.theta);
                let visible = bearing.abs() <= self.params.beacon_aperture_rad
                    && !self.statics.segment_blocked(pos, beacon.pos, beacon.height_m);
                out.beacons_deg[b] = visible.then(|| noisy_deg(rng, bearing, noise.beacon_deg));
            }
        }
        out.ground = self
            .lab
            .targets
            .iter()
            .position(|t| (t.pos - pos).norm_squared() <= t.radius_m * t.radius_m)
            .map(|t| t as u16);
        out
    }

    /// Collects the wall and body edges that some sensor of the robot may see.
    fn gather(&self, i: usize, r: &Robot, cands: &mut Candidates<'_>) {
        cands.edges.clear();
        *cands.stamp = cands.stamp.wrapping_add(1);
        if *cands.stamp == 0 {
            cands.edge_stamp.iter_mut().for_each(|s| *s = 0);
            *cands.stamp = 1;
        }
        let stamp = *cands.stamp;
        let pos = r.pose.position();
        let (inner, reach) = (r.sensor_radius, r.reach);
        let e = Vector2::new(reach, reach);
        let (lo, hi) = (pos - e, pos + e);
        let s = self.statics;
        let (x0, y0, x1, y1) = s.spec.cell_range(lo, hi);
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                for &edge in s.edges_in(iy * s.spec.nx + ix) {
                    let seen = &mut cands.edge_stamp[edge as usize];
                    if *seen != stamp {
                        *seen = stamp;
                        let e = &s.edges[edge as usize];
                        let seg = Segment { a: e.a, b: e.b, normal: e.normal };
                        if seg.visible_from(pos, inner, reach) {
                            cands.edges.push(seg);
                        }
                    }
                }
            }
        }
        self.dyn_grid.query(lo, hi, |j| {
            let g = &self.geo[j as usize];
            let near = reach + g.bound_radius;
            if j as usize != i && g.alive && (g.centre - pos).norm_squared() <= near * near {
                for k in 0..4 {
                    let seg = Segment { a: g.corners[k], b: g.corners[(k + 1) % 4], normal: g.normals[k] };
                    if seg.visible_from(pos, inner, reach) {
                        cands.edges.push(seg);
                    }
                }
            }
        });
    }

    /// The distance from a sensor to the nearest wall or body inside its cone, capped at its
    /// range.
    fn proximity(sensor: &PreparedSensor, pos: Point2<Real>, c: Real, s: Real, cands: &Candidates<'_>) -> Real {
        let p = pos + rotate(sensor.origin, c, s);
        let right = rotate(sensor.edge_right, c, s);
        let left = rotate(sensor.edge_left, c, s);
        // A cone wider than 180° is not convex: split it at its axis into two that are.
        let halves: [(Vector2<Real>, Vector2<Real>); 2];
        let cones: &[(Vector2<Real>, Vector2<Real>)] = if sensor.wide {
            let axis = rotate(sensor.axis, c, s);
            halves = [(right, axis), (axis, left)];
            &halves
        } else {
            halves = [(right, left), (right, left)];
            &halves[..1]
        };
        let mut best = sensor.range;
        for &(u1, u2) in cones {
            for seg in cands.edges.iter() {
                best = cone_distance(p, u1, u2, seg.a, seg.b, seg.normal, best);
            }
        }
        best
    }
}

fn noisy_deg(rng: &mut Rng, angle_rad: Real, sigma_deg: Real) -> Real {
    if sigma_deg > 0.0 { wire_deg(angle_rad + (sigma_deg * rng.gaussian()).to_radians()) } else { wire_deg(angle_rad) }
}

/// Distance from `p` to the part of segment a→b inside the convex cone spanned
/// counter-clockwise from `u1` to `u2` (at most 180°), or `best` when that is nearer.
///
/// `normal` is the segment's outward normal: an edge whose back faces the sensor cannot hold
/// the nearest point of its wall (the front edges are nearer along every line from `p`), and an
/// edge whose line is already farther than `best` cannot improve it; both tests are a dot
/// product, and they reject most edges before any clipping.
#[inline]
pub(crate) fn cone_distance(
    p: Point2<Real>,
    u1: Vector2<Real>,
    u2: Vector2<Real>,
    a: Point2<Real>,
    b: Point2<Real>,
    normal: Vector2<Real>,
    best: Real,
) -> Real {
    let w = a - p;
    let h = -normal.dot(&w);
    if h < 0.0 || h >= best {
        return best;
    }
    let d = b - a;
    let (mut t0, mut t1) = (0.0, 1.0);
    // Keep the part of a + t·d with cross(u1, ·) ≥ 0 and cross(·, u2) ≥ 0.
    for (k0, k1) in [(cross(u1, w), cross(u1, d)), (cross(w, u2), cross(d, u2))] {
        if k1 > 0.0 {
            t0 = Real::max(t0, -k0 / k1);
        } else if k1 < 0.0 {
            t1 = Real::min(t1, -k0 / k1);
        } else if k0 < 0.0 {
            return best;
        }
    }
    if t0 > t1 {
        return best;
    }
    let dd = d.norm_squared();
    let t = if dd > 0.0 { (-w.dot(&d) / dd).clamp(t0, t1) } else { t0 };
    let dist = (w + d * t).norm();
    if dist < best { dist } else { best }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(deg: Real) -> Vector2<Real> {
        let a = deg.to_radians();
        Vector2::new(a.cos(), a.sin())
    }

    /// A wall face x = 2 from y = −5 to 5, seen from the origin (its outward normal is −x).
    fn face() -> (Point2<Real>, Point2<Real>, Vector2<Real>) {
        (Point2::new(2.0, 5.0), Point2::new(2.0, -5.0), Vector2::new(-1.0, 0.0))
    }

    #[test]
    fn a_face_straight_ahead_reads_its_perpendicular_distance() {
        let (a, b, n) = face();
        let d = cone_distance(Point2::origin(), unit(-30.0), unit(30.0), a, b, n, 10.0);
        assert!((d - 2.0).abs() < 1e-12, "{d}");
    }

    #[test]
    fn a_cone_that_misses_the_foot_reads_the_nearest_point_on_its_edge() {
        let (a, b, n) = face();
        // Cone from 40° to 80°: nearest point of the face inside it is along the 40° edge.
        let d = cone_distance(Point2::origin(), unit(40.0), unit(80.0), a, b, n, 10.0);
        assert!((d - 2.0 / 40f64.to_radians().cos()).abs() < 1e-12, "{d}");
    }

    #[test]
    fn a_face_behind_the_cone_or_its_back_is_not_seen() {
        let (a, b, n) = face();
        assert_eq!(cone_distance(Point2::origin(), unit(150.0), unit(210.0), a, b, n, 10.0), 10.0);
        // The same face seen from behind (x = 3) is the wall's back: skipped.
        assert_eq!(cone_distance(Point2::new(3.0, 0.0), unit(150.0), unit(210.0), a, b, n, 10.0), 10.0);
    }

    #[test]
    fn a_corner_inside_the_cone_is_the_nearest_point() {
        // A face from (2, 1) to (2, 10) seen with a ±30° cone: the corner at (2, 1) is in the
        // cone (26.6°), so the distance is √5.
        let d = cone_distance(Point2::origin(), unit(-30.0), unit(30.0), Point2::new(2.0, 10.0), Point2::new(2.0, 1.0), Vector2::new(-1.0, 0.0), 10.0);
        assert!((d - 5f64.sqrt()).abs() < 1e-12, "{d}");
    }

    #[test]
    fn farther_than_best_leaves_best() {
        let (a, b, n) = face();
        assert_eq!(cone_distance(Point2::origin(), unit(-30.0), unit(30.0), a, b, n, 1.5), 1.5);
    }
}
