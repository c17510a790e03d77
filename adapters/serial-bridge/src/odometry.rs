//! The chair's odometry from its board's encoder counters: where the adapter says the chair is
//! (the pose it pushes to the hub) and how far each wheel has turned (the encoders it reports).
//!
//! The board's counters are cumulative `i32`s that wrap; each sample's delta is taken with
//! wrapping subtraction, so the wrap never shows. Distances are kept in metres, so a board
//! replaced by one of another resolution (another BoardInfo) continues the same odometry. A new
//! connection, or a board that restarted (its clock went back), makes the next sample the new
//! baseline: its counters start again, the pose does not jump.

use agent_sdk::odometry::Odometry;
use sim_model::{Pose, encoder_ticks_per_m};

/// Dead reckoning on the chair's wheel encoders: the board's counters turned into wheel travel,
/// integrated by the agents' own odometry ([`Odometry::travel`]), so a physical chair and a
/// simulated one are estimated by one model.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelOdometry {
    /// The pose.
    core: Odometry,
    wheel_radius_m: f64,
    /// Board counts per metre of wheel travel, once a BoardInfo said the counts per turn.
    counts_per_m: Option<f64>,
    /// The last sample's board time and counters: the baseline of the next delta.
    last: Option<(u32, [i32; 2])>,
    /// Wheel travel since the start, left and right, metres.
    travel_m: [f64; 2],
}

/// What a sample did to the odometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The wheels' deltas were integrated.
    Moved,
    /// The sample became the baseline (the first after a connection or a BoardInfo).
    Baseline,
    /// The board's clock went back (it restarted): the sample became the new baseline.
    BoardRestarted,
    /// No counts-per-turn known yet (no BoardInfo): the sample was not used.
    Unscaled,
}

impl WheelOdometry {
    /// Odometry starting at `start` for wheels of `wheel_radius_m`, `track_m` apart.
    pub fn new(start: Pose, track_m: f64, wheel_radius_m: f64) -> WheelOdometry {
        WheelOdometry {
            // The core counts no ticks of its own: the board's come in as metres.
            core: Odometry::new(start, 0.0, track_m),
            wheel_radius_m,
            counts_per_m: None,
            last: None,
            travel_m: [0.0; 2],
        }
    }

    /// The board's encoder resolution (its BoardInfo); `false` (and no change) for 0 counts.
    /// The next sample becomes the baseline.
    pub fn set_counts_per_rev(&mut self, counts_per_rev: u32) -> bool {
        if counts_per_rev == 0 {
            return false;
        }
        self.counts_per_m = Some(encoder_ticks_per_m(f64::from(counts_per_rev), self.wheel_radius_m));
        self.last = None;
        true
    }

    /// Forgets the baseline: the next sample's counters are the new zero (a new connection).
    pub fn rebase(&mut self) {
        self.last = None;
    }

    /// Takes one sample's board time and cumulative counters, left and right.
    pub fn sample(&mut self, board_time_ms: u32, counts: [i32; 2]) -> Step {
        let Some(counts_per_m) = self.counts_per_m else { return Step::Unscaled };
        let Some((last_time, last_counts)) = self.last.replace((board_time_ms, counts)) else {
            return Step::Baseline;
        };
        // The board's clock wraps too: a step back of less than half its range is a restart.
        if (board_time_ms.wrapping_sub(last_time) as i32) < 0 {
            return Step::BoardRestarted;
        }
        let d = [0, 1].map(|k| f64::from(counts[k].wrapping_sub(last_counts[k])) / counts_per_m);
        self.travel_m[0] += d[0];
        self.travel_m[1] += d[1];
        self.core.travel(d);
        Step::Moved
    }

    /// The pose (its wire form is [`Pose::to_wire_deg`]).
    pub fn pose(&self) -> Pose {
        self.core.pose()
    }

    /// Whether the encoders' scale is known (a BoardInfo came).
    pub fn scaled(&self) -> bool {
        self.counts_per_m.is_some()
    }

    /// The wheels' cumulative travel in the hub's encoder units (`ticks_per_m`, the map
    /// header's `params.encoder_ticks_per_m`), rounded from the total so that rounding never
    /// accumulates.
    pub fn hub_encoders(&self, ticks_per_m: f64) -> [i64; 2] {
        // `as` saturates; a non-finite scale gives 0.
        self.travel_m.map(|m| (m * ticks_per_m).round() as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// Wheels of circumference 1 m, 0.5 m apart, 1000 counts a turn: 1000 counts a metre.
    fn odo() -> WheelOdometry {
        let mut o = WheelOdometry::new(Pose::new(1.0, 2.0, 0.0), 0.5, 1.0 / TAU);
        assert!(o.set_counts_per_rev(1000));
        o
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9)
    }

    #[test]
    fn the_first_sample_is_the_baseline_and_straight_travel_moves_along_the_heading() {
        let mut o = odo();
        assert_eq!(o.sample(0, [5000, -7000]), Step::Baseline);
        assert_eq!(o.pose().to_wire_deg(), [1.0, 2.0, 0.0], "the baseline does not move the chair");
        assert_eq!(o.sample(100, [5500, -6500]), Step::Moved);
        assert!(close(o.pose().to_wire_deg(), [1.5, 2.0, 0.0]), "{:?}", o.pose().to_wire_deg());
        assert_eq!(o.hub_encoders(2000.0), [1000, 1000]);
    }

    #[test]
    fn counters_that_wrap_give_the_small_delta_not_a_jump() {
        let mut o = odo();
        o.sample(0, [i32::MAX - 99, i32::MIN + 50]);
        // Left forward 200 counts across the wrap; right back 100 across it the other way.
        assert_eq!(o.sample(100, [i32::MIN + 100, i32::MAX - 49]), Step::Moved);
        assert_eq!(o.hub_encoders(1000.0), [200, -100]);
        let [x, y, h] = o.pose().to_wire_deg();
        // 0.05 m along the start heading, turned by (−0.1 − 0.2) / 0.5 rad.
        assert!((x - 1.05).abs() < 1e-9 && (y - 2.0).abs() < 1e-9, "{x} {y}");
        assert!((h - (-0.6f64).to_degrees()).abs() < 1e-9, "{h}");
    }

    #[test]
    fn a_turn_on_the_spot_turns_by_the_wheels_difference_over_the_track_and_wraps() {
        let mut o = WheelOdometry::new(Pose::from_deg(0.0, 0.0, 170.0), 0.5, 1.0 / TAU);
        o.set_counts_per_rev(1000);
        o.sample(0, [0, 0]);
        // 20° = 0.349 rad = (dr − dl) / 0.5 → dr = −dl = 0.0873 m.
        let d = (20f64.to_radians() * 0.5 / 2.0 * 1000.0).round() as i32;
        o.sample(100, [-d, d]);
        let [x, y, h] = o.pose().to_wire_deg();
        assert!(x.abs() < 1e-12 && y.abs() < 1e-12);
        assert!((h + 170.0).abs() < 0.1, "wrapped into (−180, 180]: {h}");
    }

    #[test]
    fn a_new_baseline_continues_without_a_jump() {
        let mut o = odo();
        o.sample(0, [0, 0]);
        o.sample(100, [1000, 1000]);
        // Reconnected to a board whose counters restarted elsewhere.
        o.rebase();
        assert_eq!(o.sample(5, [-123_456, 98_765]), Step::Baseline);
        assert!(close(o.pose().to_wire_deg(), [2.0, 2.0, 0.0]));
        o.sample(105, [-122_456, 99_765]);
        assert!(close(o.pose().to_wire_deg(), [3.0, 2.0, 0.0]));
        assert_eq!(o.hub_encoders(1000.0), [2000, 2000], "the encoders continue too");
    }

    #[test]
    fn a_board_whose_clock_went_back_restarted_and_its_sample_is_the_new_baseline() {
        let mut o = odo();
        o.sample(5000, [10_000, 10_000]);
        assert_eq!(o.sample(20, [0, 0]), Step::BoardRestarted);
        assert_eq!(o.pose().to_wire_deg(), [1.0, 2.0, 0.0]);
        o.sample(120, [100, 100]);
        assert!(close(o.pose().to_wire_deg(), [1.1, 2.0, 0.0]));
        // The board's clock wrapping forwards is no restart.
        let mut o = odo();
        o.sample(u32::MAX - 10, [0, 0]);
        assert_eq!(o.sample(90, [100, 100]), Step::Moved);
    }

    #[test]
    fn without_a_board_info_samples_are_not_integrated() {
        let mut o = WheelOdometry::new(Pose::default(), 0.5, 0.17);
        assert_eq!(o.sample(0, [0, 0]), Step::Unscaled);
        assert_eq!(o.sample(100, [500, 500]), Step::Unscaled);
        assert!(!o.set_counts_per_rev(0), "0 counts a turn is refused");
        assert!(!o.scaled());
        assert_eq!(o.pose().to_wire_deg(), [0.0, 0.0, 0.0]);
    }
}
