//! The board's range readings as the hub takes them: metres, in the chair's sensor order
//! (`sim_model::chair::SENSORS`, whose board ids say which reading is which), NaN where no
//! fresh reading came since the last tick (the hub keeps the last one), +∞ for no echo.

use ipc_types::MAX_PROXIMITY;
use serial_protocol::{NO_ECHO, Reading, Sample};
use sim_model::chair::{Kind, index_of};

/// A board range in millimetres as metres: +∞ for no echo within the sensor's reach.
pub fn range_m(range_mm: u16) -> f32 {
    if range_mm == NO_ECHO { f32::INFINITY } else { f32::from(range_mm) / 1000.0 }
}

/// The freshest reading of each of the chair's sensors since the last tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreshReadings {
    m: [f32; MAX_PROXIMITY],
    /// Readings of sensor ids the chair's profile does not have, ignored.
    unknown: u64,
}

impl Default for FreshReadings {
    fn default() -> FreshReadings {
        FreshReadings::new()
    }
}

impl FreshReadings {
    /// No readings.
    pub fn new() -> FreshReadings {
        FreshReadings { m: [f32::NAN; MAX_PROXIMITY], unknown: 0 }
    }

    /// Takes a sample's readings; a later sample's reading of a sensor replaces an earlier one.
    pub fn add(&mut self, sample: &Sample) {
        let all = sample
            .ir
            .as_slice()
            .iter()
            .map(|r| (Kind::Ir, r))
            .chain(sample.sonar.as_slice().iter().map(|r| (Kind::Sonar, r)));
        for (kind, &Reading { id, range_mm }) in all {
            match index_of(kind, id).and_then(|i| self.m.get_mut(i)) {
                Some(slot) => *slot = range_m(range_mm),
                None => self.unknown = self.unknown.saturating_add(1),
            }
        }
    }

    /// The readings for this tick, in the hub's sensor order; starts afresh.
    pub fn take(&mut self) -> [f32; MAX_PROXIMITY] {
        std::mem::replace(&mut self.m, [f32::NAN; MAX_PROXIMITY])
    }

    /// Readings ignored so far because the chair has no sensor of that kind and id.
    pub fn unknown(&self) -> u64 {
        self.unknown
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serial_protocol::Readings;
    use sim_model::chair::SENSORS;

    fn sample(ir: &[(u8, u16)], sonar: &[(u8, u16)]) -> Sample {
        let r = |v: &[(u8, u16)]| {
            Readings::from_slice(&v.iter().map(|&(id, range_mm)| Reading { id, range_mm }).collect::<Vec<_>>())
                .expect("at most 8")
        };
        Sample { ir: r(ir), sonar: r(sonar), ..Sample::default() }
    }

    #[test]
    fn readings_land_at_their_sensors_hub_index_in_metres_and_no_echo_is_infinite() {
        let mut f = FreshReadings::new();
        f.add(&sample(&[(0, 850), (2, NO_ECHO)], &[(4, 1200), (0, 300)]));
        let m = f.take();
        let at = |kind, id| index_of(kind, id).expect("a mounted sensor");
        assert_eq!(m[at(Kind::Ir, 0)], 0.85);
        assert_eq!(m[at(Kind::Ir, 2)], f32::INFINITY);
        assert_eq!(m[at(Kind::Sonar, 4)], 1.2);
        assert_eq!(m[at(Kind::Sonar, 0)], 0.3);
        assert_eq!(m.iter().filter(|v| v.is_nan()).count(), SENSORS.len() - 4, "the rest: no fresh reading");
        assert!(f.take().iter().all(|v| v.is_nan()), "taken: nothing fresh until the next sample");
    }

    #[test]
    fn ids_the_chair_does_not_have_are_ignored_and_counted() {
        let mut f = FreshReadings::new();
        // The chair has IR 0..=2 and sonars 0..=4.
        f.add(&sample(&[(3, 100), (7, 100)], &[(5, 100)]));
        assert!(f.take().iter().all(|v| v.is_nan()));
        assert_eq!(f.unknown(), 3);
    }

    #[test]
    fn a_later_samples_reading_replaces_an_earlier_one_and_others_stay() {
        let mut f = FreshReadings::new();
        f.add(&sample(&[(0, 500), (1, 600)], &[]));
        f.add(&sample(&[(0, 400)], &[]));
        let m = f.take();
        assert_eq!(m[index_of(Kind::Ir, 0).expect("ir 0")], 0.4);
        assert_eq!(m[index_of(Kind::Ir, 1).expect("ir 1")], 0.6);
        assert_eq!(range_m(0), 0.0);
    }
}
