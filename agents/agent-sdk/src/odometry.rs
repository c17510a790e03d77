//! Where a robot thinks it is from its own sensors: dead reckoning on its wheel encoders, its
//! heading held by its compass. An agent never gets its robot's true pose (that is for
//! observers), so every agent that needs a pose estimates one this way or from GPS.
//!
//! ```
//! use agent_sdk::odometry::Odometry;
//! use sim_model::Pose;
//!
//! // 1,000 ticks a metre, wheels 0.6 m apart, starting at (1, 2) facing +x.
//! let mut odo = Odometry::new(Pose::new(1.0, 2.0, 0.0), 1000.0, 0.6);
//! odo.update([0, 0], None);
//! let p = odo.update([500, 500], None); // both wheels 0.5 m forward
//! assert!((p.x_m - 1.5).abs() < 1e-9 && (p.y_m - 2.0).abs() < 1e-9);
//! ```

use sim_model::{Pose, wrap_rad};

/// The share of the compass's disagreement with the wheels' heading taken each tick. At
/// 10 Hz it averages the compass over about 1.2 s, so its noise (2° by default) shrinks to
/// about 0.4° (√(g/(2−g))), while the wheels' heading walk under slip has no time to build up.
pub const COMPASS_GAIN: f64 = 0.08;

/// Dead reckoning from cumulative wheel-encoder ticks, with an optional compass.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// The estimate; its heading is kept in (−π, π].
    pose: Pose,
    ticks_per_m: f64,
    track_m: f64,
    last: Option<[i64; 2]>,
}

impl Odometry {
    /// Odometry from `start` for encoders of `ticks_per_m`
    /// (the map header's `params.encoder_ticks_per_m`) on wheels `track_m` apart (the
    /// robot's width, its registration's `height_m`).
    pub fn new(start: Pose, ticks_per_m: f64, track_m: f64) -> Self {
        Self { pose: start, ticks_per_m, track_m, last: None }
    }

    /// Advances by the ticks counted since the last call, then turns the heading `COMPASS_GAIN`
    /// of the way to the compass (degrees) when there is a reading. The first call only sets
    /// the reference count. Returns the estimate.
    pub fn update(&mut self, ticks: [i64; 2], compass_deg: Option<f64>) -> Pose {
        self.advance(ticks);
        if let Some(deg) = compass_deg {
            self.steer_heading(deg.to_radians(), COMPASS_GAIN);
        }
        self.pose
    }

    /// Advances by the ticks counted since the last call (the first call only sets the
    /// reference count). Returns the estimate.
    pub fn advance(&mut self, ticks: [i64; 2]) -> Pose {
        if let Some(last) = self.last
            && self.ticks_per_m > 0.0
        {
            let dl = ticks[0].wrapping_sub(last[0]) as f64 / self.ticks_per_m;
            let dr = ticks[1].wrapping_sub(last[1]) as f64 / self.ticks_per_m;
            self.travel([dl, dr]);
        }
        self.last = Some(ticks);
        self.pose
    }

    /// Advances by each wheel's travel since the last step, left and right, metres (for
    /// encoders counted elsewhere, such as a physical chair's board). Returns the estimate.
    pub fn travel(&mut self, wheels_m: [f64; 2]) -> Pose {
        if self.track_m > 0.0 {
            let [dl, dr] = wheels_m;
            let ds = (dl + dr) / 2.0;
            let dth = (dr - dl) / self.track_m;
            // The step's distance and turn as speeds over one unit of time, along the heading
            // the step began with, as the hub moves robots (thesis eq. 4.7).
            let (sin, cos) = self.pose.heading_rad.sin_cos();
            self.pose = sim_model::advance(self.pose, ds, dth, cos, sin, 1.0);
        }
        self.pose
    }

    /// Turns the heading by `gain` of its difference to `heading_rad`, the short way round (a
    /// complementary filter with an absolute heading sensor); a non-finite heading is ignored.
    pub fn steer_heading(&mut self, heading_rad: f64, gain: f64) -> Pose {
        if heading_rad.is_finite() {
            let h = self.pose.heading_rad;
            self.pose.heading_rad = wrap_rad(h + gain * wrap_rad(heading_rad - h));
        }
        self.pose
    }

    /// Moves the estimate to `pose`, as a fix from another
    /// sensor (GPS) does; the encoder reference is kept.
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
    }

    /// The estimate.
    pub fn pose(&self) -> Pose {
        self.pose
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turn_in_place_turns_the_heading_by_the_wheels_difference_over_the_track() {
        let mut odo = Odometry::new(Pose::default(), 1000.0, 0.5);
        odo.update([0, 0], None);
        // Left back 0.1 m, right forward 0.1 m: 0.2 m over a 0.5 m track = 0.4 rad.
        let Pose { x_m: x, y_m: y, heading_rad: h } = odo.update([-100, 100], None);
        assert!((x.abs(), y.abs()) < (1e-12, 1e-12) && (h - 0.4).abs() < 1e-12, "{x} {y} {h}");
    }

    #[test]
    fn the_compass_pulls_a_drifted_heading_back_the_short_way_round() {
        let mut odo = Odometry::new(Pose::from_deg(0.0, 0.0, 179.0), 1000.0, 0.5);
        odo.update([0, 0], None);
        for _ in 0..200 {
            odo.update([0, 0], Some(-179.0));
        }
        assert!((odo.pose().heading_deg() + 179.0).abs() < 0.01, "{}", odo.pose().heading_deg());
    }

    #[test]
    fn without_a_scale_or_a_track_the_estimate_stays_where_it_started() {
        let mut odo = Odometry::new(Pose::new(1.0, 1.0, 0.0), 0.0, 0.5);
        odo.update([0, 0], None);
        assert_eq!(odo.update([100, 300], None), Pose::new(1.0, 1.0, 0.0));
    }
}
