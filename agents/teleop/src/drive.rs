//! What the driver has asked for (speed, turn, step) and the wheel powers it makes.

use crate::keys::Key;

/// The steps `+` and `-` move between, as fractions of full power.
pub const STEPS: [f64; 6] = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5];
/// The step a session starts with (0.1 of full power).
const DEFAULT_STEP: usize = 3;
/// Largest turn term: at ±1 a stopped chair spins on the spot at full power.
pub const MAX_TURN: f64 = 1.0;

/// The driver's command: a speed and a turn, each changed by one step per key press.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    speed: f64,
    turn: f64,
    step: usize,
}

impl Default for Drive {
    fn default() -> Self {
        Self { speed: 0.0, turn: 0.0, step: DEFAULT_STEP }
    }
}

/// Rounds away the drift of repeated float steps (0.1 + 0.2 ≠ 0.3), so a speed stepped up and
/// back down is exactly zero again.
fn tidy(v: f64) -> f64 {
    let r = (v * 1e6).round() / 1e6;
    if r == 0.0 { 0.0 } else { r }
}

impl Drive {
    /// Stopped, with a step of 0.1.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forward speed in [−1, 1] (fraction of full power; negative is reverse).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Turn term in [−`MAX_TURN`, `MAX_TURN`]; positive turns left (counter-clockwise).
    pub fn turn(&self) -> f64 {
        self.turn
    }

    /// The size of one step.
    pub fn step(&self) -> f64 {
        STEPS[self.step]
    }

    /// Applies a key; whether anything changed. [`Key::Quit`] and [`Key::Resume`] change nothing here.
    pub fn apply(&mut self, key: Key) -> bool {
        let before = *self;
        let step = self.step();
        match key {
            Key::Faster => self.speed = tidy((self.speed + step).min(1.0)),
            Key::Slower => self.speed = tidy((self.speed - step).max(-1.0)),
            Key::Left => self.turn = tidy((self.turn + step).min(MAX_TURN)),
            Key::Right => self.turn = tidy((self.turn - step).max(-MAX_TURN)),
            Key::Stop => (self.speed, self.turn) = (0.0, 0.0),
            Key::StepUp => self.step = (self.step + 1).min(STEPS.len() - 1),
            Key::StepDown => self.step = self.step.saturating_sub(1),
            Key::Quit | Key::Resume => {}
        }
        *self != before
    }

    /// Wheel powers `[left, right]`: the turn is taken from the left wheel and given to the
    /// right, each clamped to [−1, 1].
    pub fn powers(&self) -> [f64; 2] {
        [tidy((self.speed - self.turn).clamp(-1.0, 1.0)), tidy((self.speed + self.turn).clamp(-1.0, 1.0))]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn after(keys: &[Key]) -> Drive {
        let mut d = Drive::new();
        for &k in keys {
            d.apply(k);
        }
        d
    }

    #[test]
    fn a_new_drive_is_stopped_with_a_step_of_a_tenth() {
        let d = Drive::new();
        assert_eq!((d.speed(), d.turn(), d.step(), d.powers()), (0.0, 0.0, 0.1, [0.0, 0.0]));
    }

    #[test]
    fn faster_and_slower_step_the_speed_and_both_wheels() {
        let d = after(&[Key::Faster; 3]);
        assert_eq!(d.speed(), 0.3);
        assert_eq!(d.powers(), [0.3, 0.3]);
        let d = after(&[Key::Faster, Key::Faster, Key::Slower, Key::Slower]);
        assert_eq!(d.speed(), 0.0, "stepping up and down returns to exactly zero");
        let d = after(&[Key::Slower; 2]);
        assert_eq!(d.powers(), [-0.2, -0.2], "below zero is reverse");
    }

    #[test]
    fn speed_is_bounded_to_full_power_both_ways() {
        assert_eq!(after(&[Key::Faster; 15]).speed(), 1.0);
        assert_eq!(after(&[Key::Slower; 15]).speed(), -1.0);
        let mut d = after(&[Key::Faster; 10]);
        assert!(!d.apply(Key::Faster), "a press at the bound changes nothing");
    }

    #[test]
    fn left_takes_from_the_left_wheel_and_gives_to_the_right() {
        let d = after(&[Key::Faster, Key::Faster, Key::Faster, Key::Faster, Key::Faster, Key::Left]);
        assert_eq!(d.turn(), 0.1);
        assert_eq!(d.powers(), [0.4, 0.6]);
        let d = after(&[Key::Right, Key::Right]);
        assert_eq!(d.powers(), [0.2, -0.2], "turning right on the spot");
        assert_eq!(after(&[Key::Left; 3]).powers(), [-0.3, 0.3], "turning left on the spot");
    }

    #[test]
    fn turn_is_bounded_and_powers_are_clamped_per_wheel() {
        assert_eq!(after(&[Key::Left; 20]).turn(), MAX_TURN);
        assert_eq!(after(&[Key::Right; 20]).turn(), -MAX_TURN);
        let mut keys = vec![Key::Faster; 8];
        keys.extend([Key::Left; 5]);
        let d = after(&keys);
        assert_eq!((d.speed(), d.turn()), (0.8, 0.5));
        assert_eq!(d.powers(), [0.3, 1.0], "0.8 + 0.5 is clamped to full power");
    }

    #[test]
    fn space_stops_speed_and_turn_but_keeps_the_step() {
        let d = after(&[Key::StepUp, Key::Faster, Key::Left, Key::Stop]);
        assert_eq!((d.speed(), d.turn(), d.step(), d.powers()), (0.0, 0.0, 0.2, [0.0, 0.0]));
    }

    #[test]
    fn plus_and_minus_move_through_the_steps_and_stop_at_the_ends() {
        assert_eq!(after(&[Key::StepUp]).step(), 0.2);
        assert_eq!(after(&[Key::StepUp; 10]).step(), 0.5);
        assert_eq!(after(&[Key::StepDown]).step(), 0.05);
        assert_eq!(after(&[Key::StepDown; 10]).step(), 0.01);
        let d = after(&[Key::StepDown, Key::Faster, Key::Faster, Key::Faster]);
        assert_eq!(d.speed(), 0.15);
    }

    #[test]
    fn apply_reports_whether_anything_changed() {
        let mut d = Drive::new();
        assert!(d.apply(Key::Faster));
        assert!(d.apply(Key::Stop));
        assert!(!d.apply(Key::Stop));
        assert!(!d.apply(Key::Quit));
        for _ in 0..3 {
            assert!(d.apply(Key::StepDown));
        }
        assert!(!d.apply(Key::StepDown), "already the smallest step");
    }
}
