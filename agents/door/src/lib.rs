//! The door agent (thesis §5.3): doors are robots whose agent limits their motion. A normal
//! door turns about its hinge (a 1.0 × 0.1 m leaf with its centre of movement at 0.99 of its
//! length), a sliding door drives along its length, a rotating door spins about its middle.
//!
//! Each door opens when its proximity sensors see something within `trigger_m`, or when a
//! robot within message range says `door open NAME` (or `door open *`) — the thesis's future
//! work, doors that open by communication. It stays open at least `quiet_s` and closes once
//! nothing has been seen for `quiet_s`. On contact it stops, waits `retry_s`, then tries
//! again: an opening door goes on opening, a closing door opens again and closes after the
//! next quiet period. Its angle or travel is read from its own pose, as a door's encoder
//! would. State changes are printed to stderr, one line each.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use agent_sdk::cli::CommonArgs;
use agent_sdk::logs::RobotLogs;
use agent_sdk::odometry::Odometry;
use agent_sdk::{Agent, Wait};
use anyhow::Context as _;
use ipc_types::{ActionBlock, COLLISION, HAS_COMPASS, RobotKind, RobotRegistration, SensorBlock, SensorSpec};
use serde::Deserialize;
use sim_model::{Pose, PoseDeg, wrap_rad};

/// Options of `iwsim agent door`.
#[derive(Debug, clap::Args, Clone)]
#[command(long_about = "Doors as robots (thesis §5.3). Presets: normal (turns about its hinge), sliding \\
(drives along its length), rotating (spins about its middle). A door opens when its proximity sensors \\
see something within --trigger metres, or when a robot says \\\"door open NAME\\\" (or \\\"door open *\\\"); \\
it closes after --quiet seconds with nothing seen, and on contact it stops, waits --retry seconds and \\
tries again. Several doors come from --config FILE with one [[doors]] table each, taking the same \\
keys as the options (name, preset, pose, body, max_speed, open, trigger, quiet, retry).")]
#[command(mut_arg("log", |a| a.help("Write one CSV log per door into this directory").value_name("LOG")))]
#[command(mut_arg("connect_timeout", |a| a.help("Seconds to wait for the hub to come up").value_name("CONNECT_TIMEOUT")))]
pub struct DoorArgs {
    /// `--session`, `--connect-timeout`, `--log` (one CSV log per door).
    #[command(flatten)]
    pub common: CommonArgs,
    /// Doors from a TOML file ([[doors]] tables); the door options below are then ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Name (robots address it in messages).
    #[arg(long, default_value = "door1")]
    pub name: String,
    /// normal, sliding or rotating.
    #[arg(long, default_value = "normal")]
    pub preset: String,
    /// Closed pose X,Y,DIR: the centre of movement (a normal door's hinge) and heading (a
    /// normal door's leaf lies ahead of its hinge).
    #[arg(long, allow_hyphen_values = true)]
    pub pose: Option<String>,
    /// How far it opens: degrees to turn (normal; + is counter-clockwise) or metres to slide
    /// along its heading (sliding; default its length). Ignored by rotating doors.
    #[arg(long, allow_hyphen_values = true)]
    pub open: Option<f64>,
    /// Sensor range: something nearer opens the door, metres.
    #[arg(long, default_value_t = 1.5)]
    pub trigger: f64,
    /// Seconds with nothing seen before it closes.
    #[arg(long, default_value_t = 3.0)]
    pub quiet: f64,
    /// Seconds to wait after a contact before trying again.
    #[arg(long, default_value_t = 2.0)]
    pub retry: f64,
}

/// One door.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DoorConfig {
    /// Name.
    pub name: String,
    /// Preset.
    #[serde(default = "normal")]
    pub preset: Preset,
    /// Closed pose in its wire form: x, y metres, heading degrees (as registered).
    pub pose: PoseDeg,
    /// Length, thickness, centre of movement (default: the preset's).
    #[serde(default)]
    pub body: Option<[f64; 3]>,
    /// Speed at full power, m/s (default: the preset's).
    #[serde(default)]
    pub max_speed: Option<f64>,
    /// Degrees (normal) or metres (sliding) to open.
    #[serde(default)]
    pub open: Option<f64>,
    /// Sensor range, metres.
    #[serde(default = "trigger")]
    pub trigger: f64,
    /// Quiet seconds before closing.
    #[serde(default = "quiet")]
    pub quiet: f64,
    /// Seconds to wait after a contact.
    #[serde(default = "retry")]
    pub retry: f64,
}

fn normal() -> Preset {
    Preset::Normal
}
fn trigger() -> f64 {
    1.5
}
fn quiet() -> f64 {
    3.0
}
fn retry() -> f64 {
    2.0
}

/// The thesis's door presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// A hinged leaf turning about one end.
    Normal,
    /// A leaf driving along its length.
    Sliding,
    /// A leaf spinning about its middle.
    Rotating,
}

impl Preset {
    fn parse(s: &str) -> anyhow::Result<Self> {
        match s {
            "normal" => Ok(Self::Normal),
            "sliding" => Ok(Self::Sliding),
            "rotating" => Ok(Self::Rotating),
            _ => anyhow::bail!("door preset {s:?}: expected normal, sliding or rotating"),
        }
    }

    /// Length, thickness, centre of movement (thesis §5.3 and §7.4).
    fn body(self) -> [f64; 3] {
        match self {
            Self::Normal => [1.0, 0.1, 0.99],
            Self::Sliding | Self::Rotating => [1.0, 0.1, 0.5],
        }
    }
}

/// What a door is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DoorState {
    /// Shut.
    Closed,
    /// Moving to open.
    Opening,
    /// Open since the last time something was seen.
    Open,
    /// Moving to shut.
    Closing,
    /// Stopped after a contact; resumes the previous motion at `until_s`.
    Blocked {
        /// Whether it was opening (else closing).
        opening: bool,
        /// When it tries again.
        until_s: f64,
    },
}

impl DoorState {
    fn label(self) -> &'static str {
        match self {
            Self::Closed => "closed",
            Self::Opening => "opening",
            Self::Open => "open",
            Self::Closing => "closing",
            Self::Blocked { .. } => "blocked",
        }
    }
}

/// Readings kept per sensor for the median that filters the noise.
const HISTORY: usize = 5;
/// How much nearer than its background a reading must be to count as something there, metres.
const MARGIN_M: f64 = 0.4;

/// One door's controller: pure, so it is tested without a hub.
///
/// Its sensors ride on the leaf, so what they see at rest differs shut and open (an open
/// leaf may face a wall half a metre away). Each sensor therefore keeps a background — the
/// farthest median reading since the door last came to rest — and something is seen when the
/// median reading is within the trigger distance and clearly nearer than that background.
#[derive(Debug, Clone)]
pub struct Door {
    /// Its configuration.
    pub cfg: DoorConfig,
    /// Its state.
    pub state: DoorState,
    last_seen_s: f64,
    body: [f64; 3],
    history: Vec<Vec<f64>>,
    background: Vec<f64>,
    /// Whether the background belongs to the open pose (else the shut one).
    background_open: Option<bool>,
}

/// Powers that turn a leaf by `err` radians (counter-clockwise positive), gently near the end.
fn turn_powers(err: f64) -> [f64; 2] {
    let u = (1.5 * err).clamp(-0.5, 0.5);
    let u = if u.abs() < 0.04 { 0.04 * u.signum() } else { u };
    [-u, u]
}

impl Door {
    /// A closed door.
    pub fn new(cfg: DoorConfig) -> Self {
        let body = cfg.body.unwrap_or(cfg.preset.body());
        Self {
            cfg,
            state: DoorState::Closed,
            last_seen_s: f64::NEG_INFINITY,
            body,
            history: Vec::new(),
            background: Vec::new(),
            background_open: None,
        }
    }

    /// Feeds one tick's readings; whether something is there.
    fn observe(&mut self, readings: &[f64]) -> bool {
        let at_rest = match self.state {
            DoorState::Closed => Some(false),
            DoorState::Open => Some(true),
            _ => None,
        };
        if at_rest.is_none() || at_rest != self.background_open || self.history.len() != readings.len() {
            // Moving, or just come to rest: what the sensors saw before is not this pose's.
            self.history = vec![Vec::new(); readings.len()];
            self.background = vec![f64::NEG_INFINITY; readings.len()];
            self.background_open = at_rest;
        }
        let mut seen = false;
        for (k, &d) in readings.iter().enumerate() {
            let h = &mut self.history[k];
            if h.len() == HISTORY {
                h.remove(0);
            }
            h.push(if d.is_finite() { d } else { f64::INFINITY });
            let mut sorted = h.clone();
            sorted.sort_by(f64::total_cmp);
            let median = sorted[sorted.len() / 2];
            let near = median < self.cfg.trigger && median < self.background[k] - MARGIN_M;
            if near {
                seen = true;
            } else if h.len() >= 3 {
                self.background[k] = self.background[k].max(median);
            }
        }
        // While moving the leaf's view sweeps; only its own motion is judged then (contact).
        seen && at_rest.is_some()
    }

    /// Its registration: body, slow motors, and two sensors on each face looking out.
    pub fn registration(&self) -> RobotRegistration {
        let [w, h, com] = self.body;
        let mut reg = RobotRegistration::new(&self.cfg.name)
            .body(w, h, com)
            .motors(self.cfg.max_speed.unwrap_or(0.1), 0.5)
            .at(Some(self.cfg.pose));
        reg.kind = RobotKind::Door as u32;
        // Along the leaf at a quarter and three quarters of its length, on both faces; narrow
        // cones so an open door does not keep seeing its own frame.
        // The leaf runs from (1 − COM)·W behind its centre of movement to COM·W ahead of it
        // (thesis Table 4.1), so a normal door's leaf lies ahead of its hinge.
        let rear = -(1.0 - com) * w;
        let mut k = 0;
        for along in [0.25, 0.75] {
            let x = rear + along * w;
            for side in [1.0, -1.0] {
                reg.sensors[k] = SensorSpec {
                    x_m: x,
                    y_m: side * h / 2.0,
                    angle_deg: side * 90.0,
                    cone_deg: 30.0,
                    // Readings are noisy: a range well past the trigger distance keeps an empty
                    // view (reported at the range) from dipping under it.
                    range_m: self.cfg.trigger * 1.5,
                };
                k += 1;
            }
        }
        reg.sensor_count = k as u32;
        reg
    }

    fn open_amount(&self) -> f64 {
        match self.cfg.preset {
            Preset::Normal => self.cfg.open.unwrap_or(90.0).to_radians(),
            Preset::Sliding => self.cfg.open.unwrap_or(self.body[0]),
            Preset::Rotating => 0.0,
        }
    }

    /// How far from closed (radians or metres, signed like `open`).
    fn progress(&self, pose: Pose) -> f64 {
        let shut = Pose::from_wire_deg(self.cfg.pose);
        let h0 = shut.heading_rad;
        match self.cfg.preset {
            Preset::Normal | Preset::Rotating => wrap_rad(pose.heading_rad - h0),
            Preset::Sliding => (pose.x_m - shut.x_m) * h0.cos() + (pose.y_m - shut.y_m) * h0.sin(),
        }
    }

    /// Powers that move the door toward `target` progress; `None` once there.
    fn drive_to(&self, pose: Pose, target: f64) -> Option<[f64; 2]> {
        let err = target - self.progress(pose);
        match self.cfg.preset {
            Preset::Normal => (err.abs() > 1f64.to_radians()).then(|| turn_powers(wrap_rad(err))),
            Preset::Sliding => (err.abs() > 0.01).then(|| {
                let u = (3.0 * err).clamp(-0.6, 0.6);
                let u = if u.abs() < 0.05 { 0.05 * u.signum() } else { u };
                [u, u]
            }),
            Preset::Rotating => None,
        }
    }

    /// Powers that hold the door at `target` progress while it rests: nothing while it is
    /// within twice the tolerance it stops at (so it does not hunt on its compass's noise),
    /// back to the target once its estimate, which keeps converging on the compass at rest,
    /// says it has drifted further — as a door closer does.
    fn hold(&self, pose: Pose, target: f64) -> [f64; 2] {
        let slack = match self.cfg.preset {
            Preset::Normal => 2f64.to_radians(),
            Preset::Sliding => 0.02,
            Preset::Rotating => return [0.0, 0.0],
        };
        if (target - self.progress(pose)).abs() > slack {
            self.drive_to(pose, target).unwrap_or([0.0, 0.0])
        } else {
            [0.0, 0.0]
        }
    }

    /// One tick: what the sensors see, whether it is touching something, whether a robot asked
    /// it to open. Returns the powers and, when the state changed, the new state.
    ///
    /// `pose` is where the door thinks its leaf is, from its own encoders and compass (see
    /// [`serve`]): an agent never gets its robot's true pose.
    pub fn step(&mut self, b: &SensorBlock, pose: Pose, now_s: f64, asked: bool) -> ([f64; 2], Option<DoorState>) {
        let readings = &b.proximity_m[..(b.proximity_count as usize).min(b.proximity_m.len())];
        let seen = self.observe(readings) || asked;
        if seen {
            self.last_seen_s = now_s;
        }
        let contact = b.present & COLLISION != 0;
        let before = self.state;
        let spin = [-0.3, 0.3];
        let powers = match self.state {
            DoorState::Closed => {
                if seen {
                    self.state = DoorState::Opening;
                    [0.0, 0.0]
                } else {
                    self.hold(pose, 0.0)
                }
            }
            DoorState::Opening | DoorState::Closing if contact => {
                self.state =
                    DoorState::Blocked { opening: self.state == DoorState::Opening, until_s: now_s + self.cfg.retry };
                [0.0, 0.0]
            }
            DoorState::Opening => match self.cfg.preset {
                Preset::Rotating => {
                    if now_s - self.last_seen_s >= self.cfg.quiet {
                        self.state = DoorState::Closing;
                    }
                    spin
                }
                _ => match self.drive_to(pose, self.open_amount()) {
                    Some(p) => p,
                    None => {
                        // Open for at least the quiet period, whoever is still on the way.
                        self.state = DoorState::Open;
                        self.last_seen_s = now_s;
                        [0.0, 0.0]
                    }
                },
            },
            DoorState::Open => {
                if now_s - self.last_seen_s >= self.cfg.quiet {
                    self.state = DoorState::Closing;
                    [0.0, 0.0]
                } else {
                    self.hold(pose, self.open_amount())
                }
            }
            DoorState::Closing => {
                if asked {
                    self.state = DoorState::Opening;
                    [0.0, 0.0]
                } else if self.cfg.preset == Preset::Rotating {
                    // A revolving leaf stops square with its frame, either way round.
                    let p = self.progress(pose);
                    let to_square = wrap_rad(2.0 * p) / 2.0;
                    if to_square.abs() < 1f64.to_radians() {
                        self.state = DoorState::Closed;
                        [0.0, 0.0]
                    } else {
                        spin
                    }
                } else {
                    match self.drive_to(pose, 0.0) {
                        Some(p) => p,
                        None => {
                            self.state = DoorState::Closed;
                            [0.0, 0.0]
                        }
                    }
                }
            }
            DoorState::Blocked { until_s, .. } => {
                // After a pause it tries again: an opening door goes on opening; a closing door
                // opens again (whatever it hit is in the doorway) and closes after the quiet
                // period, as automatic doors do.
                if now_s >= until_s {
                    self.state = DoorState::Opening;
                }
                [0.0, 0.0]
            }
        };
        (powers, (self.state != before).then_some(self.state))
    }
}

/// Whether a message asks door `name` to open.
pub fn asks_to_open(message: &[u8], name: &str) -> bool {
    let text = String::from_utf8_lossy(message);
    let mut words = text.split_whitespace();
    matches!((words.next(), words.next(), words.next()), (Some("door"), Some("open"), Some(n)) if n == name || n == "*")
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    doors: Vec<DoorConfig>,
}

fn doors_from(args: &DoorArgs) -> anyhow::Result<Vec<DoorConfig>> {
    if let Some(path) = &args.config {
        let text = agent_sdk::files::read_text(path).with_context(|| format!("reading {}", path.display()))?;
        let cfg: ConfigFile = toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        anyhow::ensure!(!cfg.doors.is_empty(), "{}: no [[doors]]", path.display());
        return Ok(cfg.doors);
    }
    let pose = args.pose.as_deref().context("--pose X,Y,DIR is needed (or --config)")?;
    let pose = agent_sdk::args::pose(pose).map_err(|e| anyhow::anyhow!("--pose {e}"))?;
    Ok(vec![DoorConfig {
        name: args.name.clone(),
        preset: Preset::parse(&args.preset)?,
        pose,
        body: None,
        max_speed: None,
        open: args.open,
        trigger: args.trigger,
        quiet: args.quiet,
        retry: args.retry,
    }])
}

/// `iwsim agent door`.
pub fn run(args: &DoorArgs) -> anyhow::Result<ExitCode> {
    let doors: Vec<Door> = doors_from(args)?.into_iter().map(Door::new).collect();
    let mut agent = args.common.connect("door")?;
    let result = serve(&mut agent, doors, args.common.log.as_deref());
    agent.close();
    result
}

/// Serves the doors. Each knows where its leaf is by dead reckoning on its own encoders from
/// the pose it was registered at, its heading held by its compass (when the run has one).
fn serve(agent: &mut Agent, mut doors: Vec<Door>, log: Option<&Path>) -> anyhow::Result<ExitCode> {
    let mut ids = Vec::new();
    for d in &doors {
        ids.push(agent.register(&d.registration()).with_context(|| format!("registering {}", d.cfg.name))?);
    }
    let ticks_per_m = agent.map()?.header.params.encoder_ticks_per_m;
    let mut odometry: Vec<Odometry> =
        doors.iter().map(|d| Odometry::new(Pose::from_wire_deg(d.cfg.pose), ticks_per_m, d.body[1])).collect();
    agent.ready()?;
    let mut logs = RobotLogs::new(log);
    for (d, &id) in doors.iter().zip(&ids) {
        logs.add(id, &d.cfg.name);
    }
    let mut actions = Vec::with_capacity(doors.len());
    while let Some(tick) = agent.wait_tick(Wait::Blocking)? {
        actions.clear();
        for ((door, odo), &id) in doors.iter_mut().zip(&mut odometry).zip(&ids) {
            let Some(b) = agent.sensors().iter().find(|b| b.robot_id == id) else { continue };
            let compass = (b.present & HAS_COMPASS != 0).then_some(b.compass_deg);
            let p = odo.update(b.encoder_ticks, compass);
            let asked = b.messages().any(|(_, m)| asks_to_open(m, &door.cfg.name));
            // The leaf's heading rounded through degrees, the unit its closed pose is written
            // in, as the door has always judged it: recorded door runs reproduce bit for bit.
            let estimate = Pose::from_deg(p.x_m, p.y_m, p.heading_deg());
            let (powers, changed) = door.step(b, estimate, tick.sim_time_s, asked);
            if let Some(s) = changed {
                agent_sdk::report!("door {}: {} at t {:.1} s", door.cfg.name, s.label(), tick.sim_time_s);
            }
            logs.row(b, tick.sim_time_s, powers)?;
            actions.push(ActionBlock::motors(id, powers[0], powers[1]));
        }
        agent.send(tick.tick, &actions)?;
    }
    logs.finish(agent)?;
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;
    use ipc_types::MAX_PROXIMITY;

    fn block(near: Option<f64>, contact: bool) -> SensorBlock {
        let mut b = SensorBlock::zeroed();
        b.proximity_count = 4;
        b.proximity_m = [3.0; MAX_PROXIMITY];
        if let Some(d) = near {
            b.proximity_m[1] = d;
        }
        if contact {
            b.present |= COLLISION;
        }
        b
    }

    fn door(preset: Preset) -> Door {
        Door::new(DoorConfig {
            name: "d".into(),
            preset,
            pose: [0.0, 0.0, 0.0],
            body: None,
            max_speed: None,
            open: None,
            trigger: 1.5,
            quiet: 3.0,
            retry: 2.0,
        })
    }

    /// Steps the door `n` ticks of 0.1 s from `t`; returns the last powers and every change.
    fn run(d: &mut Door, t: &mut f64, n: usize, pose: Pose, near: Option<f64>) -> ([f64; 2], Vec<DoorState>) {
        let mut changes = Vec::new();
        let mut last = [0.0; 2];
        for _ in 0..n {
            let (p, c) = d.step(&block(near, false), pose, *t, false);
            last = p;
            changes.extend(c);
            *t += 0.1;
        }
        (last, changes)
    }

    #[test]
    fn a_normal_door_opens_when_something_comes_and_closes_after_the_quiet_period() {
        let mut d = door(Preset::Normal);
        let mut t = 0.0;
        assert_eq!(run(&mut d, &mut t, 10, Pose::from_deg(0.0, 0.0, 0.0), None), ([0.0, 0.0], vec![]));
        // Something at 1.0 m: seen once the median has it (the third tick).
        let (_, c) = run(&mut d, &mut t, 3, Pose::from_deg(0.0, 0.0, 0.0), Some(1.0));
        assert_eq!(c, vec![DoorState::Opening]);
        // Opening turns it counter-clockwise: right wheel forward.
        let (p, _) = run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 10.0), Some(1.0));
        assert!(p[1] > 0.0 && p[0] < 0.0, "{p:?}");
        assert_eq!(run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 89.5), Some(1.0)).1, vec![DoorState::Open]);
        let opened = t;
        // Open: the view differs (a wall at 0.6 m), which is its new background, not a
        // visitor; it stays open 3 s, then closes.
        let (_, c) = run(&mut d, &mut t, 29, Pose::from_deg(0.0, 0.0, 89.5), Some(0.6));
        assert_eq!(c, vec![]);
        let (_, c) = run(&mut d, &mut t, 2, Pose::from_deg(0.0, 0.0, 89.5), Some(0.6));
        assert_eq!(c, vec![DoorState::Closing], "at {t} s, opened at {opened} s");
        let (p, _) = run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 60.0), None);
        assert!(p[1] < 0.0 && p[0] > 0.0, "closing turns back: {p:?}");
        assert_eq!(run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 0.5), None).1, vec![DoorState::Closed]);
    }

    #[test]
    fn an_open_door_stays_open_while_someone_passes() {
        let mut d = door(Preset::Normal);
        let mut t = 0.0;
        run(&mut d, &mut t, 5, Pose::from_deg(0.0, 0.0, 0.0), None);
        d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 0.0), t, true);
        run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 90.0), None);
        assert_eq!(d.state, DoorState::Open);
        run(&mut d, &mut t, 20, Pose::from_deg(0.0, 0.0, 90.0), Some(1.4));
        // A chair in the doorway, 0.3 m from the leaf, for 5 s: no closing meanwhile.
        let (_, c) = run(&mut d, &mut t, 50, Pose::from_deg(0.0, 0.0, 90.0), Some(0.3));
        assert_eq!(c, vec![]);
        let (_, c) = run(&mut d, &mut t, 28, Pose::from_deg(0.0, 0.0, 90.0), Some(1.4));
        assert_eq!(c, vec![], "3 s from the last sighting, not from when it left the median");
        let (_, c) = run(&mut d, &mut t, 5, Pose::from_deg(0.0, 0.0, 90.0), Some(1.4));
        assert_eq!(c, vec![DoorState::Closing]);
    }

    #[test]
    fn contact_stops_the_door_and_it_retries() {
        let mut d = door(Preset::Normal);
        d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 0.0), 0.0, true);
        let (p, s) = d.step(&block(Some(1.0), true), Pose::from_deg(0.0, 0.0, 30.0), 1.0, false);
        assert_eq!((p, s), ([0.0, 0.0], Some(DoorState::Blocked { opening: true, until_s: 3.0 })));
        assert_eq!(d.step(&block(Some(1.0), false), Pose::from_deg(0.0, 0.0, 30.0), 2.9, false).1, None);
        assert_eq!(
            d.step(&block(Some(1.0), false), Pose::from_deg(0.0, 0.0, 30.0), 3.0, false).1,
            Some(DoorState::Opening)
        );
        // Closing into something: stop, wait, open again.
        d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 90.0), 3.1, false);
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 90.0), 6.2, false).1, Some(DoorState::Closing));
        let (p, s) = d.step(&block(None, true), Pose::from_deg(0.0, 0.0, 70.0), 6.3, false);
        assert_eq!((p, s), ([0.0, 0.0], Some(DoorState::Blocked { opening: false, until_s: 8.3 })));
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 70.0), 8.3, false).1, Some(DoorState::Opening));
    }

    #[test]
    fn messages_open_a_sliding_door_and_reopen_it_while_it_closes() {
        let mut d = door(Preset::Sliding);
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.0, 0.0, 0.0), 0.0, true).1, Some(DoorState::Opening));
        let (p, _) = d.step(&block(None, false), Pose::from_deg(0.3, 0.0, 0.0), 0.1, false);
        assert!(p[0] > 0.0 && p[0] == p[1], "slides forward: {p:?}");
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.995, 0.0, 0.0), 1.0, false).1, Some(DoorState::Open));
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.995, 0.0, 0.0), 3.9, false).1, None);
        assert_eq!(
            d.step(&block(None, false), Pose::from_deg(0.995, 0.0, 0.0), 4.0, false).1,
            Some(DoorState::Closing)
        );
        let (p, _) = d.step(&block(None, false), Pose::from_deg(0.8, 0.0, 0.0), 4.1, false);
        assert!(p[0] < 0.0, "slides back: {p:?}");
        assert_eq!(d.step(&block(None, false), Pose::from_deg(0.8, 0.0, 0.0), 4.2, true).1, Some(DoorState::Opening));
        assert!(asks_to_open(b"door open d", "d") && asks_to_open(b"door open *", "d"));
        assert!(!asks_to_open(b"door open e", "d") && !asks_to_open(b"doors open d", "d") && !asks_to_open(b"", "d"));
    }

    #[test]
    fn a_rotating_door_spins_after_a_sighting_and_stops_square() {
        let mut d = door(Preset::Rotating);
        let mut t = 0.0;
        run(&mut d, &mut t, 5, Pose::from_deg(0.0, 0.0, 0.0), None);
        assert_eq!(run(&mut d, &mut t, 3, Pose::from_deg(0.0, 0.0, 0.0), Some(1.0)).1, vec![DoorState::Opening]);
        let (p, _) = run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 40.0), Some(1.0));
        assert!(p[1] > 0.0);
        let (_, c) = run(&mut d, &mut t, 30, Pose::from_deg(0.0, 0.0, 100.0), None);
        assert_eq!(c, vec![DoorState::Closing]);
        assert_eq!(run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 150.0), None).1, vec![]);
        assert_eq!(run(&mut d, &mut t, 1, Pose::from_deg(0.0, 0.0, 179.5), None).1, vec![DoorState::Closed]);
    }

    #[test]
    fn a_half_turned_leaf_reads_plus_180_degrees_as_everywhere_else() {
        // The project's one angle convention, (−180°, 180°]: a leaf turned half a turn either
        // way is +π from closed, never −π.
        let d = door(Preset::Normal);
        for heading in [180.0, -180.0, 540.0] {
            assert_eq!(d.progress(Pose::from_deg(0.0, 0.0, heading)), std::f64::consts::PI, "{heading}°");
        }
        assert_eq!(d.progress(Pose::from_deg(0.0, 0.0, -90.0)), -std::f64::consts::FRAC_PI_2);
    }

    #[test]
    fn the_door_registers_as_a_door_with_outward_sensors() {
        let r = door(Preset::Normal).registration();
        assert_eq!((r.kind, r.width_m, r.height_m, r.com, r.sensor_count), (RobotKind::Door as u32, 1.0, 0.1, 0.99, 4));
        assert!(r.sensors[..4].iter().all(|s| s.angle_deg.abs() == 90.0 && s.range_m == 2.25));
        // On the leaf, which lies ahead of the hinge.
        assert!(r.sensors[..4].iter().all(|s| s.x_m > 0.0 && s.x_m < 0.99));
    }
}
