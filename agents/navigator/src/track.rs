//! Following a planned path: a path-following law on the axle (curvature feed-forward plus
//! feedback on the lateral and heading errors), turns on the spot where the path has them,
//! and the wheel powers that make the chair's filtered motors do what is asked.

use crate::geom::{Pose, V2, wrap_rad};
use crate::hybrid::{Motion, PathPose};

/// What one stretch of a path asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunKind {
    /// Drive forwards along it.
    Forward,
    /// Drive backwards along it.
    Reverse,
    /// Turn on the spot to its last heading.
    Spin,
}

/// A stretch of a path with one kind of motion.
#[derive(Debug, Clone, PartialEq)]
struct Run {
    kind: RunKind,
    poses: Vec<Pose>,
    /// Arc length at each pose, from the run's start.
    s: Vec<f64>,
    /// Curvature of the arc ending at each pose.
    kappa: Vec<f64>,
    /// Speed limit at each pose, m/s.
    vmax: Vec<f64>,
    /// Whether each pose is re-checked against new obstacles.
    check: Vec<bool>,
}

impl Run {
    fn length(&self) -> f64 {
        self.s.last().copied().unwrap_or(0.0)
    }
}

/// Gains and limits of the follower.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerParams {
    /// Feedback on the lateral error, 1/m².
    pub k_lateral: f64,
    /// Feedback on the heading error, 1/m.
    pub k_heading: f64,
    /// Braking towards the end of a run, m/s².
    pub decel: f64,
    /// Slowest speed while a run is not finished, m/s.
    pub v_min: f64,
    /// Fastest turn rate while driving, rad/s.
    pub w_max: f64,
    /// Turn rate on the spot, rad/s.
    pub spin_rate: f64,
    /// A run is finished this near its end, metres.
    pub end_tolerance: f64,
    /// A spin is finished this near its heading, radians.
    pub heading_tolerance: f64,
    /// Farther than this from the path (metres) the path is given up.
    pub max_lateral: f64,
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            k_lateral: 8.0,
            k_heading: 5.0,
            decel: 0.25,
            v_min: 0.04,
            w_max: 0.9,
            spin_rate: 0.45,
            end_tolerance: 0.02,
            heading_tolerance: 1.5f64.to_radians(),
            max_lateral: 0.12,
        }
    }
}

/// What the follower asks for this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackCommand {
    /// Speed of the axle, m/s (negative backwards).
    pub v: f64,
    /// Turn rate, rad/s.
    pub w: f64,
    /// Distance from the path, metres.
    pub lateral_error: f64,
}

/// Follows one planned path.
#[derive(Debug, Clone)]
pub struct Tracker {
    runs: Vec<Run>,
    run: usize,
    /// Index of the pose before the robot's projection in the current run.
    idx: usize,
    params: TrackerParams,
    finished: bool,
    /// Whether the path ends at the leg's goal.
    pub reaches_goal: bool,
}

impl Tracker {
    /// A follower for `path`, with a speed limit for each pose and whether each is to be
    /// re-checked when the map changes (see [`Tracker::remaining_checked`]).
    pub fn new(path: &[PathPose], vmax: &[f64], check: &[bool], reaches_goal: bool, params: TrackerParams) -> Self {
        let mut runs: Vec<Run> = Vec::new();
        for (i, pp) in path.iter().enumerate().skip(1) {
            let kind = match pp.motion {
                Motion::Forward(_) | Motion::Start => RunKind::Forward,
                Motion::Reverse(_) => RunKind::Reverse,
                Motion::Spin(_) => RunKind::Spin,
            };
            let v = vmax.get(i).copied().unwrap_or(0.1);
            let c = check.get(i).copied().unwrap_or(false);
            match runs.last_mut() {
                Some(r) if r.kind == kind => {
                    let ds = (pp.pose.pos() - path[i - 1].pose.pos()).norm();
                    let s = r.length() + ds;
                    r.poses.push(pp.pose);
                    r.s.push(s);
                    r.kappa.push(pp.motion.curvature());
                    r.vmax.push(v);
                    r.check.push(c);
                }
                _ => {
                    let prev = path[i - 1].pose;
                    let ds = (pp.pose.pos() - prev.pos()).norm();
                    let v0 = vmax.get(i - 1).copied().unwrap_or(v);
                    runs.push(Run {
                        kind,
                        poses: vec![prev, pp.pose],
                        s: vec![0.0, ds],
                        kappa: vec![pp.motion.curvature(), pp.motion.curvature()],
                        vmax: vec![v0, v],
                        check: vec![check.get(i - 1).copied().unwrap_or(false), c],
                    });
                }
            }
        }
        let finished = runs.is_empty();
        Self { runs, run: 0, idx: 0, params, finished, reaches_goal }
    }

    /// Whether the whole path has been driven.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The poses still ahead (of the current run and every later one).
    pub fn remaining(&self) -> impl Iterator<Item = &Pose> {
        let first = self.runs.get(self.run).map(|r| &r.poses[self.idx.min(r.poses.len() - 1)..]).unwrap_or(&[]);
        first.iter().chain(self.runs.iter().skip(self.run + 1).flat_map(|r| r.poses.iter()))
    }

    /// The poses still ahead that are to be re-checked when the map changes.
    pub fn remaining_checked(&self) -> impl Iterator<Item = &Pose> {
        let first = self
            .runs
            .get(self.run)
            .map(|r| {
                let k = self.idx.min(r.poses.len() - 1);
                r.poses[k..].iter().zip(&r.check[k..])
            })
            .into_iter()
            .flatten();
        first
            .chain(self.runs.iter().skip(self.run + 1).flat_map(|r| r.poses.iter().zip(&r.check)))
            .filter_map(|(p, &c)| c.then_some(p))
    }

    /// Length still to drive, metres (turns on the spot count nothing).
    pub fn remaining_length(&self) -> f64 {
        let Some(r) = self.runs.get(self.run) else { return 0.0 };
        let here = r.s[self.idx.min(r.s.len() - 1)];
        (r.length() - here) + self.runs.iter().skip(self.run + 1).map(Run::length).sum::<f64>()
    }

    /// The command for a chair at `pose` (standing still once the path is driven).
    pub fn command(&mut self, pose: &Pose) -> TrackCommand {
        loop {
            let p = self.params;
            let Some(run) = self.runs.get(self.run) else {
                self.finished = true;
                return TrackCommand { v: 0.0, w: 0.0, lateral_error: 0.0 };
            };
            if run.kind == RunKind::Spin {
                let target = run.poses[run.poses.len() - 1].theta;
                let e = wrap_rad(target - pose.theta);
                if e.abs() <= p.heading_tolerance {
                    self.next_run();
                    continue;
                }
                // Brake the turn in time: ω ≤ √(2·α·|e|) with α ≈ 1 rad/s².
                let w = e.signum() * p.spin_rate.min((2.0 * 0.8 * e.abs()).sqrt()).max(0.08);
                return TrackCommand { v: 0.0, w, lateral_error: 0.0 };
            }
            // Project the axle onto the run: the segment nearest to it, searching forwards.
            let n = run.poses.len();
            let pos = pose.pos();
            let mut best = (self.idx.min(n - 2), f64::INFINITY, 0.0);
            for k in self.idx.min(n - 2)..(self.idx + 25).min(n - 1) {
                let (a, b) = (run.poses[k].pos(), run.poses[k + 1].pos());
                let d = b - a;
                let len2 = d.norm2();
                let t = if len2 > 0.0 { ((pos - a).dot(d) / len2).clamp(0.0, 1.0) } else { 1.0 };
                let dist = (a + d * t - pos).norm();
                if dist < best.1 - 1e-9 {
                    best = (k, dist, t);
                }
            }
            let (k, _, t) = best;
            self.idx = k;
            let s_here = run.s[k] + (run.s[k + 1] - run.s[k]) * t;
            let remaining = run.length() - s_here;
            // Past the end (or at it): this run is done.
            let end = run.poses[n - 1];
            let along_end = {
                let h = V2::unit(end.theta);
                let sign = if run.kind == RunKind::Reverse { -1.0 } else { 1.0 };
                (end.pos() - pos).dot(h) * sign
            };
            if remaining <= p.end_tolerance || (k == n - 2 && along_end <= p.end_tolerance) {
                self.next_run();
                continue;
            }
            // Reference pose and curvature at the projection.
            let (a, b) = (run.poses[k], run.poses[k + 1]);
            let ref_theta = a.theta + wrap_rad(b.theta - a.theta) * t;
            let kappa = run.kappa[k + 1];
            let tangent = V2::unit(ref_theta);
            let on_path = a.pos() + (b.pos() - a.pos()) * t;
            let e_th = wrap_rad(ref_theta - pose.theta);
            let vmax = run.vmax[k].min(run.vmax[k + 1]);
            let brake = (2.0 * p.decel * remaining).sqrt();
            let mut speed = vmax.min(brake).max(p.v_min.min(vmax));
            // Slow down when the heading is off: the arc feed-forward assumes it is not.
            speed *= e_th.cos().max(0.2);
            // And for sharp arcs, so the turn rate stays within reach.
            if kappa.abs() > 1e-6 {
                speed = speed.min(p.w_max / kappa.abs()).max(p.v_min.min(vmax));
            }
            let v = if run.kind == RunKind::Reverse { -speed } else { speed };
            let lateral = {
                // Where the path is, sideways from the chair (left positive).
                let off = pos - on_path;
                let left = V2::new(-tangent.y, tangent.x);
                -off.dot(left)
            };
            let w = kappa * v + p.k_lateral * v * lateral + p.k_heading * v.abs() * e_th.sin();
            let w = w.clamp(-p.w_max, p.w_max);
            return TrackCommand { v, w, lateral_error: lateral.abs() };
        }
    }

    fn next_run(&mut self) {
        self.run += 1;
        self.idx = 0;
        if self.run >= self.runs.len() {
            self.finished = true;
        }
    }
}

/// Wheel powers from wanted speeds, through the chair's motor filter
/// `out = (1 − c)·in + c·out₋₁` (thesis eq. 4.4): the power asked for is the one that makes
/// the filtered output reach the wanted value in one tick, within [−1, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Top speed, m/s.
    pub max_speed: f64,
    /// Wheel track (the body's width), metres.
    pub track: f64,
    /// The filter's coefficient.
    pub accel_curve: f64,
    /// The filter's outputs as this model has them, left and right.
    pub out: [f64; 2],
}

impl Drive {
    /// A drive at rest.
    pub fn new(max_speed: f64, track: f64, accel_curve: f64) -> Self {
        Self { max_speed, track, accel_curve, out: [0.0; 2] }
    }

    /// Current speed and turn rate as the model has them.
    pub fn velocity(&self) -> (f64, f64) {
        sim_model::velocity(self.max_speed, self.track, self.out)
    }

    /// Records powers sent as they are (the model's outputs follow them).
    pub fn powers_raw(&mut self, powers: [f64; 2]) {
        for (out, p) in self.out.iter_mut().zip(powers) {
            *out = sim_model::motor_filter(p, *out, self.accel_curve);
        }
    }

    /// The powers to send for a wanted speed `v` (m/s) and turn rate `w` (rad/s); updates the
    /// model's outputs.
    pub fn powers(&mut self, v: f64, w: f64) -> [f64; 2] {
        let (v, w) = (if v.is_finite() { v } else { 0.0 }, if w.is_finite() { w } else { 0.0 });
        let mut want = [(v - w * self.track / 2.0) / self.max_speed, (v + w * self.track / 2.0) / self.max_speed];
        let big = want[0].abs().max(want[1].abs());
        if big > 1.0 {
            want = [want[0] / big, want[1] / big];
        }
        let c = self.accel_curve;
        let mut powers = [0.0; 2];
        for k in 0..2 {
            // The filter inverted: the power whose output is `want` one tick from now.
            let p = if c < 1.0 { ((want[k] - c * self.out[k]) / (1.0 - c)).clamp(-1.0, 1.0) } else { 0.0 };
            powers[k] = p;
            self.out[k] = sim_model::motor_filter(p, self.out[k], c);
        }
        powers
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hybrid::arc;

    fn straight_then_spin() -> Vec<PathPose> {
        let mut path = vec![PathPose { pose: Pose::from_deg(0.0, 0.0, 0.0), motion: Motion::Start }];
        for _ in 0..20 {
            let last = path[path.len() - 1].pose;
            path.push(PathPose { pose: arc(&last, 0.1, 0.0), motion: Motion::Forward(0.0) });
        }
        for _ in 0..9 {
            let last = path[path.len() - 1].pose;
            let a = 10f64.to_radians();
            path.push(PathPose { pose: Pose::new(last.x, last.y, last.theta + a), motion: Motion::Spin(a) });
        }
        path
    }

    #[test]
    fn the_drive_reaches_a_wanted_speed_through_the_motor_filter() {
        let mut d = Drive::new(0.49, 0.65, 0.83);
        let mut out = [0.0f64; 2];
        for _ in 0..30 {
            let p = d.powers(0.3, 0.0);
            for k in 0..2 {
                out[k] = sim_model::motor_filter(p[k], out[k], 0.83);
            }
        }
        assert!((out[0] * 0.49 - 0.3).abs() < 1e-9 && (out[1] - out[0]).abs() < 1e-12);
        assert!((d.velocity().0 - 0.3).abs() < 1e-9);
        // A pure turn: the wheels go opposite ways.
        for _ in 0..30 {
            d.powers(0.0, 0.5);
        }
        let (v, w) = d.velocity();
        assert!(v.abs() < 1e-9 && (w - 0.5).abs() < 1e-9);
    }

    #[test]
    fn the_follower_drives_a_path_and_then_turns_on_the_spot() {
        let path = straight_then_spin();
        let vmax = vec![0.3; path.len()];
        let check = vec![true; path.len()];
        let mut t = Tracker::new(&path, &vmax, &check, true, TrackerParams::default());
        assert!(t.remaining_checked().count() >= path.len(), "every pose is re-checked");
        // Start 5 cm to the right of the path: the follower steers back left.
        let mut pose = Pose::from_deg(0.0, -0.05, 0.0);
        let dt = 0.1;
        let mut ticks = 0;
        while !t.finished() && ticks < 400 {
            let c = t.command(&pose);
            pose = pose.advanced(c.v, c.w, dt);
            ticks += 1;
        }
        assert!(t.finished(), "{pose:?}");
        assert!((pose.x - 2.0).abs() < 0.05 && pose.y.abs() < 0.03, "{pose:?}");
        assert!((pose.theta - 90f64.to_radians()).abs() < 0.05, "{pose:?}");
    }
}
