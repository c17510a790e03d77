//! Where the chair thinks it is: wheel-encoder odometry (the default), GPS, or the two fused.
//! Never the hub's ground truth, which agents do not receive.
//!
//! Wheels slip (the hub's encoder slip, on whenever noise is), and what slip does most harm
//! to is the heading: the two wheels' errors differ, the difference turns the estimate, and a
//! heading off by a degree puts the chair 17 cm to the side after 10 m. So whenever the chair
//! has a compass, odometry's heading is pulled towards it by [`COMPASS_GAIN`] each tick: the
//! heading follows the wheels over a second and the compass over a few seconds, and cannot
//! drift. The position still comes from the wheels, whose error along the way is small.

use crate::geom::{Pose, V2, wrap_rad};
use crate::sensors::Input;

/// A source of the pose estimate.
pub trait PoseSource: std::fmt::Debug {
    /// The estimate after this tick's readings.
    fn update(&mut self, input: &Input) -> Pose;

    /// Moves the estimate's position to `pos` (a correction from another sensor), keeping
    /// its heading.
    fn set_position(&mut self, pos: V2);
}

/// The share of the compass's disagreement with odometry's heading taken each tick (the SDK's,
/// [`agent_sdk::odometry::COMPASS_GAIN`]). At 10 Hz it averages the compass over about 1.2 s:
/// its 2° noise (Ciber-Rato's default) shrinks to about 0.4°, and slip's heading walk (about
/// 0.1° a tick at the hub's default 2 % and a chair's cruise) has no time to build up; together
/// about half a degree (1σ), against a walk without bound on the wheels alone. The best
/// constant gain for those two noises (√(walk² / compass²)) is about 0.06 at the default slip
/// and 0.12 at twice it; 0.08 serves both (over maze seeds 1–20 at twice the slip the worst
/// position error is 0.075 m with it, 0.114 m with 0.05; `closed_loop::slip` holds 0.10 m).
pub const COMPASS_GAIN: f64 = agent_sdk::odometry::COMPASS_GAIN;

/// Which pose source to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PoseSourceKind {
    /// Wheel-encoder odometry from the start pose, its heading held by the compass when the
    /// chair has one: smooth, and off by centimetres over a run however the wheels slip.
    Odometry,
    /// The GPS fix as it comes (0.5 m noise by default: too coarse for doorways).
    Gps,
    /// Odometry (compass-held, as above) pulled slowly towards GPS, so drift cannot grow
    /// without bound even without a compass.
    Fused,
}

/// Dead reckoning from cumulative wheel-encoder ticks: the SDK's [`agent_sdk::odometry::Odometry`]
/// in the navigator's [`Pose`].
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    inner: agent_sdk::odometry::Odometry,
}

impl Odometry {
    /// Odometry starting at `start`, for encoders of `ticks_per_m` and wheels `track_m` apart.
    pub fn new(start: Pose, ticks_per_m: f64, track_m: f64) -> Self {
        Self { inner: agent_sdk::odometry::Odometry::new(start.into(), ticks_per_m, track_m) }
    }

    /// Advances the estimate by the ticks counted since the last call. The hub integrates a
    /// tick's motion along the heading the tick began with (thesis eq. 4.7), and so does this.
    pub fn advance(&mut self, ticks: [i64; 2]) -> Pose {
        self.inner.advance(ticks).into()
    }

    /// Turns the estimate's heading by `gain` of its difference to `heading_rad` (taken the
    /// short way round): a complementary filter with an absolute heading sensor.
    pub fn steer_heading(&mut self, heading_rad: f64, gain: f64) -> Pose {
        self.inner.steer_heading(heading_rad, gain).into()
    }

    /// Advances by this tick's encoder counts, then steers the heading towards the compass
    /// when there is one.
    fn update_with_compass(&mut self, input: &Input) -> Pose {
        self.inner.update(input.encoder_ticks, input.compass_deg).into()
    }

    /// The estimate.
    pub fn pose(&self) -> Pose {
        self.inner.pose().into()
    }

    fn set_pose(&mut self, p: Pose) {
        self.inner.set_pose(p.into());
    }
}

impl PoseSource for Odometry {
    fn update(&mut self, input: &Input) -> Pose {
        self.update_with_compass(input)
    }

    fn set_position(&mut self, pos: V2) {
        let theta = self.pose().theta;
        self.set_pose(Pose::new(pos.x, pos.y, theta));
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

    fn set_position(&mut self, pos: V2) {
        self.pose = Pose::new(pos.x, pos.y, self.pose.theta);
    }
}

/// Odometry corrected towards GPS by a small gain each tick (a complementary filter): the
/// position follows odometry over seconds and GPS over minutes; the heading is odometry's,
/// held by the compass when there is one.
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
        let mut p = self.odometry.update_with_compass(input);
        if let Some(g) = input.gps
            && g.x_m.is_finite()
            && g.y_m.is_finite()
        {
            let pos = p.pos() + (V2::new(g.x_m, g.y_m) - p.pos()) * self.gain;
            p = Pose::new(pos.x, pos.y, wrap_rad(p.theta));
            self.odometry.set_pose(p);
        }
        p
    }

    fn set_position(&mut self, pos: V2) {
        self.odometry.set_position(pos);
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
            compass_deg: None,
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

    fn still(ticks: [i64; 2], compass_deg: Option<f64>) -> Input {
        Input {
            tick: 1,
            time_s: 0.1,
            proximity_m: [0.0; 8],
            proximity_count: 0,
            encoder_ticks: ticks,
            gps: None,
            compass_deg,
            collision: false,
        }
    }

    #[test]
    fn the_compass_pulls_a_slipped_heading_back_the_short_way_round() {
        // Odometry believes 175°; the compass says −175° (10° away across ±180°).
        let mut o = Odometry::new(Pose::from_deg(0.0, 0.0, 175.0), TICKS_PER_M, 0.65);
        let p = o.update(&still([0, 0], Some(-175.0)));
        let turned = wrap_rad(p.theta - 175f64.to_radians()).to_degrees();
        assert!((turned - 10.0 * COMPASS_GAIN).abs() < 1e-9, "turned {turned}°");
        for _ in 0..200 {
            o.update(&still([0, 0], Some(-175.0)));
        }
        assert!(wrap_rad(o.pose().theta - (-175f64).to_radians()).abs() < 1e-3, "{:?}", o.pose());
    }

    #[test]
    fn without_a_compass_odometry_is_pure_dead_reckoning() {
        let mut o = Odometry::new(Pose::from_deg(0.0, 0.0, 30.0), TICKS_PER_M, 0.65);
        o.update(&still([0, 0], None));
        let p = o.update(&still([0, 0], None));
        assert_eq!(p, Pose::from_deg(0.0, 0.0, 30.0));
    }

    #[test]
    fn a_noisy_compass_holds_a_slipping_heading_to_a_fraction_of_a_degree() {
        // 30 m straight ahead in 600 ticks, each wheel's count off by a random 2 % a tick (the
        // hub's default slip), the compass off by a random 2° (Ciber-Rato's default).
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        // A uniform draw in ±√3·sd has that standard deviation.
        let mut noisy = |sd: f64| sd * 3f64.sqrt() * uniform();
        let mut odo = Odometry::new(Pose::from_deg(0.0, 0.0, 0.0), TICKS_PER_M, 0.65);
        let mut held = odo.clone();
        let (mut l, mut r) = (0.0, 0.0);
        odo.advance([0, 0]);
        held.update(&still([0, 0], Some(0.0)));
        let (mut odo_sq, mut held_sq) = (0.0, 0.0);
        for _ in 0..600 {
            l += 0.05 * (1.0 + noisy(0.02));
            r += 0.05 * (1.0 + noisy(0.02));
            let ticks = [(l * TICKS_PER_M) as i64, (r * TICKS_PER_M) as i64];
            odo_sq += odo.advance(ticks).theta.powi(2);
            held_sq += held.update(&still(ticks, Some(noisy(2.0)))).theta.powi(2);
        }
        let rms_deg = |sq: f64| (sq / 600.0).sqrt().to_degrees();
        let (odo_deg, held_deg) = (rms_deg(odo_sq), rms_deg(held_sq));
        assert!(held_deg < 0.8, "held heading off by {held_deg}° (rms)");
        assert!(odo_deg > 1.5 * held_deg, "dead reckoning {odo_deg}°, held {held_deg}°");
        assert!(held.pose().y.abs() < 0.1, "held stays on the line: {:?}", held.pose());
    }
}
