//! The agent process: connect to a hub, register the chair, and answer every tick with the
//! navigator's wheel powers.

use std::process::ExitCode;

use agent_sdk::logs::RobotLogs;
use agent_sdk::{Agent, Wait};
use anyhow::Context as _;
use ipc_types::{ActionBlock, MAX_PROXIMITY, RobotRegistration, SENSOR_GPS, SensorSpec};

use crate::NavigatorArgs;
use crate::geom::{Pose, V2};
use crate::map::NavMap;
use crate::navigator::{Body, Checkpoint, NavConfig, NavEvent, Navigator};
use crate::pilot::Pilot;

/// Expansions a tick's search may make when the hub does not wait for the answer (real
/// time): about 25 ms on the reference machine (6 µs an expansion, AMD EPYC), so the answer
/// comes well within the 100 ms cycle on a machine 2-3 times slower. Unbounded, a search
/// took up to 470 ms, and the chair drove on its last command for those four ticks: in
/// `iwsim demo` it came within 5 mm of box B (issue 26).
const REAL_TIME_PLAN_ALLOWANCE: usize = 4000;
use crate::pose::PoseSourceKind;
use crate::sensors::{Input, check_mode, default_layout};

/// Runs the navigator agent until the hub's run ends. Exits with success when the last
/// checkpoint was reached.
pub fn run(args: &NavigatorArgs) -> anyhow::Result<ExitCode> {
    // Refuse what cannot run before touching the hub.
    anyhow::ensure!(args.cruise > 0.0 && args.cruise <= 1.0, "--cruise {} is not in (0, 1]", args.cruise);
    anyhow::ensure!(args.arrive > 0.0, "--arrive {} must be positive", args.arrive);
    let session = &args.common.hub.session;
    let mut agent = args.common.connect("navigator").with_context(|| format!("joining session {session:?}"))?;
    // Close on every path, errors included: the last process of a session removes its files.
    let result = drive(&mut agent, args);
    agent.close();
    result
}

/// The configuration from the options and the hub's map header.
fn config(args: &NavigatorArgs, header: &ipc_types::MapHeader) -> anyhow::Result<NavConfig> {
    let [w, h, com] = args.body;
    let body = Body { width_m: w, height_m: h, com };
    let checkpoints: Vec<Checkpoint> = args.checkpoints.iter().map(Checkpoint::from).collect();
    let first = checkpoints.first().context("at least one --checkpoint is needed")?;
    let start = match args.robot.pose {
        Some(wire) => sim_model::Pose::from_wire_deg(wire).into(),
        None => {
            let toward = checkpoints.get(1).map_or(0.0, |c| {
                let d = c.pos - first.pos;
                d.y.atan2(d.x)
            });
            Pose::new(first.pos.x, first.pos.y, toward)
        }
    };
    let p = &header.params;
    // A hub that does not say gets the thesis's encoders: 1024 ticks a turn of a 0.17 m wheel.
    let ticks_per_m =
        if p.encoder_ticks_per_m > 0.0 { p.encoder_ticks_per_m } else { sim_model::encoder_ticks_per_m(1024.0, 0.17) };
    let defaults = NavConfig::intellwheels();
    Ok(NavConfig {
        body,
        max_speed_mps: args.max_speed,
        accel_curve: args.accel_curve,
        cruise: args.cruise,
        sensors: default_layout(&body.footprint()),
        checkpoints,
        start,
        arrive_m: args.arrive,
        cycle_s: if header.cycle_ms > 0 { header.cycle_ms as f64 / 1000.0 } else { 0.1 },
        proximity_latency: p.latency[0],
        pose_source: args.pose_source,
        encoder_ticks_per_m: ticks_per_m,
        margin_m: defaults.margin_m,
        keep_right: args.keep_right,
        plan_allowance: args.plan_allowance.map(|n| n as usize),
        proximity_noise_m: if p.noise_proximity_m.is_finite() { p.noise_proximity_m.max(0.0) } else { 0.0 },
        wall_fix_gain: args.wall_fix,
    })
}

fn drive(agent: &mut Agent, args: &NavigatorArgs) -> anyhow::Result<ExitCode> {
    let map_data = agent.map()?;
    let map = NavMap::new(&map_data);
    let cfg = config(args, &map_data.header)?;
    let name = &args.robot.name;
    if name.len() > crate::traffic::MAX_NAME_BYTES {
        anyhow::bail!(
            "the chair's name {name:?} is {} bytes; a navigator's is at most {} (it travels in every traffic \
             message the chair says)",
            name.len(),
            crate::traffic::MAX_NAME_BYTES
        );
    }

    let mut reg = RobotRegistration::new(name)
        .id(args.robot.id)
        .body(cfg.body.width_m, cfg.body.height_m, cfg.body.com)
        .motors(cfg.max_speed_mps, cfg.accel_curve)
        .at(Some(sim_model::Pose::from(cfg.start).to_wire_deg()));
    let mut sensors = [SensorSpec { x_m: 0.0, y_m: 0.0, angle_deg: 0.0, cone_deg: 0.0, range_m: 0.0 }; MAX_PROXIMITY];
    for (slot, mount) in sensors.iter_mut().zip(&cfg.sensors) {
        *slot = mount.spec();
    }
    reg.sensors = sensors;
    reg.sensor_count = cfg.sensors.len().min(MAX_PROXIMITY) as u32;
    // Real and augmented modes attach to a physical chair of this name (its adapter registered
    // it), and ask the hub for the mode.
    reg.flags |= args.mode.wire().reg_flags();
    let id = agent.register(&reg).with_context(|| format!("registering {name}"))?;
    agent.ready()?;
    let checkpoints = cfg.checkpoints.clone();
    let cycle_s = cfg.cycle_s;
    agent_sdk::report!(
        "navigator {name}: robot {id} in session {:?} on {:?}, from ({:.2}, {:.2}, {:.0}°) through {} checkpoint(s)",
        args.common.hub.session,
        map.name,
        cfg.start.x,
        cfg.start.y,
        sim_model::wire_deg(cfg.start.theta),
        checkpoints.len()
    );
    let mut logs = RobotLogs::new(args.common.log.as_deref());
    logs.add(id, name);
    let mut pilot = Pilot::new(name, Navigator::new(map, cfg));
    if args.zone_claims {
        pilot = pilot.with_zone_claims();
    }
    let mut contacts = 0u32;
    let mut last_time = 0.0;
    let mut mode_checked = false;
    // Each tick's planning and control time, µs: the navigator's cost, which must not grow
    // when chairs meet (a lock-step run waits for it).
    let mut tick_us = TickTimes::default();
    while let Some(tick) = agent.wait_tick(Wait::Blocking)? {
        let time_s = tick.tick as f64 * cycle_s;
        last_time = time_s;
        // Read where the hub wrote it (the SDK holds the sample), not copied.
        let Some(block) = agent.sensors().iter().find(|b| b.robot_id == id) else {
            agent.send(tick.tick, &[ActionBlock::motors(id, 0.0, 0.0)])?;
            continue;
        };
        if !mode_checked {
            check_mode(args.mode, name, block)?;
            // Checked on the first block, not the map: a physical chair has a fix (its
            // adapter's pose) whatever the hub's GPS setting.
            anyhow::ensure!(
                args.pose_source == PoseSourceKind::Odometry
                    || map_data.header.params.sensors_on & SENSOR_GPS != 0
                    || block.present & ipc_types::HAS_GPS != 0,
                "--pose-source {:?} needs GPS, which this hub's run has off (switch it on in the parameters file)",
                args.pose_source
            );
            mode_checked = true;
        }
        contacts = block.collision_count;
        let allowance =
            args.plan_allowance.map(|n| n as usize).or((!tick.lockstep).then_some(REAL_TIME_PLAN_ALLOWANCE));
        if pilot.navigator().config().plan_allowance != allowance {
            pilot.navigator_mut().set_plan_allowance(allowance);
        }
        let input = Input::from_block(block, time_s);
        let started = std::time::Instant::now();
        let out = pilot.tick(&input, block.messages().map(|(_, m)| m));
        tick_us.add(u32::try_from(started.elapsed().as_micros()).unwrap_or(u32::MAX));
        for e in &out.events {
            report(name, &checkpoints, e);
        }
        for note in &out.notes {
            agent_sdk::report!("navigator {name}: {note}");
        }
        let mut action = ActionBlock::motors(id, out.powers[0], out.powers[1]);
        if let Some(say) = &out.say
            && !action.with_say(say.as_bytes())
        {
            // Cannot happen for names of at most `MAX_NAME_BYTES` and places on a map; say so
            // if it does, since the other chairs would not hear this one.
            agent_sdk::report!("navigator {name}: message of {} bytes too long to say: {say}", say.len());
        }
        agent.send(tick.tick, &[action])?;
        // Logged after the send, so the log never delays the action; the sample is the same.
        if let Some(block) = agent.sensors().iter().find(|b| b.robot_id == id) {
            logs.row(block, time_s, out.powers)?;
        }
    }
    // The run's final readings: the last contacts, and the log's last row.
    if let Some(block) = agent.sensors().iter().find(|b| b.robot_id == id) {
        contacts = block.collision_count;
    }
    logs.finish(agent)?;
    if let Some(cost) = tick_us.cost() {
        agent_sdk::report!("navigator {name}: {cost}");
    }
    let nav = pilot.navigator();
    let stats = nav.stats();
    agent_sdk::report!(
        "navigator {name}: {} searches ({} found nothing), {} nodes expanded, {} safety stops",
        stats.plans,
        stats.failed_plans,
        stats.expansions,
        stats.safety_stops
    );
    let reached = nav.next_checkpoint().min(checkpoints.len());
    if nav.finished() {
        agent_sdk::report!(
            "navigator {name}: the run ended; all {reached} checkpoint(s) reached, {contacts} contact(s)"
        );
        Ok(ExitCode::SUCCESS)
    } else {
        agent_sdk::report!(
            "navigator {name}: the run ended at t {last_time:.1} s with {reached} of {} checkpoint(s) reached, {contacts} contact(s)",
            checkpoints.len()
        );
        Ok(ExitCode::FAILURE)
    }
}

fn report(name: &str, checkpoints: &[Checkpoint], e: &NavEvent) {
    let at = |i: usize| checkpoints.get(i).map_or(V2::default(), |c| c.pos);
    match e {
        NavEvent::Leg { index, route_m } => {
            let p = at(*index);
            match route_m {
                Some(m) => {
                    agent_sdk::report!(
                        "navigator {name}: to checkpoint {} ({:.2}, {:.2}): route {m:.1} m",
                        index + 1,
                        p.x,
                        p.y
                    )
                }
                None => agent_sdk::report!(
                    "navigator {name}: to checkpoint {} ({:.2}, {:.2}): no route on the map as known; trying anyway",
                    index + 1,
                    p.x,
                    p.y
                ),
            }
        }
        NavEvent::Reached { index, checkpoint, time_s, .. } => {
            agent_sdk::report!(
                "navigator {name}: reached checkpoint {} ({:.2}, {:.2}) at t {time_s:.1} s",
                index + 1,
                checkpoint.x,
                checkpoint.y
            );
        }
        NavEvent::Finished { time_s } => agent_sdk::report!("navigator {name}: done at t {time_s:.1} s; holding still"),
        NavEvent::Blocked { index, reason } => {
            agent_sdk::report!("navigator {name}: no way to checkpoint {} just now ({reason}); waiting", index + 1)
        }
    }
}

/// Tick times, µs, in a histogram of fixed size however long the run: exact below 64 µs,
/// eight buckets per doubling above (each within 12.5 % of what it holds).
#[derive(Debug, Clone)]
pub struct TickTimes {
    counts: Vec<u64>,
    max_us: u32,
    ticks: u64,
}

impl Default for TickTimes {
    fn default() -> Self {
        Self { counts: vec![0; TickTimes::BUCKETS], max_us: 0, ticks: 0 }
    }
}

impl TickTimes {
    const BUCKETS: usize = 64 + 26 * 8;

    fn bucket(us: u32) -> usize {
        if us < 64 {
            return us as usize;
        }
        let octave = 31 - us.leading_zeros() as usize; // 6..=31
        let eighth = ((us >> (octave - 3)) & 7) as usize;
        64 + (octave - 6) * 8 + eighth
    }

    /// The least time a bucket holds, µs.
    fn floor(bucket: usize) -> u32 {
        if bucket < 64 {
            return bucket as u32;
        }
        let (octave, eighth) = ((bucket - 64) / 8 + 6, (bucket - 64) % 8);
        ((8 + eighth) as u32) << (octave - 3)
    }

    /// One tick's time.
    pub fn add(&mut self, us: u32) {
        self.counts[Self::bucket(us)] += 1;
        self.max_us = self.max_us.max(us);
        self.ticks += 1;
    }

    /// The percentiles; `None` before the first tick.
    pub fn cost(&self) -> Option<TickCost> {
        if self.ticks == 0 {
            return None;
        }
        let at = |q: f64| {
            let rank = ((self.ticks - 1) as f64 * q).round() as u64;
            let mut seen = 0;
            for (b, &n) in self.counts.iter().enumerate() {
                seen += n;
                if seen > rank {
                    return Self::floor(b).min(self.max_us);
                }
            }
            self.max_us
        };
        Some(TickCost { ticks: self.ticks, p50_us: at(0.5), p99_us: at(0.99), max_us: self.max_us })
    }
}

/// What the navigator's ticks cost: the time of planning and control per tick (wall time of
/// computation alone, no waiting), as percentiles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickCost {
    /// Ticks measured.
    pub ticks: u64,
    /// Median, µs.
    pub p50_us: u32,
    /// 99th percentile, µs.
    pub p99_us: u32,
    /// The slowest tick, µs.
    pub max_us: u32,
}

impl std::fmt::Display for TickCost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "planning and control per tick: p50 {} µs, p99 {} µs (within 12.5 %), max {} µs over {} ticks",
            self.p50_us, self.p99_us, self.max_us, self.ticks
        )
    }
}

#[cfg(test)]
mod tests {
    use super::TickTimes;

    #[test]
    fn tick_cost_percentiles() {
        let mut t = TickTimes::default();
        assert_eq!(t.cost(), None);
        for us in (1..=60).rev() {
            t.add(us);
        }
        let c = t.cost().expect("ticks");
        assert_eq!((c.ticks, c.p50_us, c.p99_us, c.max_us), (60, 31, 59, 60), "exact below 64 µs");
        // Large times land within 12.5 % below what they are.
        let mut t = TickTimes::default();
        for us in [100, 1_000, 123_456, 3_217_239, u32::MAX] {
            let b = TickTimes::bucket(us);
            let f = TickTimes::floor(b);
            assert!(f <= us && f64::from(us - f) <= 0.125 * f64::from(us), "{us} in a bucket from {f}");
            t.add(us);
        }
        let c = t.cost().expect("ticks");
        assert_eq!(c.max_us, u32::MAX);
        assert!(c.to_string().contains("max 4294967295 µs over 5 ticks"), "{c}");
    }
}
