//! Where the navigator's readings come from: the proximity sensors on the chair, and the seam
//! between the hub's virtual sensors and a physical chair's (thesis §5.4.3: Virtual, Real and
//! Augmented modes).
//!
//! The hub merges a physical chair's real readings with the virtual ones (its adapter, `iwsim
//! serial`, sends them), so every mode arrives in the same sensor block; [`check_mode`] makes
//! sure the block is in the mode asked for.

use ipc_types::{HAS_COMPASS, HAS_GPS, MAX_PROXIMITY, SensorBlock, SensorMode, SensorSpec};

use crate::geom::{Cone, Footprint, Pose, V2};

/// A proximity sensor on the chair, in the body frame (origin at the axle, x ahead, y left).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorMount {
    /// Along the heading, metres.
    pub x_m: f64,
    /// Across the heading (left positive), metres.
    pub y_m: f64,
    /// Direction relative to the heading, radians.
    pub angle_rad: f64,
    /// Full opening, radians.
    pub cone_rad: f64,
    /// Range, metres.
    pub range_m: f64,
}

impl SensorMount {
    /// A sensor from metres and degrees.
    pub fn deg(x_m: f64, y_m: f64, angle_deg: f64, cone_deg: f64, range_m: f64) -> Self {
        Self { x_m, y_m, angle_rad: angle_deg.to_radians(), cone_rad: cone_deg.to_radians(), range_m }
    }

    /// The sensor's cone in the lab frame for a chair at `pose`.
    pub fn cone(&self, pose: &Pose) -> Cone {
        Cone {
            apex: pose.to_world(V2::new(self.x_m, self.y_m)),
            dir: pose.theta + self.angle_rad,
            half: self.cone_rad / 2.0,
        }
    }

    /// The sensor as registered with the hub.
    pub fn spec(&self) -> SensorSpec {
        SensorSpec {
            x_m: self.x_m,
            y_m: self.y_m,
            angle_deg: sim_model::wire_deg(self.angle_rad),
            cone_deg: self.cone_rad.to_degrees(),
            range_m: self.range_m,
        }
    }
}

/// The navigator's eight sensors, placed on any body (positions scale with it), all with a
/// 3 m range:
///
/// | # | where                        | looking | cone | for                                 |
/// |---|------------------------------|---------|------|-------------------------------------|
/// | 0 | front centre                 | 0°      | 2°   | what is straight ahead, placed well |
/// | 1 | front, 0.6 of the way left   | +25°    | 3°   | faces ahead-left, gap edges         |
/// | 2 | front, 0.6 of the way right  | −25°    | 3°   | faces ahead-right, gap edges        |
/// | 3 | front-left corner            | +60°    | 10°  | what the front corner swings into   |
/// | 4 | front-right corner           | −60°    | 10°  | likewise on the right               |
/// | 5 | left side, body centre       | +90°    | 20°  | what the chair passes               |
/// | 6 | right side, body centre      | −90°    | 20°  | likewise on the right               |
/// | 7 | rear centre                  | 180°    | 30°  | backing up                          |
///
/// Narrow cones are what make the sensed map usable in a 1 m gap: a reading says only that
/// something lies somewhere on an arc across its cone, at the distance read, and a 12° arc at
/// 2 m is 0.4 m long — as long as the slalom's clearance. With 2–3° the forward sensors place
/// a face within a few centimetres; the chair's motion sweeps them across what lies ahead.
/// The wider side and rear cones mostly clear space (everything nearer than a reading is
/// free) and feed the reactive layer.
pub fn default_layout(fp: &Footprint) -> Vec<SensorMount> {
    let (front, rear, half, mid) = (fp.front, fp.rear, fp.half, fp.centre_offset());
    let range = 3.0;
    vec![
        SensorMount::deg(front, 0.0, 0.0, 2.0, range),
        SensorMount::deg(front, 0.6 * half, 25.0, 3.0, range),
        SensorMount::deg(front, -0.6 * half, -25.0, 3.0, range),
        SensorMount::deg(front, half, 60.0, 10.0, range),
        SensorMount::deg(front, -half, -60.0, 10.0, range),
        SensorMount::deg(mid, half, 90.0, 20.0, range),
        SensorMount::deg(mid, -half, -90.0, 20.0, range),
        SensorMount::deg(-rear, 0.0, 180.0, 30.0, range),
    ]
}

/// A GPS fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpsFix {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, degrees.
    pub heading_deg: f64,
}

/// One tick's readings, whatever their source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Input {
    /// The tick.
    pub tick: u64,
    /// Simulated seconds.
    pub time_s: f64,
    /// Proximity distances, metres (first `proximity_count`).
    pub proximity_m: [f64; MAX_PROXIMITY],
    /// Proximity sensors reported.
    pub proximity_count: usize,
    /// Cumulative wheel-encoder ticks, left and right.
    pub encoder_ticks: [i64; 2],
    /// The GPS fix, when the run has GPS on.
    pub gps: Option<GpsFix>,
    /// The compass heading, degrees, when the run has the compass on.
    pub compass_deg: Option<f64>,
    /// The collision sensor.
    pub collision: bool,
}

impl Input {
    /// The proximity readings.
    pub fn proximity(&self) -> &[f64] {
        &self.proximity_m[..self.proximity_count.min(MAX_PROXIMITY)]
    }

    /// The readings of the hub's sensor block (the virtual sensors), which carries what the
    /// chair's sensors measure and never where it truly is.
    pub fn from_block(b: &SensorBlock, time_s: f64) -> Self {
        let gps = (b.present & HAS_GPS != 0).then_some(GpsFix {
            x_m: b.gps_x_m,
            y_m: b.gps_y_m,
            heading_deg: b.gps_heading_deg,
        });
        Self {
            tick: b.tick,
            time_s,
            proximity_m: b.proximity_m,
            proximity_count: (b.proximity_count as usize).min(MAX_PROXIMITY),
            encoder_ticks: b.encoder_ticks,
            gps,
            compass_deg: (b.present & HAS_COMPASS != 0).then_some(b.compass_deg),
            collision: b.present & ipc_types::COLLISION != 0,
        }
    }
}

/// Where the chair's sensors are read (thesis §5.4.3). The hub does the merging: a physical
/// chair's adapter (`iwsim serial`) sends it the chair's real readings, and the chair's block
/// carries what the mode selects, so the navigator reads every mode the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// The hub's readings: of a simulated chair, or the virtual twin of a physical one.
    Virtual,
    /// A physical chair's own sensors and encoders (its adapter must be registered first).
    Real,
    /// A physical chair that also sees the virtual world: per sensor, the nearer of the real
    /// and the virtual reading.
    Augmented,
}

impl Mode {
    /// The hub's name for the mode.
    pub fn wire(self) -> SensorMode {
        match self {
            Self::Virtual => SensorMode::Virtual,
            Self::Real => SensorMode::Real,
            Self::Augmented => SensorMode::Augmented,
        }
    }
}

/// Why the readings do not come from where they were asked to.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SensorSourceOpenError {
    /// Real and Augmented need a physical chair behind its adapter, which the hub did not
    /// attach this agent to.
    #[error(
        "--sensors {0}: robot {1:?} is not a physical chair; start its adapter first (`iwsim serial --robot {1} ...`) \
         so that this agent attaches to it"
    )]
    NotAChair(&'static str, String),
}

/// Checks that the first block of `name` is in the mode asked for: a navigator in real or
/// augmented mode that got a simulated chair would drive blind to what it was told to see.
pub fn check_mode(mode: Mode, name: &str, block: &SensorBlock) -> Result<(), SensorSourceOpenError> {
    let label = match mode {
        Mode::Virtual => return Ok(()),
        Mode::Real => "real",
        Mode::Augmented => "augmented",
    };
    if block.sensor_mode == mode.wire() as u32 && block.drive_flags & ipc_types::DRIVE_CONTROLLED != 0 {
        Ok(())
    } else {
        Err(SensorSourceOpenError::NotAChair(label, name.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;

    #[test]
    fn real_and_augmented_modes_need_the_block_of_an_attached_chair() {
        let mut b = SensorBlock::zeroed();
        assert_eq!(check_mode(Mode::Virtual, "c", &b), Ok(()));
        let e = check_mode(Mode::Real, "c", &b).expect_err("a simulated chair's block");
        assert!(e.to_string().contains("iwsim serial --robot c"), "{e}");
        b.sensor_mode = SensorMode::Augmented as u32;
        b.drive_flags = ipc_types::DRIVE_CONTROLLED;
        assert_eq!(check_mode(Mode::Augmented, "c", &b), Ok(()));
        assert!(check_mode(Mode::Real, "c", &b).is_err(), "the hub's mode differs");
    }

    #[test]
    fn the_default_layout_is_the_physical_chairs() {
        let [w, h, com] = sim_model::chair::BODY;
        let layout = default_layout(&Footprint::of_body(w, h, com));
        assert_eq!(layout.len(), sim_model::chair::SENSORS.len());
        for (m, c) in layout.iter().zip(&sim_model::chair::SENSORS) {
            let spec = m.spec();
            for (a, b) in [
                (spec.x_m, c.x_m),
                (spec.y_m, c.y_m),
                (spec.angle_deg, c.angle_deg),
                (spec.cone_deg, c.cone_deg),
                (spec.range_m, c.range_m),
            ] {
                assert!((a - b).abs() < 1e-9, "{m:?} vs {c:?}");
            }
        }
    }

    #[test]
    fn blocks_give_readings_but_never_the_true_pose() {
        let mut b = SensorBlock::zeroed();
        b.tick = 4;
        b.proximity_count = 2;
        b.proximity_m[..2].copy_from_slice(&[0.5, 2.5]);
        b.encoder_ticks = [100, 120];
        let i = Input::from_block(&b, 0.4);
        assert_eq!((i.tick, i.proximity(), i.encoder_ticks, i.gps), (4, &[0.5, 2.5][..], [100, 120], None));
        b.present = HAS_GPS;
        b.gps_x_m = 9.0;
        assert_eq!(Input::from_block(&b, 0.4).gps.map(|g| g.x_m), Some(9.0));
        assert_eq!(i.compass_deg, None, "no compass bit, no heading");
        b.present = HAS_COMPASS;
        b.compass_deg = -135.0;
        assert_eq!(Input::from_block(&b, 0.4).compass_deg, Some(-135.0));
    }

    #[test]
    fn the_layout_keeps_every_sensor_on_the_body() {
        let fp = Footprint::of_body(1.1, 0.65, 0.8);
        let layout = default_layout(&fp);
        assert_eq!(layout.len(), 8);
        for s in &layout {
            assert!(s.x_m <= fp.front + 1e-9 && s.x_m >= -fp.rear - 1e-9 && s.y_m.abs() <= fp.half + 1e-9);
            assert!(s.range_m <= 3.0);
        }
        let c = layout[0].cone(&Pose::from_deg(10.0, 6.1, 90.0));
        assert!((c.apex.x - 10.0).abs() < 1e-9 && (c.apex.y - 6.98).abs() < 1e-9);
    }
}
