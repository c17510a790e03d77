//! Map matching: the chair's odometry pose corrected by its real range readings of the walls
//! the map knows.
//!
//! Wheels slip, and the encoders cannot see it: over a corridor the odometry pose drifts a
//! few centimetres and a degree or two. In augmented mode that matters twice over, because the
//! hub places the chair's virtual twin at the pose the adapter pushes: virtual obstacles stand
//! in that frame while the real walls stand in the true one, and a gap between a virtual box
//! and a real wall is narrower in one frame than the chair believes. So the adapter localises
//! the chair before it pushes the pose: each tick it predicts what every sensor should read
//! off the map's walls (`sim_model::cone_range`, the hub's own proximity model) from the
//! current estimate, and moves the estimate a little towards the pose whose predictions agree
//! with the readings (one damped Gauss–Newton step on x, y and heading).
//!
//! Only what the map and the room share can be matched: the lab's border and its walls, never
//! a scenario's obstacles (the room has none of the virtual ones) nor whatever stands only in
//! the room. So a reading is used only when it is finite and the map predicts a wall within
//! its reach and near it ([`GATE_M`]); the rest (a box the map lacks, a sonar's dropout or
//! spurious echo, another chair) is left out. The step is damped and bounded per tick, so the
//! estimate moves smoothly; directions the readings cannot tell (along a straight corridor)
//! keep odometry's value. Deterministic: no randomness, only the readings and the odometry.

use std::f64::consts::PI;

use agent_sdk::map::Map;
use ipc_types::MAX_PROXIMITY;
use sim_model::chair::{Mount, SENSORS};
use sim_model::{Pose, cone_range, wrap_rad};

/// A reading farther than this from the map's prediction is not a known wall, metres.
pub const GATE_M: f64 = 0.25;
/// The share of the Gauss–Newton step taken each tick: corrections are spread over a few
/// ticks, so one tick's noise barely moves the pose.
pub const GAIN: f64 = 0.3;
/// The largest correction of the position in one tick, metres.
pub const MAX_STEP_M: f64 = 0.02;
/// The largest correction of the heading in one tick, radians (0.5°).
pub const MAX_TURN_RAD: f64 = 0.5 * PI / 180.0;
/// The damping on each unknown (a prior that the odometry is right), in the units of the
/// normal equations: large against a well-seen direction, decisive for an unseen one.
const DAMPING: [f64; 3] = [0.05, 0.05, 0.05];
/// Fewer matched readings than this leave the pose to odometry.
const MIN_READINGS: usize = 2;

/// The odometry pose and the correction learnt so far.
#[derive(Debug, Clone, PartialEq)]
pub struct Localiser {
    /// Wall segments the room shares with the map: `[ax, ay, bx, by]`.
    segments: Vec<[f64; 4]>,
    /// The correction as a rigid transform of the odometry frame: rotation, then translation.
    turn: f64,
    shift: [f64; 2],
    /// Readings matched at the last tick.
    matched: usize,
}

impl Localiser {
    /// A localiser on the map's known walls (its border and its walls, not the scenario's
    /// obstacles).
    pub fn new(map: &Map) -> Localiser {
        let (w, h) = (map.width_m, map.height_m);
        let border = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]];
        let mut segments: Vec<[f64; 4]> = (0..4)
            .map(|i| {
                let (a, b) = (border[i], border[(i + 1) % 4]);
                [a[0], a[1], b[0], b[1]]
            })
            .collect();
        for wall in map.walls.iter().filter(|w| !w.obstacle) {
            let n = wall.corners.len();
            for i in 0..n {
                let (a, b) = (wall.corners[i], wall.corners[(i + 1) % n]);
                segments.push([a.x, a.y, b.x, b.y]);
            }
        }
        Localiser { segments, turn: 0.0, shift: [0.0; 2], matched: 0 }
    }

    /// The estimate for an odometry pose: the odometry with the correction learnt so far.
    pub fn estimate(&self, odometry: Pose) -> Pose {
        let Pose { x_m: x, y_m: y, heading_rad: theta } = odometry;
        let (s, c) = self.turn.sin_cos();
        Pose::new(c * x - s * y + self.shift[0], s * x + c * y + self.shift[1], wrap_rad(theta + self.turn))
    }

    /// Takes this tick's real readings (metres in the chair's sensor order; NaN where none
    /// came, +∞ for no echo) at odometry pose `odometry`, corrects the estimate towards what
    /// they say, and returns it.
    pub fn update(&mut self, odometry: Pose, readings: &[f32; MAX_PROXIMITY]) -> Pose {
        let pose = self.estimate(odometry);
        // Each used reading with the map's prediction at the estimate.
        let used: Vec<(&Mount, f64, f64)> = SENSORS
            .iter()
            .zip(readings)
            .filter_map(|(m, &z)| {
                let z = f64::from(z);
                if !z.is_finite() {
                    return None;
                }
                let h = self.predict(pose, m);
                (h < m.range_m - 0.01 && (z - h).abs() < GATE_M).then_some((m, z, h))
            })
            .collect();
        self.matched = used.len();
        if used.len() < MIN_READINGS {
            return pose;
        }
        // The normal equations of the readings' residuals, with numeric derivatives of the
        // predictions (a reading's nearest wall point can jump between segments).
        const EPS: [f64; 3] = [1e-3, 1e-3, 1e-3];
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for &(m, z, h) in &used {
            let mut j = [0.0; 3];
            for (k, e) in EPS.iter().enumerate() {
                let mut p = pose;
                *[&mut p.x_m, &mut p.y_m, &mut p.heading_rad][k] += e;
                j[k] = (self.predict(p, m) - h) / e;
            }
            for r in 0..3 {
                for c in 0..3 {
                    jtj[r][c] += j[r] * j[c];
                }
                jtr[r] += j[r] * (z - h);
            }
        }
        for (k, d) in DAMPING.iter().enumerate() {
            jtj[k][k] += d;
        }
        let Some(step) = solve3(jtj, jtr) else { return pose };
        let (dx, dy) = (GAIN * step[0], GAIN * step[1]);
        let shrink = MAX_STEP_M / dx.hypot(dy).max(MAX_STEP_M);
        let (dx, dy) = (dx * shrink, dy * shrink);
        let dtheta = (GAIN * step[2]).clamp(-MAX_TURN_RAD, MAX_TURN_RAD);
        let corrected = Pose::new(pose.x_m + dx, pose.y_m + dy, wrap_rad(pose.heading_rad + dtheta));
        // The new transform takes the odometry pose to the corrected one.
        self.turn = wrap_rad(corrected.heading_rad - odometry.heading_rad);
        let (s, c) = self.turn.sin_cos();
        let [ox, oy] = odometry.position();
        self.shift = [corrected.x_m - (c * ox - s * oy), corrected.y_m - (s * ox + c * oy)];
        // What `estimate` gives from now on (the corrected pose, to rounding).
        self.estimate(odometry)
    }

    /// Readings matched to the map at the last update.
    pub fn matched(&self) -> usize {
        self.matched
    }

    /// What sensor `m` reads at `pose` off the map's known walls.
    fn predict(&self, Pose { x_m: x, y_m: y, heading_rad: theta }: Pose, m: &Mount) -> f64 {
        let (s, c) = theta.sin_cos();
        let apex = [x + c * m.x_m - s * m.y_m, y + s * m.x_m + c * m.y_m];
        let axis = theta + m.angle_deg.to_radians();
        let cone = m.cone_deg.to_radians();
        self.segments
            .iter()
            .map(|&[ax, ay, bx, by]| cone_range(apex, axis, cone, [ax, ay], [bx, by], m.range_m))
            .fold(m.range_m, f64::min)
    }
}

/// Solves a 3×3 symmetric positive system by Cramer's rule; `None` if it is singular.
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if !d.is_finite() || d.abs() < 1e-12 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(m) / d;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::map::{Point, Wall};

    /// A 4 m wide corridor along x with a cross wall at its end: every direction is seen.
    fn corridor() -> Map {
        let wall = |c: &[(f64, f64)], obstacle: bool| Wall {
            height_m: 1.0,
            corners: c.iter().map(|&(x, y)| Point::new(x, y)).collect(),
            obstacle,
        };
        Map {
            width_m: 12.0,
            height_m: 6.0,
            walls: vec![
                wall(&[(0.0, 0.0), (12.0, 0.0), (12.0, 1.0), (0.0, 1.0)], false),
                wall(&[(0.0, 2.2), (12.0, 2.2), (12.0, 6.0), (0.0, 6.0)], false),
                // A scenario obstacle: virtual, never in the room, never matched.
                wall(&[(3.0, 1.3), (3.3, 1.3), (3.3, 1.6), (3.0, 1.6)], true),
            ],
            ..Map::default()
        }
    }

    /// What the chair's sensors read at the true pose off the known walls.
    fn readings(l: &Localiser, truth: Pose) -> [f32; MAX_PROXIMITY] {
        let mut z = [f32::NAN; MAX_PROXIMITY];
        for (slot, m) in z.iter_mut().zip(&SENSORS) {
            let h = l.predict(truth, m);
            *slot = if h < m.range_m { h as f32 } else { f32::INFINITY };
        }
        z
    }

    #[test]
    fn the_estimate_converges_on_the_true_pose_where_the_walls_tell_it() {
        let mut l = Localiser::new(&corridor());
        assert_eq!(l.segments.len(), 4 + 8, "the border and the two known walls, not the obstacle");
        // The odometry is 6 cm to the left and 2° off; the chair stands still in the corridor.
        let truth = Pose::new(6.0, 1.6, 0.0);
        let odometry = Pose::from_deg(6.0, 1.66, 2.0);
        let z = readings(&l, truth);
        let mut pose = odometry;
        for _ in 0..60 {
            pose = l.update(odometry, &z);
        }
        assert!(l.matched() >= MIN_READINGS, "{}", l.matched());
        assert!((pose.y_m - truth.y_m).abs() < 0.005, "across the corridor: {pose:?}");
        assert!(pose.heading_rad.abs() < 0.2f64.to_radians(), "heading: {pose:?}");
        assert!((pose.x_m - truth.x_m).abs() < 0.02, "along it, nothing pulls: odometry's x stays: {pose:?}");
    }

    #[test]
    fn each_tick_moves_the_pose_a_bounded_step() {
        let mut l = Localiser::new(&corridor());
        let truth = Pose::new(6.0, 1.6, 0.0);
        let odometry = Pose::new(6.0, 1.8, 0.0);
        let z = readings(&l, truth);
        let before = l.estimate(odometry);
        let after = l.update(odometry, &z);
        let moved = (after.x_m - before.x_m).hypot(after.y_m - before.y_m);
        assert!(moved > 0.0 && moved <= MAX_STEP_M + 1e-12, "{moved}");
        assert!((after.heading_rad - before.heading_rad).abs() <= MAX_TURN_RAD + 1e-12);
    }

    #[test]
    fn the_correction_rides_along_with_odometry() {
        let mut l = Localiser::new(&corridor());
        let z = readings(&l, Pose::new(6.0, 1.6, 0.0));
        for _ in 0..60 {
            l.update(Pose::new(6.0, 1.7, 0.0), &z);
        }
        // Odometry moves 1 m ahead with no readings: the estimate moves with it, corrected.
        let est = l.update(Pose::new(7.0, 1.7, 0.0), &[f32::NAN; MAX_PROXIMITY]);
        assert!((est.x_m - 7.0).abs() < 0.02 && (est.y_m - 1.6).abs() < 0.01, "{est:?}");
    }

    #[test]
    fn readings_of_what_the_map_lacks_are_left_out() {
        let mut l = Localiser::new(&corridor());
        let pose = Pose::new(6.0, 1.6, 0.0);
        // Every sensor sees something 0.4 m nearer than any known wall (a box only the room
        // has), or gets no echo (a dropout), or none came: nothing is matched, the pose stays.
        let mut z = readings(&l, pose);
        for v in &mut z[..SENSORS.len()] {
            *v = if *v > 0.45 { *v - 0.4 } else { f32::INFINITY };
        }
        z[0] = f32::INFINITY;
        z[1] = f32::NAN;
        assert_eq!(l.update(pose, &z), pose);
        assert_eq!(l.matched(), 0);
    }

    #[test]
    fn a_singular_system_is_refused() {
        assert_eq!(solve3([[0.0; 3]; 3], [1.0; 3]), None);
        let x = solve3([[2.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 8.0]], [2.0, 4.0, 8.0]).expect("regular");
        assert_eq!(x, [1.0, 1.0, 1.0]);
    }
}
