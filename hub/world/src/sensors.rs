//! The sensor phase: proximity cones, compass, GPS, beacons, ground, collision and encoders,
//! each with its noise and latency.

use nalgebra::{Point2, Vector2};

use super::body::PreparedSensor;
use super::grid::{DynGrid, Segment, StaticIndex};
use super::{Geo, MAX_PROXIMITY, Robot, SensorReadings, World};
use crate::map::{Lab, Params};
use crate::math::{Real, cross, rotate, wire_deg, wrap_rad};
use crate::rng::{Draw, Rng};

/// What the measuring of one robot reads (borrowed apart from the robots and the generator).
struct Scene<'a> {
    statics: &'a StaticIndex,
    dyn_grid: &'a DynGrid,
    geo: &'a [Geo],
    lab: &'a Lab,
    params: &'a Params,
}

/// Candidate segments for one robot's proximity sensors.
struct Candidates<'a> {
    /// Copies of the wall and body edges some sensor may see, dense for the per-sensor loops;
    /// kept only for a robot with a cone wider than 180° (the scalar path reads them).
    segments: &'a mut Vec<Segment>,
    /// The same, relative to the robot and in f32.
    local: &'a mut Vec<LocalSegment>,
    /// Other robots' discs (centre, radius) some sensor may see.
    discs: &'a mut Vec<(Point2<Real>, Real)>,
}

/// Whether any sensor of a robot at `centre`, whose sensors sit within `inner` of it and see
/// no farther than `reach` from it, could read this segment: not when every sensor is behind
/// its face, and not when it is out of reach.
#[inline]
fn visible_from(seg: &Segment, centre: Point2<Real>, inner: Real, reach: Real) -> bool {
    let w = seg.a - centre;
    let h = -seg.normal.dot(&w);
    if h < -inner || h > reach {
        return false;
    }
    let t = (-w.dot(&seg.d) * seg.inv_len2).clamp(0.0, 1.0);
    (w + seg.d * t).norm_squared() <= reach * reach
}

impl World {
    /// Measures every robot on its committed pose and reports through the latency lines;
    /// `prime` reports straight out instead (readings before the first step, when no earlier
    /// reading exists to delay), with the same noise as any tick's: the stream is keyed by the
    /// tick and the robot's name and start pose (not its slot, which settles only at the
    /// first step), so priming twice draws the same values, whatever order robots came in. Measuring reads the neighbours only
    /// through `geo` and the grids, so each robot's readings are written in the same pass.
    pub(super) fn sense_with(&mut self, prime: bool, chunking: &super::Chunking) {
        let World { statics, dyn_grid, geo, lab, params, slots, seed, scratch, tick, .. } = self;
        let scene = Scene { statics, dyn_grid, geo, lab, params };
        let (seed, tick) = (*seed, *tick);
        let mut units = vec![(); slots.len()]; // zero-sized: never allocates
        super::run_chunks(chunking, slots, &mut units, &mut scratch.sense, |base, slots, _, sc| {
            let mut cands = Candidates { segments: &mut sc.segments, local: &mut sc.local, discs: &mut sc.discs };
            for (k, slot) in slots.iter_mut().enumerate() {
                let i = base + k;
                let Some(r) = &mut slot.robot else { continue };
                let key = if prime { super::prime_key(r) } else { super::stream_key(i, slot.generation) };
                let mut rng = Rng::stream(seed, key, tick, Draw::Sense);
                let now = scene.measure(i, r, &mut cands, &mut rng, tick);
                scene.report(r, now, prime);
            }
        });
    }
}

impl Scene<'_> {
    /// Puts a robot's readings of this tick through the latency lines (or, `prime`, straight
    /// out).
    fn report(&self, r: &mut Robot, now: SensorReadings, prime: bool) {
        let lat = self.params.latency;
        let depth = lat.max() as usize;
        if depth == 0 || prime {
            r.readings = now;
            return;
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
        // The heading's cosine and sine, computed when the pose was committed.
        let heading = self.geo[i].normals[0];
        let mut distances =
            proximity_all(&r.sensors[..r.sensor_count], pos, heading.x, heading.y, cands.local, cands.segments);
        // Discs are few next to wall edges: a scalar pass after the segment kernel.
        for &(centre, radius) in cands.discs.iter() {
            for (k, sensor) in r.sensors[..r.sensor_count].iter().enumerate() {
                let d = disc_proximity(sensor, pos, heading.x, heading.y, centre, radius);
                distances[k] = distances[k].min(d);
            }
        }
        // A plain Ciber-Rato robot (a disc) reads its IR as Ciber-Rato does, 1/d with the noise
        // added to that value; a chair's range sensors add it to the distance.
        let ciber_rato = r.spec.shape == crate::BodyShape::Disc;
        for (k, &d) in distances.iter().enumerate().take(r.sensor_count) {
            out.proximity_m[k] = match noise.proximity_m {
                sigma if sigma <= 0.0 => d,
                sigma if ciber_rato => {
                    // Readings stay within the sensor's range, as every reading does.
                    let inverse = rng.noisy(1.0 / d.max(1e-9), sigma);
                    let range = r.sensors[k].range;
                    if inverse * range > 1.0 { 1.0 / inverse } else { range }
                }
                sigma => rng.noisy(d, sigma).max(0.0),
            };
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
                let bearing = wrap_rad(v.y.atan2(v.x) - r.pose.theta);
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
        // Drawn last, so that the other readings keep the draws they had before there was a
        // line sensor.
        out.line = self.line_reading(r, heading, rng);
        out
    }

    /// The line sensor: each element reads whether it lies on a line on the floor, and reads
    /// the opposite with the chance [`crate::map::NoiseParams::line_flip_prob`] (in any lab: a
    /// lab without lines reads a stray 1 now and then, as Ciber-Rato's does).
    /// `heading` is the heading's cosine and sine.
    fn line_reading(&self, r: &Robot, heading: Vector2<Real>, rng: &mut Rng) -> u8 {
        let flip = self.params.noise.line_flip_prob;
        let lines = !self.statics.lines.is_empty();
        if !lines && flip <= 0.0 {
            return 0;
        }
        let (c, s) = (heading.x, heading.y);
        let mut bits = 0u8;
        for k in 0..super::LINE_ELEMENTS {
            let on = lines && {
                let (x, y) = super::line_element(k);
                self.statics.on_line(Point2::new(r.pose.x + c * x - s * y, r.pose.y + s * x + c * y))
            };
            let read = if flip > 0.0 && rng.next_f64() < flip { !on } else { on };
            bits |= u8::from(read) << k;
        }
        bits
    }

    /// Collects the wall and body edges that some sensor of the robot may see.
    fn gather(&self, i: usize, r: &Robot, cands: &mut Candidates<'_>) {
        cands.segments.clear();
        cands.local.clear();
        cands.discs.clear();
        let pos = r.pose.position();
        let (inner, reach) = (r.sensor_radius, r.reach);
        let e = Vector2::new(reach, reach);
        let (lo, hi) = (pos - e, pos + e);
        let s = self.statics;
        let (x0, y0, x1, y1) = s.spec.cell_range(lo, hi);
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                for &entry in s.edges_in(iy * s.spec.nx + ix) {
                    // Take each edge once: in the first of its cells inside the query box.
                    if !entry.first_in(ix, iy, x0, y0) {
                        continue;
                    }
                    let e = &s.edges[entry.index()];
                    if visible_from(&e.seg, pos, inner, reach) {
                        if r.any_wide {
                            cands.segments.push(e.seg);
                        }
                        cands.local.push(LocalSegment::new(&e.seg, pos));
                    }
                }
            }
        }
        self.dyn_grid.query(lo, hi, |j| {
            let g = &self.geo[j as usize];
            let near = reach + g.bound_radius;
            if j as usize != i && g.alive && (g.centre - pos).norm_squared() <= near * near {
                if g.disc_radius > 0.0 {
                    // A disc is read as its circle, not as the square around it.
                    cands.discs.push((g.centre, g.disc_radius));
                    return;
                }
                for k in 0..4 {
                    let seg =
                        Segment::with_normal(g.corners[k], g.corners[(k + 1) % 4], g.normals[k], g.inv_len2[k & 1]);
                    if visible_from(&seg, pos, inner, reach) {
                        if r.any_wide {
                            cands.segments.push(seg);
                        }
                        cands.local.push(LocalSegment::new(&seg, pos));
                    }
                }
            }
        });
    }
}

/// A candidate segment relative to the measuring robot's centre of movement, in `f32` for the
/// vectorised kernel (a few metres from the robot, f32 keeps well under a micrometre).
#[derive(Debug, Clone, Copy)]
pub(super) struct LocalSegment {
    ax: f32,
    ay: f32,
    dx: f32,
    dy: f32,
    nx: f32,
    ny: f32,
    inv_len2: f32,
}

impl LocalSegment {
    fn new(seg: &Segment, centre: Point2<Real>) -> Self {
        let a = seg.a - centre;
        Self {
            ax: a.x as f32,
            ay: a.y as f32,
            dx: seg.d.x as f32,
            dy: seg.d.y as f32,
            nx: seg.normal.x as f32,
            ny: seg.normal.y as f32,
            inv_len2: seg.inv_len2 as f32,
        }
    }
}

/// Eight f32 lanes, one per proximity sensor. Written as plain array loops, which LLVM turns
/// into SIMD on any x86-64 (two SSE registers) without `unsafe` or nightly features.
#[derive(Debug, Clone, Copy, PartialEq)]
struct F8([f32; 8]);

/// Eight lane masks, each all ones or all zeros: the form an SSE compare gives, so a select
/// is three bitwise operations. (As `[bool; 8]` every select widened bytes to lanes first, and
/// selects and mins took a third of sensing.)
#[derive(Debug, Clone, Copy)]
struct M8([u32; 8]);

// Index loops over the eight lanes are the shape LLVM vectorises most reliably.
#[allow(clippy::needless_range_loop)]
impl F8 {
    const ZERO: F8 = F8([0.0; 8]);

    #[inline(always)]
    fn splat(v: f32) -> F8 {
        F8([v; 8])
    }

    #[inline(always)]
    fn zip(self, o: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        let mut r = [0.0; 8];
        for k in 0..8 {
            r[k] = f(self.0[k], o.0[k]);
        }
        F8(r)
    }

    #[inline(always)]
    fn test(self, o: F8, f: impl Fn(f32, f32) -> bool) -> M8 {
        let mut r = [0; 8];
        for k in 0..8 {
            r[k] = if f(self.0[k], o.0[k]) { u32::MAX } else { 0 };
        }
        M8(r)
    }

    #[inline(always)]
    fn min(self, o: F8) -> F8 {
        self.zip(o, |a, b| if a < b { a } else { b })
    }

    #[inline(always)]
    fn clamp01(self) -> F8 {
        self.zip(F8::ZERO, |a, _| a.clamp(0.0, 1.0))
    }

    #[inline(always)]
    fn ge(self, o: F8) -> M8 {
        self.test(o, |a, b| a >= b)
    }

    #[inline(always)]
    fn le(self, o: F8) -> M8 {
        self.test(o, |a, b| a <= b)
    }
}

#[allow(clippy::needless_range_loop)]
impl M8 {
    #[inline(always)]
    fn and(self, o: M8) -> M8 {
        let mut r = [0; 8];
        for k in 0..8 {
            r[k] = self.0[k] & o.0[k];
        }
        M8(r)
    }

    #[inline(always)]
    fn select(self, yes: F8, no: F8) -> F8 {
        let mut r = [0.0; 8];
        for k in 0..8 {
            r[k] = f32::from_bits((self.0[k] & yes.0[k].to_bits()) | (!self.0[k] & no.0[k].to_bits()));
        }
        F8(r)
    }
}

macro_rules! f8_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl std::ops::$tr for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                self.zip(o, |a, b| a $op b)
            }
        }
    };
}
f8_op!(Add, add, +);
f8_op!(Sub, sub, -);
f8_op!(Mul, mul, *);
f8_op!(Div, div, /);

impl std::ops::Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.zip(F8::ZERO, |a, _| -a)
    }
}

/// Whether each lane's point (x, y) lies in its cone (u1 → u2 counter-clockwise).
#[inline(always)]
fn in_cone((u1x, u1y, u2x, u2y): (F8, F8, F8, F8), x: F8, y: F8) -> M8 {
    (u1x * y - u1y * x).ge(F8::ZERO).and((x * u2y - y * u2x).ge(F8::ZERO))
}

/// Squared distance along the cone edge u to where it crosses the segment w + t·d, or ∞.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn cross_edge_sq(ux: F8, uy: F8, wx: F8, wy: F8, dx: F8, dy: F8, w_x_d: F8) -> F8 {
    let den = ux * dy - uy * dx;
    let s = w_x_d / den;
    let t = (wx * uy - wy * ux) / den;
    s.ge(F8::ZERO).and(t.ge(F8::ZERO)).and(t.le(F8::splat(1.0))).select(s * s, F8::splat(f32::INFINITY))
}

/// Every sensor's distance to the nearest segment inside its cone, capped at its range.
///
/// The sensors are laid out as eight lanes and each segment is tested against all of them
/// without branches: which edge a cone sees, and whether its nearest point is inside or on the
/// cone's border, change from robot to robot, and as branches they were mispredicted often
/// enough to double the cost of a tick. Cones wider than 180° take the scalar path.
///
/// On a CPU with AVX2 the same code runs compiled for it (the eight lanes fit one register
/// instead of two). The operations are the same IEEE ones either way (Rust never fuses a
/// multiply and an add on its own), so the readings are bit for bit the same on any x86-64.
fn proximity_all(
    sensors: &[PreparedSensor],
    pos: Point2<Real>,
    c: Real,
    s: Real,
    local: &[LocalSegment],
    segments: &[Segment],
) -> [Real; MAX_PROXIMITY] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has just been found to support AVX2, all the function enables.
        #[allow(unsafe_code)]
        return unsafe { proximity_all_avx2(sensors, pos, c, s, local, segments) };
    }
    proximity_all_inline(sensors, pos, c, s, local, segments)
}

/// [`proximity_all`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn proximity_all_avx2(
    sensors: &[PreparedSensor],
    pos: Point2<Real>,
    c: Real,
    s: Real,
    local: &[LocalSegment],
    segments: &[Segment],
) -> [Real; MAX_PROXIMITY] {
    proximity_all_inline(sensors, pos, c, s, local, segments)
}

/// The body of [`proximity_all`], inlined into each of its compilations.
#[inline(always)]
fn proximity_all_inline(
    sensors: &[PreparedSensor],
    pos: Point2<Real>,
    c: Real,
    s: Real,
    local: &[LocalSegment],
    segments: &[Segment],
) -> [Real; MAX_PROXIMITY] {
    const L: usize = MAX_PROXIMITY;
    let (mut px, mut py, mut u1x, mut u1y, mut u2x, mut u2y) =
        (F8::ZERO, F8::ZERO, F8::ZERO, F8::ZERO, F8::ZERO, F8::ZERO);
    let mut best_sq = F8::ZERO;
    for (k, sensor) in sensors.iter().enumerate() {
        let p = rotate(sensor.origin, c, s);
        let (r, l) = (rotate(sensor.edge_right, c, s), rotate(sensor.edge_left, c, s));
        (px.0[k], py.0[k]) = (p.x as f32, p.y as f32);
        (u1x.0[k], u1y.0[k], u2x.0[k], u2y.0[k]) = (r.x as f32, r.y as f32, l.x as f32, l.y as f32);
        best_sq.0[k] = (sensor.range * sensor.range) as f32;
    }
    let inf = F8::splat(f32::INFINITY);
    for seg in local {
        let wx = F8::splat(seg.ax) - px;
        let wy = F8::splat(seg.ay) - py;
        let (dx, dy) = (F8::splat(seg.dx), F8::splat(seg.dy));
        let facing = (F8::splat(seg.nx) * wx + F8::splat(seg.ny) * wy).le(F8::ZERO);
        // The segment's closest point to the sensor.
        let t = (-(wx * dx + wy * dy) * F8::splat(seg.inv_len2)).clamp01();
        let (qx, qy) = (wx + dx * t, wy + dy * t);
        let cone = (u1x, u1y, u2x, u2y);
        // Otherwise the nearest point inside the cone is an end of the segment inside it,
        // or where the segment crosses one of the cone's edges.
        let (bx, by) = (wx + dx, wy + dy);
        let a_sq = in_cone(cone, wx, wy).select(wx * wx + wy * wy, inf);
        let b_sq = in_cone(cone, bx, by).select(bx * bx + by * by, inf);
        let w_x_d = wx * dy - wy * dx;
        let edge_sq =
            cross_edge_sq(u1x, u1y, wx, wy, dx, dy, w_x_d).min(cross_edge_sq(u2x, u2y, wx, wy, dx, dy, w_x_d));
        let d_sq = in_cone(cone, qx, qy).select(qx * qx + qy * qy, a_sq.min(b_sq).min(edge_sq));
        best_sq = best_sq.min(facing.select(d_sq, inf));
    }
    let best_sq = best_sq.0;
    let mut out = [0.0; L];
    for (k, sensor) in sensors.iter().enumerate() {
        out[k] = if sensor.wide {
            proximity(sensor, pos, c, s, segments)
        } else {
            (best_sq[k] as Real).sqrt().min(sensor.range)
        };
    }
    out
}

/// The distance from a sensor to the nearest segment inside its cone, capped at its range.
#[inline]
fn proximity(sensor: &PreparedSensor, pos: Point2<Real>, c: Real, s: Real, segments: &[Segment]) -> Real {
    let p = pos + rotate(sensor.origin, c, s);
    let right = rotate(sensor.edge_right, c, s);
    let left = rotate(sensor.edge_left, c, s);
    let mut best = sensor.range;
    let mut best_sq = best * best;
    if sensor.wide {
        // A cone wider than 180° is not convex: split it at its axis into two that are.
        let axis = rotate(sensor.axis, c, s);
        for seg in segments {
            cone_distance_sq(p, right, axis, seg, &mut best, &mut best_sq);
            cone_distance_sq(p, axis, left, seg, &mut best, &mut best_sq);
        }
    } else {
        for seg in segments {
            cone_distance_sq(p, right, left, seg, &mut best, &mut best_sq);
        }
    }
    best
}

/// The distance from a sensor to the nearest point of a disc inside its cone, capped at its
/// range (the disc's circle, as Ciber-Rato's sensors see another robot).
fn disc_proximity(
    sensor: &PreparedSensor,
    pos: Point2<Real>,
    c: Real,
    s: Real,
    centre: Point2<Real>,
    radius: Real,
) -> Real {
    let p = pos + rotate(sensor.origin, c, s);
    let right = rotate(sensor.edge_right, c, s);
    let left = rotate(sensor.edge_left, c, s);
    let d = if sensor.wide {
        // Not convex: split at the axis, as for segments.
        let axis = rotate(sensor.axis, c, s);
        cone_disc_distance(p, right, axis, centre, radius).min(cone_disc_distance(p, axis, left, centre, radius))
    } else {
        cone_disc_distance(p, right, left, centre, radius)
    };
    d.min(sensor.range)
}

/// The distance from `p` to the part of the disc (`centre`, `radius`) inside the convex cone
/// spanned counter-clockwise from `u1` to `u2` (at most 180°), or ∞ when the cone misses it.
///
/// When the disc's nearest point to `p` lies in the cone, that is the answer. Otherwise the
/// nearest point of the (convex) part of the disc inside the cone lies on one of the cone's
/// edges: where that ray enters the disc.
pub(crate) fn cone_disc_distance(
    p: Point2<Real>,
    u1: Vector2<Real>,
    u2: Vector2<Real>,
    centre: Point2<Real>,
    radius: Real,
) -> Real {
    let w = centre - p;
    let dist_sq = w.norm_squared();
    let excess = dist_sq - radius * radius;
    if excess <= 0.0 {
        // The sensor is inside the disc.
        return 0.0;
    }
    if cross(u1, w) >= 0.0 && cross(w, u2) >= 0.0 {
        return dist_sq.sqrt() - radius;
    }
    let mut best = Real::INFINITY;
    for u in [u1, u2] {
        let b = u.dot(&w);
        let disc = b * b - excess;
        if b > 0.0 && disc >= 0.0 {
            best = best.min(b - disc.sqrt());
        }
    }
    best
}

fn noisy_deg(rng: &mut Rng, angle_rad: Real, sigma_deg: Real) -> Real {
    if sigma_deg > 0.0 { wire_deg(angle_rad + (sigma_deg * rng.gaussian()).to_radians()) } else { wire_deg(angle_rad) }
}

/// Lowers `best` (and `best_sq` = best²) to the distance from `p` to the part of `seg` inside
/// the convex cone spanned counter-clockwise from `u1` to `u2` (at most 180°), if nearer.
///
/// An edge whose back faces the sensor cannot hold the nearest point of its solid (the front
/// edges are nearer along every line from `p`), and an edge whose line is already farther than
/// `best` cannot improve it: both tests are one dot product and reject most edges. When the
/// segment's closest point to `p` lies in the cone, that is the answer; only otherwise is the
/// segment clipped to the cone.
#[inline]
pub(crate) fn cone_distance_sq(
    p: Point2<Real>,
    u1: Vector2<Real>,
    u2: Vector2<Real>,
    seg: &Segment,
    best: &mut Real,
    best_sq: &mut Real,
) {
    let w = seg.a - p;
    let h = -seg.normal.dot(&w);
    if h < 0.0 || h >= *best {
        return;
    }
    let t_star = (-w.dot(&seg.d) * seg.inv_len2).clamp(0.0, 1.0);
    let q = w + seg.d * t_star;
    let dist_sq = if cross(u1, q) >= 0.0 && cross(q, u2) >= 0.0 {
        q.norm_squared()
    } else {
        match clipped_distance_sq(u1, u2, w, seg.d, t_star) {
            Some(d) => d,
            None => return,
        }
    };
    if dist_sq < *best_sq {
        *best_sq = dist_sq;
        *best = dist_sq.sqrt();
    }
}

/// The squared distance to the part of the segment w + t·d (relative to the apex) inside the
/// cone, given that its unconstrained closest point t* is outside the cone: the answer is the
/// clipped end nearer to t*.
#[cold]
fn clipped_distance_sq(
    u1: Vector2<Real>,
    u2: Vector2<Real>,
    w: Vector2<Real>,
    d: Vector2<Real>,
    t_star: Real,
) -> Option<Real> {
    // Keep the part of w + t·d with cross(u1, ·) ≥ 0 and cross(·, u2) ≥ 0; k0 + t·k1 is
    // each side's value along the segment.
    let sides = [(cross(u1, w), cross(u1, d)), (cross(w, u2), cross(d, u2))];
    // Both ends outside one side: the segment misses the cone, and no division is needed.
    if sides.iter().any(|&(k0, k1)| k0 < 0.0 && k0 + k1 < 0.0) {
        return None;
    }
    let (mut t0, mut t1) = (0.0, 1.0);
    for (k0, k1) in sides {
        if k1 > 0.0 {
            t0 = Real::max(t0, -k0 / k1);
        } else if k1 < 0.0 {
            t1 = Real::min(t1, -k0 / k1);
        } else if k0 < 0.0 {
            return None;
        }
    }
    if t0 > t1 {
        return None;
    }
    let t = t_star.clamp(t0, t1);
    Some((w + d * t).norm_squared())
}

/// The distance form of [`cone_distance_sq`], for tests.
#[cfg(test)]
fn cone_distance(
    p: Point2<Real>,
    u1: Vector2<Real>,
    u2: Vector2<Real>,
    a: Point2<Real>,
    b: Point2<Real>,
    normal: Vector2<Real>,
    best: Real,
) -> Real {
    let len2 = (b - a).norm_squared();
    let seg = Segment::with_normal(a, b, normal, 1.0 / len2);
    let (mut best, mut best_sq) = (best, best * best);
    cone_distance_sq(p, u1, u2, &seg, &mut best, &mut best_sq);
    best
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
        let d = cone_distance(
            Point2::origin(),
            unit(-30.0),
            unit(30.0),
            Point2::new(2.0, 10.0),
            Point2::new(2.0, 1.0),
            Vector2::new(-1.0, 0.0),
            10.0,
        );
        assert!((d - 5f64.sqrt()).abs() < 1e-12, "{d}");
    }

    proptest::proptest! {
        /// `sim_model::cone_range`, which clients use to predict readings from the map, is
        /// this model: on random walls and cones both give one range (the hub's segments are
        /// one-sided, so each wall is tried both ways round).
        #[test]
        fn sim_models_cone_range_is_the_hubs_proximity(
            (x, y, a, cone) in (-1.0f64..1.0, -1.0f64..1.0, -3.2f64..3.2, 0.05f64..3.1),
            heading in -3.2f64..3.2,
            (wx, wy, dx, dy) in (-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0),
        ) {
            let spec = crate::ProximitySpec { x_m: x, y_m: y, angle_rad: a, cone_rad: cone, range_m: Some(4.0) };
            let sensor = PreparedSensor::new(&spec, 4.0);
            let (p, q) = (Point2::new(wx, wy), Point2::new(wx + dx, wy + dy));
            let segments: Vec<Segment> = [Segment::new(p, q), Segment::new(q, p)].into_iter().flatten().collect();
            proptest::prop_assume!(segments.len() == 2);
            let (s, c) = heading.sin_cos();
            let hub = proximity(&sensor, Point2::origin(), c, s, &segments);
            let apex = [x * c - y * s, x * s + y * c];
            let client = sim_model::cone_range(apex, heading + a, cone, [p.x, p.y], [q.x, q.y], 4.0);
            proptest::prop_assert!((hub - client).abs() < 1e-9, "hub {} vs sim-model {}", hub, client);
        }
    }

    proptest::proptest! {
        /// The eight-lane f32 kernel and the scalar f64 path agree within 0.1 mm on random
        /// walls and sensors.
        #[test]
        fn the_vector_kernel_agrees_with_the_scalar_cone_distance(
            heading in -3.2f64..3.2,
            cx in 40.0f64..60.0,
            cy in 40.0f64..60.0,
            cones in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -3.2f64..3.2, 0.05f64..3.1), 1..=8),
            walls in proptest::collection::vec((35.0f64..65.0, 35.0f64..65.0, -5.0f64..5.0, -5.0f64..5.0), 1..12),
        ) {
            let sensors: Vec<PreparedSensor> = cones
                .iter()
                .map(|&(x, y, a, cone)| PreparedSensor::new(&crate::ProximitySpec { x_m: x, y_m: y, angle_rad: a, cone_rad: cone, range_m: Some(4.0) }, 4.0))
                .collect();
            let segments: Vec<Segment> = walls.iter().filter_map(|&(x, y, dx, dy)| Segment::new(Point2::new(x, y), Point2::new(x + dx, y + dy))).collect();
            let centre = Point2::new(cx, cy);
            let local: Vec<LocalSegment> = segments.iter().map(|s| LocalSegment::new(s, centre)).collect();
            let (s, c) = heading.sin_cos();
            let fast = proximity_all(&sensors, centre, c, s, &local, &segments);
            // The compilation for this CPU (AVX2 where it has it) and the baseline one agree
            // bit for bit, so a seeded run does not depend on the machine.
            let baseline = proximity_all_inline(&sensors, centre, c, s, &local, &segments);
            proptest::prop_assert_eq!(fast.map(f64::to_bits), baseline.map(f64::to_bits));
            for (k, sensor) in sensors.iter().enumerate() {
                let slow = proximity(sensor, centre, c, s, &segments);
                proptest::prop_assert!((fast[k] - slow).abs() < 1e-4, "sensor {k}: {} vs {}", fast[k], slow);
            }
        }
    }

    #[test]
    fn a_disc_reads_as_its_circle_inside_the_cone() {
        let o = Point2::origin();
        // Straight ahead: the distance to the circle.
        let d = cone_disc_distance(o, unit(-30.0), unit(30.0), Point2::new(3.0, 0.0), 0.5);
        assert!((d - 2.5).abs() < 1e-12, "{d}");
        // A disc off to the side, clipped by the cone's left edge: where that ray enters it.
        // Centre (2, 2), edge at 30°: b = u·w = 2cos30 + 2sin30, the entry is b − √(b² − (8 − r²)).
        let (b, r) = (2.0 * 30f64.to_radians().cos() + 2.0 * 30f64.to_radians().sin(), 0.8);
        let want = b - (b * b - (8.0 - r * r)).sqrt();
        let d = cone_disc_distance(o, unit(-30.0), unit(30.0), Point2::new(2.0, 2.0), r);
        assert!((d - want).abs() < 1e-12, "{d} vs {want}");
        // The cone misses a disc behind it, and a sensor inside a disc reads 0.
        assert_eq!(cone_disc_distance(o, unit(-30.0), unit(30.0), Point2::new(-3.0, 0.0), 0.5), f64::INFINITY);
        assert_eq!(cone_disc_distance(o, unit(-30.0), unit(30.0), Point2::new(0.2, 0.1), 0.5), 0.0);
    }

    #[test]
    fn farther_than_best_leaves_best() {
        let (a, b, n) = face();
        assert_eq!(cone_distance(Point2::origin(), unit(-30.0), unit(30.0), a, b, n, 1.5), 1.5);
    }
}
