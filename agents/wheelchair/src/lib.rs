//! `iwsim agent wheelchair`: the thesis's "Wheelchair Robotic Agent" — several chairs in one
//! process, each with its body, motors, sensors, start pose, type and a script (constant
//! powers or waypoints), on the agent SDK.

use std::path::Path;
use std::process::ExitCode;

use agent_sdk::cli::{BodyArgs, CommonArgs};
use agent_sdk::logs::RobotLogs;
use agent_sdk::odometry::Odometry;
use agent_sdk::{Agent, Wait};
use anyhow::Context as _;
use ipc_types::{
    ActionBlock, COLLISION, HAS_COMPASS, MAX_PROXIMITY, RobotKind, RobotRegistration, SensorBlock, SensorSpec,
};
use serde::Deserialize;
use sim_model::{Pose, PoseDeg};

use clap::Args;
use std::path::PathBuf;

/// Options of `iwsim agent wheelchair`.
#[derive(Debug, Args, Clone)]
#[command(long_about = "Registers one or more wheelchairs and drives each by a script: constant motor \
powers, or a list of waypoints it drives to in turn (steering on its own odometry, its heading held \
by the compass: this is a scripted test agent, not a navigator) before it stops.

With --config FILE the chairs come from a TOML file, one [[chairs]] table each:

  [[chairs]]
  name = \"chair1\"
  pose = [12.5, 6.0, 180.0]      # x, y metres, heading degrees
  body = [1.1, 0.65, 0.8]        # length, width (wheel track), centre of movement
  max_speed = 0.49               # m/s at full power
  accel_curve = 0.83             # motor filter, thesis chapter 4
  sensors = [[0.88, 0.0, 0.0, 60.0, 3.0]]   # x, y, angle, cone, range (default: thesis Table 4.5)
  powers = [1.0, 1.0]            # script: constant powers, or
  waypoints = [[7.0, 6.0]]       # script: drive to each point in turn, then stop
  speed = 0.5                    # power used on the way to waypoints
  start_s = 0.0                  # wait this long before moving

Without --config, the options below describe --robots identical chairs.")]
#[command(mut_arg("log", |a| a.help("Write one CSV log per chair into this directory").value_name("LOG")))]
#[command(mut_arg("connect_timeout", |a| {
    a.help("Wait this many seconds for the hub to start serving the session").value_name("CONNECT_TIMEOUT")
}))]
pub struct WheelchairArgs {
    /// `--session`, `--connect-timeout`, `--log` (one CSV log per chair).
    #[command(flatten)]
    pub common: CommonArgs,
    /// Chairs from a TOML file (see above); the body and script options below are ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Robots to register.
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=ipc_types::MAX_ROBOTS as u64))]
    pub robots: usize,
    /// Name prefix of the robots.
    #[arg(long, default_value = "chair")]
    pub name: String,
    /// Requested id of the first robot (0: first free grid slot).
    #[arg(long, default_value_t = 0)]
    pub id: u32,
    /// Start pose of the first robot as X,Y,DIR (metres, degrees); further robots form a
    /// lattice `--spacing` apart, ten to a row. Without it, robots take grid slots.
    #[arg(long, value_parser = agent_sdk::args::pose, allow_hyphen_values = true)]
    pub pose: Option<PoseDeg>,
    /// Distance between robots of the lattice, metres.
    #[arg(long, default_value_t = 2.0)]
    pub spacing: f64,
    /// Motor powers LEFT,RIGHT in [-1, 1].
    #[arg(long, value_parser = agent_sdk::args::powers, default_value = "0.5,0.5", allow_hyphen_values = true)]
    pub powers: [f64; 2],
    /// How the chairs move: simulated (the hub moves them) or real (this agent moves them and
    /// tells the hub their poses, standing in for physical chairs).
    #[arg(long, value_enum, default_value = "simulated")]
    pub kind: ChairKind,
    /// `--width`, `--height`, `--com`.
    #[command(flatten)]
    pub body: BodyArgs,
    /// Top speed, m/s.
    #[arg(long, default_value_t = 0.5)]
    pub max_speed: f64,
    /// Acceleration curve, [0, 1).
    #[arg(long, default_value_t = 0.5)]
    pub accel_curve: f64,
    /// Stop after answering this many ticks (0: until the run ends).
    #[arg(long, default_value_t = 0)]
    pub ticks: u64,
    /// Spin on shared memory instead of sleeping between ticks.
    #[arg(long)]
    pub busy_poll: bool,
    /// At the end, print the hub-publish → agent-has-it latency percentiles as JSON.
    #[arg(long)]
    pub report_latency: bool,
}

/// How a chair moves (the thesis's robot `Type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ChairKind {
    /// The hub moves it from its motor powers.
    #[default]
    Simulated,
    /// It moves itself and tells the hub where it is, as a physical chair's controller does
    /// in mixed reality: here the agent stands in for the chair, integrating the thesis's
    /// motor filter and kinematics (eqs. 4.4–4.9) from its script's powers.
    Real,
}

/// One chair of a `--config` file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChairConfig {
    /// Name (also its log's file name).
    pub name: String,
    /// Requested id (0: any).
    #[serde(default)]
    pub id: u32,
    /// Start pose x, y metres, heading degrees (default: a grid slot).
    #[serde(default)]
    pub pose: Option<PoseDeg>,
    /// `simulated` (default) or `real`.
    #[serde(default)]
    pub kind: ChairKind,
    /// Length, width (wheel track), centre of movement.
    #[serde(default = "default_body")]
    pub body: [f64; 3],
    /// Speed at full power, m/s.
    #[serde(default = "default_speed")]
    pub max_speed: f64,
    /// Motor filter (thesis chapter 4).
    #[serde(default = "default_curve")]
    pub accel_curve: f64,
    /// Proximity sensors: x, y, angle, cone, range (empty: thesis Table 4.5's four).
    #[serde(default)]
    pub sensors: Vec<[f64; 5]>,
    /// Script: constant powers.
    #[serde(default)]
    pub powers: Option<[f64; 2]>,
    /// Script: points to drive to in turn, then stop.
    #[serde(default)]
    pub waypoints: Vec<[f64; 2]>,
    /// Power on the way to waypoints.
    #[serde(default = "default_cruise")]
    pub speed: f64,
    /// Seconds to stand still before the script starts.
    #[serde(default)]
    pub start_s: f64,
}

fn default_body() -> [f64; 3] {
    [1.0, 1.0, 0.5]
}
fn default_speed() -> f64 {
    0.5
}
fn default_curve() -> f64 {
    0.5
}
fn default_cruise() -> f64 {
    0.5
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    chairs: Vec<ChairConfig>,
}

/// Reads a `--config` file.
pub fn read_config(path: &Path) -> anyhow::Result<Vec<ChairConfig>> {
    let text = places::files::read_text(path).with_context(|| format!("reading {}", path.display()))?;
    let cfg: ConfigFile = toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e))?;
    anyhow::ensure!(!cfg.chairs.is_empty(), "{}: no [[chairs]]", path.display());
    for c in &cfg.chairs {
        anyhow::ensure!(c.sensors.len() <= MAX_PROXIMITY, "{}: chair {}: at most 8 sensors", path.display(), c.name);
        anyhow::ensure!(
            c.powers.is_none() || c.waypoints.is_empty(),
            "{}: chair {}: give powers or waypoints, not both",
            path.display(),
            c.name
        );
    }
    Ok(cfg.chairs)
}

/// The chairs the command line describes.
fn chairs_from_args(args: &WheelchairArgs) -> Vec<ChairConfig> {
    (0..args.robots)
        .map(|k| ChairConfig {
            name: format!("{}{}", args.name, k + 1),
            id: if args.id > 0 { args.id + k as u32 } else { 0 },
            pose: args
                .pose
                .map(|[x, y, dir]| [x + args.spacing * (k % 10) as f64, y + args.spacing * (k / 10) as f64, dir]),
            kind: args.kind,
            body: [args.body.width, args.body.height, args.body.com],
            max_speed: args.max_speed,
            accel_curve: args.accel_curve,
            sensors: Vec::new(),
            powers: Some(args.powers),
            waypoints: Vec::new(),
            speed: default_cruise(),
            start_s: 0.0,
        })
        .collect()
}

fn registration(c: &ChairConfig) -> RobotRegistration {
    let [w, h, com] = c.body;
    let mut reg =
        RobotRegistration::new(&c.name).id(c.id).body(w, h, com).motors(c.max_speed, c.accel_curve).at(c.pose);
    reg.kind = match c.kind {
        ChairKind::Simulated => RobotKind::Simulated,
        ChairKind::Real => RobotKind::Real,
    } as u32;
    for (k, [x_m, y_m, angle_deg, cone_deg, range_m]) in c.sensors.iter().copied().enumerate() {
        reg.sensors[k] = SensorSpec { x_m, y_m, angle_deg, cone_deg, range_m };
    }
    reg.sensor_count = c.sensors.len() as u32;
    reg
}

/// A physical chair's motion as the agent computes it for a `real` chair: the motor filter
/// `out = (1 − curve)·in + curve·out` and the differential-drive kinematics of thesis eqs.
/// 4.4–4.9, stepped as the hub steps simulated chairs, so that a real chair on a script goes
/// where a simulated one would (noise apart).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OwnMotion {
    /// Filtered motor outputs, left and right.
    pub out: [f64; 2],
    /// Where the chair is.
    pub pose: Pose,
}

impl OwnMotion {
    /// At rest at `pose`.
    pub fn at(pose: Pose) -> Self {
        Self { out: [0.0; 2], pose }
    }

    /// One tick of `dt` seconds with `powers`; returns the new pose. The formulas are the
    /// hub's own (`sim_model`), so only the hub's noise tells the two apart.
    pub fn step(&mut self, c: &ChairConfig, powers: [f64; 2], dt: f64) -> Pose {
        for (out, p) in self.out.iter_mut().zip(powers) {
            *out = sim_model::motor_filter(p.clamp(-1.0, 1.0), *out, c.accel_curve);
        }
        let (v, omega) = sim_model::velocity(c.max_speed, c.body[1], self.out);
        let (sin, cos) = self.pose.heading_rad.sin_cos();
        self.pose = sim_model::advance(self.pose, v, omega, cos, sin, dt);
        self.pose
    }
}

/// Powers that steer a chair at `pose` to `goal`: turn on the spot when far off course,
/// otherwise drive with a proportional correction. `None` once within 0.15 m.
pub fn toward(pose: Pose, goal: [f64; 2], speed: f64) -> Option<[f64; 2]> {
    let (dx, dy) = (goal[0] - pose.x_m, goal[1] - pose.y_m);
    if dx.hypot(dy) < 0.15 {
        return None;
    }
    let err = sim_model::wrap_rad(dy.atan2(dx) - pose.heading_rad);
    if err.abs() > 0.6 {
        let t = 0.3 * err.signum();
        return Some([-t, t]);
    }
    let turn = (0.8 * err).clamp(-0.3, 0.3);
    Some([(speed - turn).clamp(-1.0, 1.0), (speed + turn).clamp(-1.0, 1.0)])
}

/// The sensor block of robot `id`, the agent's `k`-th robot. The hub sends an agent's blocks in
/// registration order, so the `k`-th block is normally the one; once one of its robots is
/// removed the rest move up, and the block is found by its robot id instead. `None` when the
/// robot is gone.
pub fn sensor_block_of(blocks: &[SensorBlock], k: usize, id: u32) -> Option<&SensorBlock> {
    match blocks.get(k) {
        Some(b) if b.robot_id == id => Some(b),
        _ => blocks.iter().find(|b| b.robot_id == id),
    }
}

/// `iwsim agent wheelchair`.
pub fn run(args: &WheelchairArgs) -> anyhow::Result<ExitCode> {
    let chairs = match &args.config {
        Some(path) => read_config(path)?,
        None => chairs_from_args(args),
    };
    let mut agent = args.common.connect("wheelchair")?;
    // Close the agent on every path, errors included: the last process of a session removes
    // its files, even when the hub died first.
    let result = drive(&mut agent, args, &chairs);
    agent.close();
    result
}

fn drive(agent: &mut Agent, args: &WheelchairArgs, chairs: &[ChairConfig]) -> anyhow::Result<ExitCode> {
    let mut ids = Vec::new();
    for c in chairs {
        ids.push(agent.register(&registration(c)).with_context(|| format!("registering {}", c.name))?);
    }
    agent.ready()?;
    agent_sdk::report!(
        "wheelchair: agent {} drives robots {:?} in session {:?}",
        agent.id(),
        ids,
        args.common.hub.session
    );
    let mut logs = RobotLogs::new(args.common.log.as_deref());
    for (c, &id) in chairs.iter().zip(&ids) {
        logs.add(id, &c.name);
    }
    let wait = if args.busy_poll { Wait::BusyPoll } else { Wait::Blocking };
    let mut next_waypoint = vec![0usize; chairs.len()];
    let map = agent.map().context("reading the hub's map")?;
    // Real chairs move themselves by the simulated time since the tick they last answered
    // (in real time a slow agent may miss ticks); the first step is one cycle.
    let cycle_s = f64::from(map.header.cycle_ms.max(1)) / 1000.0;
    // Where each chair starts: the pose it asked for, or its grid slot. From there a simulated
    // chair knows where it is only by its encoders and compass (an agent never gets the true
    // pose), a real one by its own motion.
    let starts: Vec<PoseDeg> = chairs
        .iter()
        .zip(&ids)
        .map(|(c, &id)| {
            c.pose.unwrap_or_else(|| {
                map.grid.get(id as usize - 1).map_or([0.0; 3], |g| [g.pos.x, g.pos.y, g.heading_deg])
            })
        })
        .collect();
    let mut odometry: Vec<Odometry> = chairs
        .iter()
        .zip(&starts)
        .map(|(c, &start)| Odometry::new(Pose::from_wire_deg(start), map.header.params.encoder_ticks_per_m, c.body[1]))
        .collect();
    let mut own: Vec<OwnMotion> = starts.iter().map(|&p| OwnMotion::at(Pose::from_wire_deg(p))).collect();
    // A real chair's motion before its last step: where it goes back to when the hub refuses
    // the pose it pushed (the chair stopped against something).
    let mut before: Vec<Option<OwnMotion>> = chairs.iter().map(|_| None).collect();
    let mut last_time: Option<f64> = None;
    let mut actions: Vec<ActionBlock> = Vec::with_capacity(chairs.len());
    let mut answered = 0u64;
    let mut latencies_ns = Vec::new();
    while let Some(tick) = agent.wait_tick(wait)? {
        actions.clear();
        let dt = last_time.map_or(cycle_s, |t| (tick.sim_time_s - t).max(0.0));
        last_time = Some(tick.sim_time_s);
        for (k, (c, &id)) in chairs.iter().zip(&ids).enumerate() {
            let Some(b) = sensor_block_of(agent.sensors(), k, id) else { continue };
            let compass = (b.present & HAS_COMPASS != 0).then_some(b.compass_deg);
            let estimate = odometry[k].update(b.encoder_ticks, compass);
            if c.kind == ChairKind::Real
                && b.present & COLLISION != 0
                && let Some(m) = before[k]
            {
                own[k] = m;
            }
            let pose = match c.kind {
                ChairKind::Simulated => estimate,
                ChairKind::Real => own[k].pose,
            };
            // The script steers on the heading rounded through degrees, the unit a chair
            // reports, so that scripted runs reproduce bit for bit the paths they always drove.
            let pose = Pose::from_deg(pose.x_m, pose.y_m, pose.heading_deg());
            let powers = if tick.sim_time_s < c.start_s {
                [0.0, 0.0]
            } else if let Some(p) = c.powers {
                p
            } else {
                loop {
                    let Some(&goal) = c.waypoints.get(next_waypoint[k]) else { break [0.0, 0.0] };
                    match toward(pose, goal, c.speed) {
                        Some(p) => break p,
                        None => {
                            agent_sdk::report!(
                                "wheelchair {}: reached waypoint {:?} at t {:.1} s",
                                c.name,
                                goal,
                                tick.sim_time_s
                            );
                            next_waypoint[k] += 1;
                        }
                    }
                }
            };
            logs.row(b, tick.sim_time_s, powers)?;
            actions.push(match c.kind {
                ChairKind::Simulated => ActionBlock::motors(id, powers[0], powers[1]),
                ChairKind::Real => {
                    before[k] = Some(own[k]);
                    let p = own[k].step(c, powers, dt);
                    ActionBlock::pose(id, p.x_m, p.y_m, p.heading_deg())
                }
            });
        }
        agent.send(tick.tick, &actions)?;
        if args.report_latency {
            latencies_ns.push(tick.latency_ns);
        }
        answered += 1;
        if args.ticks > 0 && answered >= args.ticks {
            break;
        }
    }
    // The run's final tick too, when the hub ended the run (not after `--ticks`).
    logs.finish(agent)?;
    agent_sdk::report!("wheelchair: answered {answered} ticks");
    if args.report_latency {
        // The first ticks include connection set-up; they are not the steady state.
        let steady = latencies_ns.get(latencies_ns.len().min(100)..).unwrap_or(&[]);
        println!("{}", run_records::latency::Percentiles::of_ns(steady).json());
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;

    #[test]
    fn a_config_file_larger_than_the_cap_or_not_a_file_is_refused() {
        let big = std::env::temp_dir().join(format!("iwsim-wheelchair-big-{}.toml", std::process::id()));
        std::fs::File::create(&big)
            .and_then(|f| f.set_len(places::files::MAX_TEXT_FILE_BYTES + 1))
            .expect("a sparse file");
        let err = read_config(&big).expect_err("too large");
        std::fs::remove_file(&big).expect("clean up");
        assert!(format!("{err:#}").contains("the file is larger than"), "{err:#}");
        // /dev/zero once read until memory ran out.
        let err = read_config(Path::new("/dev/zero")).expect_err("a device");
        assert!(format!("{err:#}").contains("reading /dev/zero: not a regular file but a device"), "{err:#}");
    }

    #[test]
    fn chairs_are_paired_with_their_own_sensor_blocks_after_a_removal() {
        let block = |robot_id: u32, x: f64| SensorBlock { robot_id, gps_x_m: x, ..SensorBlock::zeroed() };
        let ids = [1, 2, 3];
        let all = [block(1, 10.0), block(2, 20.0), block(3, 30.0)];
        let paired: Vec<_> =
            ids.iter().enumerate().map(|(k, &id)| sensor_block_of(&all, k, id).map(|b| b.gps_x_m)).collect();
        assert_eq!(paired, vec![Some(10.0), Some(20.0), Some(30.0)]);
        // Robot 1 removed: its chair gets nothing, and chair 2 still gets robot 2's data.
        let after = [block(2, 20.0), block(3, 30.0)];
        let paired: Vec<_> =
            ids.iter().enumerate().map(|(k, &id)| sensor_block_of(&after, k, id).map(|b| b.robot_id)).collect();
        assert_eq!(paired, vec![None, Some(2), Some(3)]);
    }

    #[test]
    fn waypoint_steering_turns_first_then_drives() {
        // Facing +x, goal behind: turn on the spot (left wheel back, right forward for +).
        assert_eq!(toward(Pose::default(), [-5.0, 0.1], 0.5).map(|p| p[0] < 0.0 && p[1] > 0.0), Some(true));
        // Facing the goal: both wheels forward at the cruise power.
        assert_eq!(toward(Pose::default(), [5.0, 0.0], 0.5), Some([0.5, 0.5]));
        // Arrived.
        assert_eq!(toward(Pose::new(5.0, 0.05, 0.0), [5.0, 0.0], 0.5), None);
    }

    #[test]
    fn config_files_are_checked() {
        let dir = std::env::temp_dir().join(format!("iwsim-wcfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("c.toml");
        std::fs::write(&p, "[[chairs]]\nname = \"a\"\npowers = [1, 1]\nwaypoints = [[1, 2]]\n").expect("write");
        assert!(read_config(&p).expect_err("both").to_string().contains("not both"));
        std::fs::write(&p, "[[chairs]]\nname = \"a\"\nbody = [1, 2]\n").expect("write");
        let e = read_config(&p).expect_err("short body").to_string();
        assert!(e.contains("c.toml") && e.contains("line 3"), "{e}");
        std::fs::write(&p, "[[chairs]]\nname = \"a\"\npose = [10, 6.1, 0]\nwaypoints = [[12, 6.1]]\n").expect("write");
        let c = read_config(&p).expect("good");
        assert_eq!((c[0].pose, c[0].waypoints.len(), c[0].body), (Some([10.0, 6.1, 0.0]), 1, [1.0, 1.0, 0.5]));
        let _ = std::fs::remove_dir_all(dir);
    }
}
