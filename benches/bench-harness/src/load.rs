//! The real load of `iwsim bench lockstep --load real`: where the robots stand, the agents
//! that read every sensor block and steer, and the UDP clients that parse every `<Measures>`.
//!
//! The IPC-only run measures the hub, iceoryx2 and the kernel's wake-ups: its agents answer
//! constant powers without looking at their sensors, and its robots stand 5 m apart with 3 m
//! sensors, seeing nothing. Here each robot is a chair of [`crate::tiled::chair_spec`] (eight
//! sensors round its body) on a lattice [`SPACING_M`] apart, so that about eight neighbours
//! are within sensor range and every reading costs the hub a real ray cast against them; each
//! tick every agent reads all its robots' blocks and steers each by [`crate::tiled::steer`],
//! the controller `bench world` runs. Over UDP each client decodes every datagram in full
//! (every sensor, LED and button, with the bridge codec's [`udp_bridge::codec::decode_measures`],
//! an XML parse as a stock Ciber-Rato client's handler makes) and answers with `DriveMotors`'
//! `<Actions>`.

use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::{Agent, Wait};
use anyhow::Context as _;
use ipc_types::{ActionBlock, COLLISION, HAS_COMPASS, MAX_PROXIMITY, RobotRegistration, SensorSpec};
use sim_model::PoseDeg;
use udp_bridge::codec::MeasuresData;
use world::math::Pose;

use crate::args::LoadAgentArgs;

/// Distance between neighbouring robots of the lattice, metres. A chair's bounding circle
/// has a radius of 0.93 m, so chairs 2 m apart never start touching whatever their heading;
/// with the hub's 3 m sensors each chair inside the lattice has its 4 side and 4 diagonal
/// neighbours (2 m and 2.8 m away) in range.
pub const SPACING_M: f64 = 2.0;
/// Free floor round the lattice, metres.
const MARGIN_M: f64 = 5.0;
/// A reading shorter than this saw something: well under the 3 m range, so the range's own
/// noise (σ 0.1 m) never counts.
pub const NEAR_M: f64 = 2.5;

/// Where the robots of a real-load run stand: one square lattice for every robot of every
/// agent, filled row by row, headings spread by the golden angle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lattice {
    /// Robots on the lattice.
    pub total: usize,
    /// Robots to a row.
    pub cols: usize,
}

impl Lattice {
    /// A near-square lattice of `total` robots.
    pub fn new(total: usize) -> Self {
        let total = total.max(1);
        Self { total, cols: (total as f64).sqrt().ceil() as usize }
    }

    fn rows(&self) -> usize {
        self.total.div_ceil(self.cols)
    }

    /// The start pose of robot `g` (0-based over all agents): x, y metres, heading degrees.
    pub fn pose(&self, g: usize) -> PoseDeg {
        let heading_deg = (g as f64 * 137.507_764).rem_euclid(360.0) - 180.0;
        [MARGIN_M + SPACING_M * (g % self.cols) as f64, MARGIN_M + SPACING_M * (g / self.cols) as f64, heading_deg]
    }

    /// An open lab that holds the lattice with [`MARGIN_M`] all round.
    pub fn lab_xml(&self) -> String {
        let side = |n: usize| 2.0 * MARGIN_M + SPACING_M * n.saturating_sub(1) as f64;
        format!(
            "<Lab Name=\"bench-real\" Width=\"{}\" Height=\"{}\">\n</Lab>\n",
            side(self.cols).max(20.0),
            side(self.rows()).max(20.0)
        )
    }

    /// How many other robots stand within `range_m` of a robot (centre to centre) at the
    /// start, on average over the lattice (robots on its edge have fewer).
    pub fn mean_neighbours_within(&self, range_m: f64) -> f64 {
        let reach = (range_m / SPACING_M).floor() as i64;
        let (cols, n) = (self.cols as i64, self.total as i64);
        let mut pairs = 0u64;
        for g in 0..n {
            let (x, y) = (g % cols, g / cols);
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (nx, ny) = (x + dx, y + dy);
                    let other = ny * cols + nx;
                    let dist = SPACING_M * ((dx * dx + dy * dy) as f64).sqrt();
                    if (dx, dy) != (0, 0) && (0..cols).contains(&nx) && ny >= 0 && other < n && dist <= range_m {
                        pairs += 1;
                    }
                }
            }
        }
        pairs as f64 / n as f64
    }
}

/// The hub's default proximity range, metres (the chairs' sensors take it).
pub fn sensor_range_m() -> f64 {
    world::map::Params::default().proximity_range()
}

/// The registration of a bench chair called `name` at `pose` (x, y metres, heading degrees):
/// [`crate::tiled::chair_spec`]'s body, motors and eight sensors.
pub fn chair_registration(name: &str, pose: PoseDeg) -> RobotRegistration {
    let spec = crate::tiled::chair_spec(Pose::new(0.0, 0.0, 0.0));
    let mut reg = RobotRegistration::new(name)
        .body(spec.width_m, spec.height_m, spec.com)
        .motors(spec.max_speed_mps, spec.accel_curve)
        .at(Some(pose));
    for (slot, s) in reg.sensors.iter_mut().zip(&spec.sensors) {
        *slot = SensorSpec {
            x_m: s.x_m,
            y_m: s.y_m,
            angle_deg: s.angle_rad.to_degrees(),
            cone_deg: s.cone_rad.to_degrees(),
            range_m: s.range_m.unwrap_or(0.0),
        };
    }
    reg.sensor_count = spec.sensors.len().min(MAX_PROXIMITY) as u32;
    reg
}

/// The same chair as an Intellwheels `<Robot>` registration datagram.
pub fn chair_registration_xml(name: &str, pose: PoseDeg) -> String {
    let r = chair_registration(name, pose);
    let mut s = format!(
        "<Robot Name=\"{name}\" Width=\"{}\" Height=\"{}\" COM=\"{}\" MaxSpeed=\"{}\" AccelerationCurve=\"{}\" X=\"{}\" Y=\"{}\" Dir=\"{}\">",
        r.width_m, r.height_m, r.com, r.max_speed_mps, r.accel_curve, pose[0], pose[1], pose[2]
    );
    for (id, sensor) in r.sensors[..r.sensor_count as usize].iter().enumerate() {
        s += &format!(
            "<IRSensor Id=\"{id}\" X=\"{}\" Y=\"{}\" Angle=\"{}\" Cone=\"{}\"/>",
            sensor.x_m, sensor.y_m, sensor.angle_deg, sensor.cone_deg
        );
    }
    s + "</Robot>"
}

/// What a loaded agent or client read over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Readings {
    /// Ticks answered.
    pub ticks: u64,
    /// Proximity readings read.
    pub total: u64,
    /// Of them, shorter than [`NEAR_M`]: the sensor saw a neighbour (or a wall).
    pub near: u64,
}

/// The line a loaded agent or client ends its stdout with.
const REPORT: &str = "load readings";

impl Readings {
    /// Counts one robot's readings, metres.
    pub fn add(&mut self, distances_m: &[f64]) {
        self.total += distances_m.len() as u64;
        self.near += distances_m.iter().filter(|&&d| d < NEAR_M).count() as u64;
    }

    /// The report line.
    pub fn line(&self) -> String {
        format!("{REPORT} ticks {} total {} near {}", self.ticks, self.total, self.near)
    }

    /// The sum of the report lines in `stdout` (none: zero).
    pub fn sum_of(stdout: &str) -> Readings {
        let mut sum = Readings::default();
        for line in stdout.lines().filter_map(|l| l.strip_prefix(REPORT)) {
            let mut words = line.split_whitespace();
            while let (Some(key), Some(value)) = (words.next(), words.next()) {
                let v: u64 = value.parse().unwrap_or(0);
                match key {
                    "ticks" => sum.ticks += v,
                    "total" => sum.total += v,
                    "near" => sum.near += v,
                    _ => {}
                }
            }
        }
        sum
    }

    /// The share of readings that saw something, in [0, 1].
    pub fn near_fraction(&self) -> f64 {
        if self.total == 0 { 0.0 } else { self.near as f64 / self.total as f64 }
    }
}

/// The hidden `iwsim bench load-agent`: registers its robots on the lattice, then each tick
/// reads every one of its sensor blocks and answers with the reactive rule's powers.
pub fn load_agent(args: &LoadAgentArgs) -> anyhow::Result<ExitCode> {
    let name = format!("load-agent-{}", std::process::id());
    let mut agent = match &args.zenoh {
        Some(endpoint) => {
            Agent::connect_zenoh(&agent_sdk::remote::Remote::new(endpoint), &args.session, Duration::from_secs(30))?
        }
        None => Agent::connect_within(&args.session, &name, Duration::from_secs(30))?,
    };
    // Close on every path, so the last process of a session removes its files.
    let result = drive(&mut agent, args);
    agent.close();
    let readings = result?;
    println!("{}", readings.line());
    Ok(ExitCode::SUCCESS)
}

fn drive(agent: &mut Agent, args: &LoadAgentArgs) -> anyhow::Result<Readings> {
    let lattice = Lattice::new(args.total);
    for g in args.first..args.first + args.robots {
        agent
            .register(&chair_registration(&format!("load{g}"), lattice.pose(g)))
            .with_context(|| format!("robot {g}"))?;
    }
    agent.ready()?;
    // The bench starts agents in waves, each once the last has said this.
    agent_sdk::report!(
        "load agent: agent {} drives robots {}..{} in session {:?}",
        agent.id(),
        args.first,
        args.first + args.robots,
        args.session
    );
    let mut actions = Vec::with_capacity(args.robots);
    let mut readings = Readings::default();
    while let Some(tick) = agent.wait_tick(Wait::Blocking)? {
        actions.clear();
        for b in agent.sensors() {
            let d = &b.proximity_m[..(b.proximity_count as usize).min(MAX_PROXIMITY)];
            readings.add(d);
            // On a tie, turn towards the side the chair already faces, as a driver would.
            let left_on_tie = b.present & HAS_COMPASS == 0 || b.compass_deg >= 0.0;
            if let Some((l, r)) = crate::tiled::steer(d, b.present & COLLISION != 0, left_on_tie) {
                actions.push(ActionBlock::motors(b.robot_id, l, r));
            }
        }
        agent.send(tick.tick, &actions)?;
        readings.ticks += 1;
    }
    Ok(readings)
}

/// A robot's IR readings as distances, metres (an IR value is 1 / distance).
pub fn distances_m(m: &MeasuresData) -> impl Iterator<Item = f64> + '_ {
    m.ir.iter().flatten().map(|&v| if v > 0.0 { 1.0 / v } else { f64::INFINITY })
}

/// Ciber-Rato powers are in [−0.15, 0.15]; the bridge maps 0.15 onto a full 1.0.
const CIBER_RATO_FULL_POWER: f64 = 0.15;

/// What the real-load UDP client answers a decoded `<Measures>` with (`DriveMotors`), and the
/// distances it read (for the count).
pub fn answer(m: &MeasuresData, distances: &mut Vec<f64>, left_on_tie: bool) -> String {
    distances.clear();
    distances.extend(distances_m(m));
    let collision = m.collision == Some(true);
    let (l, r) = crate::tiled::steer(distances, collision, left_on_tie).unwrap_or((0.0, 0.0));
    format!("<Actions LeftMotor=\"{:.4}\" RightMotor=\"{:.4}\"/>", l * CIBER_RATO_FULL_POWER, r * CIBER_RATO_FULL_POWER)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_inside_the_lattice_has_eight_neighbours_in_range_and_none_overlap() {
        let l = Lattice::new(100);
        assert_eq!(l.cols, 10);
        // 10 x 10: 180 side pairs and 162 diagonal pairs, each counted from both ends.
        assert!((l.mean_neighbours_within(3.0) - 6.84).abs() < 1e-9);
        assert_eq!(Lattice::new(9).mean_neighbours_within(3.0) * 9.0, 40.0, "3 x 3: the centre has 8");
        let [x0, y0, _] = l.pose(0);
        let [x1, y1, _] = l.pose(1);
        let [x10, y10, _] = l.pose(10);
        assert_eq!((x1 - x0, y1 - y0, x10 - x0, y10 - y0), (SPACING_M, 0.0, 0.0, SPACING_M));
        // Two chairs' bounding circles (0.93 m: the chair's far corner from its wheel axis)
        // never meet at this spacing.
        let spec = crate::tiled::chair_spec(Pose::new(0.0, 0.0, 0.0));
        let reach = (spec.com * spec.width_m).hypot(spec.height_m / 2.0);
        assert!(2.0 * reach < SPACING_M, "{reach}");
    }

    #[test]
    fn the_lab_holds_the_lattice() {
        let l = Lattice::new(1000);
        let xml = l.lab_xml();
        // 32 to a row: the row's last robot and the last row set the lab's size.
        let (right, top) = (l.pose(31)[0], l.pose(999)[1]);
        assert!(xml.contains(&format!("Width=\"{}\" Height=\"{}\"", right + MARGIN_M, top + MARGIN_M)), "{xml}");
    }

    #[test]
    fn ir_values_read_as_distances() {
        let m = MeasuresData { ir: vec![Some(2.0), None, Some(0.4)], ..MeasuresData::default() };
        assert_eq!(distances_m(&m).collect::<Vec<_>>(), vec![0.5, 2.5]);
    }

    #[test]
    fn a_blocked_chair_turns_on_the_spot_at_ciber_rato_power() {
        let m = MeasuresData { collision: Some(true), ir: vec![Some(0.5); 5], ..MeasuresData::default() };
        let mut d = Vec::new();
        assert_eq!(answer(&m, &mut d, true), "<Actions LeftMotor=\"-0.0600\" RightMotor=\"0.0600\"/>");
        assert_eq!(d.len(), 5);
    }

    #[test]
    fn report_lines_add_up_over_agents() {
        let a = Readings { ticks: 10, total: 80, near: 40 };
        let b = Readings { ticks: 10, total: 80, near: 20 };
        let out = format!("noise\n{}\n{}\n", a.line(), b.line());
        assert_eq!(Readings::sum_of(&out), Readings { ticks: 20, total: 160, near: 60 });
        assert_eq!(Readings::sum_of(&out).near_fraction(), 0.375);
    }

    #[test]
    fn the_chair_registers_with_its_eight_sensors_over_udp_too() {
        let xml = chair_registration_xml("c", [1.0, 2.0, 90.0]);
        assert_eq!(xml.matches("<IRSensor ").count(), 8, "{xml}");
        assert!(xml.starts_with("<Robot Name=\"c\" Width=\"1.1\" Height=\"0.65\" COM=\"0.8\""), "{xml}");
        assert_eq!(chair_registration("c", [1.0, 2.0, 90.0]).sensor_count, 8);
    }
}
