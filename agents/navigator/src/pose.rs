//! Where the chair thinks it is: wheel-encoder odometry (the default), GPS, or the two fused.
//! Never the hub's ground truth (`SensorBlock::pose`), which is for logs only.

use crate::geom::{Pose, V2, wrap_rad};
use crate::sensors::Input;

/// A source of the pose estimate.
pub trait PoseSource: std::fmt::Debug {
    /// The estimate after this tick's readings.
    fn update(&mut self, input: &Input) -> Pose;
}

/// Which pose source to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PoseSourceKind {
    /// Wheel-encoder odometry from the start pose: smooth and, on the simulator's wheels,
    /// exact up to one encoder tick.
    Odometry,
    /// The GPS fix as it comes (0.5 m noise by default: too coarse for doorways).
    Gps,
    /// Odometry pulled slowly towards GPS, so drift cannot grow without bound.
    Fused,
}

/// Dead reckoning from cumulative wheel-encoder ticks.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    pose: Pose,
    ticks_per_m: f64,
    track_m: f64,
    last: Option<[i64; 2]>,
}

impl Odometry {
    /// Odometry starting at `start`, for encoders of `ticks_per_m` and wheels `track_m` apart.
    pub fn new(start: Pose, ticks_per_m: f64, track_m: f64) -> Self {
        Self { pose: start, ticks_per_m, track_m, last: None }
    }

    /// Advances the estimate by the ticks counted since the last call. The hub integrates a
    /// tick's motion along the heading the tick began with (thesis eq. 4.7), and so does this.
    pub fn advance(&mut self, ticks: [i64; 2]) -> Pose {
        if let Some(last) = self.last
            && self.ticks_per_m > 0.0
        {
            let dl = (ticks[0] - last[0]) as f64 / self.ticks_per_m;
            let dr = (ticks[1] - last[1]) as f64 / self.ticks_per_m;
            let ds = (dl + dr) / 2.0;
            let dth = (dr - dl) / self.track_m;
            // The hub's step (sim_model::advance), the tick's distance and turn taken as speeds
            // over one unit of time: along the heading the tick began with.
            self.pose = self.pose.advanced(ds, dth, 1.0);
        }
        self.last = Some(ticks);
        self.pose
    }

    /// The estimate.
    pub fn pose(&self) -> Pose {
        self.pose
    }
}

impl PoseSource for Odometry {
    fn update(&mut self, input: &Input) -> Pose {
        self.advance(input.encoder_ticks)
    }
}

/// The GPS fix, held between fixes.
#[derive(Debug, Clone, PartialEq)]
pub struct GpsPose {
    pose: Pose,
}

impl GpsPose {
    /// GPS, starting from `start` until the first fix.
    pub fn new(start: Pose) -> Self {
        Self { pose: start }
    }
}

impl PoseSource for GpsPose {
    fn update(&mut self, input: &Input) -> Pose {
        if let Some(g) = input.gps
            && g.x_m.is_finite()
            && g.y_m.is_finite()
            && g.heading_deg.is_finite()
        {
            self.pose = Pose::from_deg(g.x_m, g.y_m, g.heading_deg);
        }
        self.pose
    }
}

/// Odometry corrected towards GPS by a small gain each tick (a complementary filter): the
/// position follows odometry over seconds and GPS over minutes; the heading is odometry's.
#[derive(Debug, Clone, PartialEq)]
pub struct Fused {
    odometry: Odometry,
    gain: f64,
}

impl Fused {
    /// Fusion with `gain` per tick (0.01 at 10 Hz averages GPS over about 10 s).
    pub fn new(odometry: Odometry, gain: f64) -> Self {
        Self { odometry, gain }
    }
}

impl PoseSource for Fused {
    fn update(&mut self, input: &Input) -> Pose {
        let mut p = self.odometry.advance(input.encoder_ticks);
        if let Some(g) = input.gps
            && g.x_m.is_finite()
            && g.y_m.is_finite()
        {
            let pos = p.pos() + (V2::new(g.x_m, g.y_m) - p.pos()) * self.gain;
            p = Pose::new(pos.x, pos.y, wrap_rad(p.theta));
            self.odometry.pose = p;
        }
        p
    }
}

/// The pose source of a kind, starting at `start`.
pub fn pose_source(kind: PoseSourceKind, start: Pose, ticks_per_m: f64, track_m: f64) -> Box<dyn PoseSource> {
    match kind {
        PoseSourceKind::Odometry => Box::new(Odometry::new(start, ticks_per_m, track_m)),
        PoseSourceKind::Gps => Box::new(GpsPose::new(start)),
        PoseSourceKind::Fused => Box::new(Fused::new(Odometry::new(start, ticks_per_m, track_m), 0.01)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TICKS_PER_M: f64 = 1000.0;

    #[test]
    fn odometry_integrates_a_straight_run() {
        let mut o = Odometry::new(Pose::from_deg(1.0, 2.0, 90.0), TICKS_PER_M, 0.65);
        o.advance([0, 0]);
        for k in 1..=20 {
            o.advance([k * 100, k * 100]);
        }
        let p = o.pose();
        assert!(p.x.abs() - 1.0 < 1e-9 && (p.x - 1.0).abs() < 1e-9, "{p:?}");
        assert!((p.y - 4.0).abs() < 1e-9, "2 m north: {p:?}");
        assert!((p.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn odometry_integrates_a_spin_on_the_spot() {
        let track = 0.65;
        let mut o = Odometry::new(Pose::from_deg(5.0, 5.0, 0.0), TICKS_PER_M, track);
        o.advance([0, 0]);
        // A half turn: each wheel travels π·track/2, in opposite directions, in 40 steps.
        let total = std::f64::consts::PI * track / 2.0 * TICKS_PER_M;
        for k in 1..=40 {
            let t = (total * k as f64 / 40.0).round() as i64;
            o.advance([-t, t]);
        }
        let p = o.pose();
        assert!((p.x - 5.0).abs() < 1e-9 && (p.y - 5.0).abs() < 1e-9, "stays put: {p:?}");
        assert!((p.theta.abs() - std::f64::consts::PI).abs() < 2.0 / (TICKS_PER_M * track), "{p:?}");
    }

    #[test]
    fn odometry_follows_an_arc_as_the_hub_integrates_it() {
        // The hub's kinematics (eqs. 4.5–4.9): x += v·cos θ₀·dt, θ += ω·dt, per tick.
        let (track, dt, v, w) = (0.65, 0.1, 0.3, 0.4);
        let mut truth = Pose::from_deg(0.0, 0.0, 0.0);
        let mut o = Odometry::new(truth, 1e9, track);
        let (mut l, mut r) = (0.0, 0.0);
        o.advance([0, 0]);
        for _ in 0..50 {
            truth = truth.advanced(v, w, dt);
            l += (v - w * track / 2.0) * dt;
            r += (v + w * track / 2.0) * dt;
            o.advance([(l * 1e9).round() as i64, (r * 1e9).round() as i64]);
        }
        let p = o.pose();
        assert!(
            (p.pos() - truth.pos()).norm() < 1e-6 && wrap_rad(p.theta - truth.theta).abs() < 1e-6,
            "{p:?} {truth:?}"
        );
    }

    #[test]
    fn gps_and_fusion_use_fixes_when_there_are_some() {
        let mut input = Input {
            tick: 1,
            time_s: 0.1,
            proximity_m: [0.0; 8],
            proximity_count: 0,
            encoder_ticks: [0, 0],
            gps: None,
            collision: false,
        };
        let start = Pose::from_deg(1.0, 1.0, 0.0);
        let mut gps = GpsPose::new(start);
        assert_eq!(gps.update(&input), start, "no fix: hold");
        input.gps = Some(crate::sensors::GpsFix { x_m: 2.0, y_m: 1.0, heading_deg: 90.0 });
        assert_eq!(gps.update(&input), Pose::from_deg(2.0, 1.0, 90.0));
        let mut fused = Fused::new(Odometry::new(start, TICKS_PER_M, 0.65), 0.5);
        let p = fused.update(&input);
        assert!((p.x - 1.5).abs() < 1e-12 && p.theta == 0.0, "half way, odometry's heading: {p:?}");
    }
}
