//! Scenarios: one TOML file says what a run is — the map, the obstacles and checkpoints, the
//! agents to start and what must come out. `iwsim run` reads them; the thesis's experiments
//! are built in (`builtin:NAME`).
//!
//! ```toml
//! name = "slalom"
//! lab = "builtin:liacc"          # or a lab file, relative to this file
//! seconds = 90                   # simulated time limit
//! cycle_ms = 100                 # tick (default 100)
//! deadline_ms = 5000             # lock-step: how long a tick waits for its agents (default 5000)
//! noise = true                   # Ciber-Rato's sensor and motor noise, 2 % wheel slip (default true)
//!
//! [[checkpoints]]                # numbered from 1 in file order
//! x = 10.0
//! y = 6.1
//! radius = 0.5                   # default 0.5 m
//!
//! [[obstacles]]                  # static boxes, sensed and collided with like walls
//! name = "A"
//! x0 = 17.0
//! y0 = 6.1
//! x1 = 17.6
//! y1 = 6.4
//! height = 1.0                   # default 1.0 m
//!
//! [[agents]]                     # each one an `iwsim agent KIND` process
//! kind = "navigator"
//! options = { name = "chair1", pose = [10.0, 6.1, 0.0], checkpoint = [[10.0, 6.1], [20.0, 6.1]] }
//! # `config` (a table) is written to a file and passed as `--config FILE`.
//! # kind = "ros2" runs `iwsim ros2` with the options, e.g. { chair = ["chair1=10,6.1,0"] }:
//! # the chairs it serves are driven by a ROS 2 stack the user starts.
//!
//! [routes]                       # checkpoints each robot must reach, in order
//! chair1 = [1, 2]
//!
//! [expect]
//! max_collisions = 0             # for every robot
//! [expect.robots.chair1]
//! route = true                   # reaches every checkpoint of its route
//! top_speed_mps = [0.4851, 0.4949]
//!
//! [chair]                        # optional: a physical chair (the emulator) in mixed reality
//! robot = "chair1"               # the robot an agent drives (its agent has name = "chair1")
//! mode = "augmented"             # the adapter's sensor mode: virtual, real or augmented
//! pose = [10.0, 6.1, 0.0]        # where it starts, in both worlds
//! # lab = "builtin:liacc"        # the emulator's room (default: the scenario's lab)
//! # stepped = true               # the adapter steps the emulator's clock (default: with --lockstep)
//! # localise = false             # push raw odometry, no map matching (default: true)
//! [[chair.room]]                 # furniture only the emulator's room has
//! name = "C"
//! x0 = 14.0
//! y0 = 6.1
//! x1 = 14.6
//! y1 = 6.4
//! dark = false                   # a dark surface the IR beams do not see (default false)
//! ```
//!
//! Options become command-line flags: `key = value` gives `--key value`, `true` gives `--key`,
//! an array of numbers `--key a,b,c`, and an array of arrays or strings one flag per element.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use places::{Checkpoint, Obstacle, RoomBox};
use serde::Deserialize;
use sim_model::PoseDeg;

/// The lock-step deadline of a scenario that sets none: long enough for any agent of ours on a
/// loaded machine, short enough that a hung one holds the run only seconds.
pub const DEFAULT_DEADLINE_MS: u64 = 5000;

/// The built-in scenarios, by name.
pub const BUILTINS: &[(&str, &str)] = &[
    ("dynamics", include_str!("../scenarios/dynamics.toml")),
    ("slalom", include_str!("../scenarios/slalom.toml")),
    ("door", include_str!("../scenarios/door.toml")),
    ("corridor-swap", include_str!("../scenarios/corridor-swap.toml")),
    ("demo", include_str!("../scenarios/demo.toml")),
    ("slalom-real", include_str!("../scenarios/slalom-real.toml")),
    ("slalom-augmented", include_str!("../scenarios/slalom-augmented.toml")),
    ("ward", include_str!("../scenarios/ward.toml")),
];

/// A scenario file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name, for summaries.
    pub name: String,
    /// One line about it.
    #[serde(default)]
    pub description: String,
    /// Lab: `builtin:NAME` or a file (relative to the scenario file).
    #[serde(default = "default_lab")]
    pub lab: String,
    /// Grid file, if not the built-in lab's own.
    #[serde(default)]
    pub grid: Option<String>,
    /// Tick, milliseconds.
    #[serde(default = "default_cycle")]
    pub cycle_ms: u32,
    /// Lock-step: how long (wall-clock ms) the hub waits for a tick's answers before it steps
    /// without the late agents. A stack that thinks long (a ROS 2 planner) needs more than the
    /// default ([`DEFAULT_DEADLINE_MS`]; [`Scenario::deadline_ms`]); a deadline that is met
    /// changes nothing in the run.
    #[serde(default)]
    pub deadline_ms: Option<u64>,
    /// Simulated time limit, seconds.
    pub seconds: f64,
    /// Noise on (true: `world::map::NoiseParams::WHEELCHAIR`, Ciber-Rato's sensor and motor
    /// noise with a real chair's encoder slip, the hub's default) or every noise off.
    #[serde(default = "yes")]
    pub noise: bool,
    /// Seed, unless the command line gives one.
    #[serde(default = "one")]
    pub seed: u64,
    /// Checkpoints, numbered from 1 (checked as they are read).
    #[serde(default)]
    pub checkpoints: Vec<Checkpoint>,
    /// Static obstacles (checked as they are read; whether they fit the lab, the hub checks).
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// Agent processes (a `[crowd]` adds its chairs' navigators to these).
    #[serde(default)]
    pub agents: Vec<AgentSpec>,
    /// Checkpoint numbers each robot must reach, in order.
    #[serde(default)]
    pub routes: BTreeMap<String, Vec<usize>>,
    /// What must hold at the end (`max_collisions` holds in the chair's room too).
    #[serde(default)]
    pub expect: Expect,
    /// A physical chair (the chair emulator, through the serial adapter) in the run.
    #[serde(default)]
    pub chair: Option<ChairSpec>,
    /// Many navigator chairs placed by the run's seed, each with its goals ([`crate::crowd`]).
    #[serde(default)]
    pub crowd: Option<crate::crowd::Crowd>,
    /// The directory relative paths are read from (not in the file).
    #[serde(skip)]
    pub base: PathBuf,
}

fn default_lab() -> String {
    "builtin:liacc".into()
}
fn default_cycle() -> u32 {
    100
}
fn yes() -> bool {
    true
}
fn one() -> u64 {
    1
}
/// A scenario as a learning environment runs it ([`Scenario::describe`]), as JSON.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Description {
    /// The lab as the hub takes it (`builtin:NAME` or a path).
    pub lab: String,
    /// The grid, likewise, if the scenario names one.
    pub grid: Option<String>,
    /// Checkpoints: x, y, radius, metres.
    pub checkpoints: Vec<[f64; 3]>,
    /// Obstacles: x0, y0, x1, y1, metres.
    pub obstacles: Vec<[f64; 4]>,
    /// The agents' start poses (`options.pose`): x, y metres, heading degrees.
    pub starts: Vec<PoseDeg>,
    /// Simulated time limit, seconds.
    pub seconds: f64,
    /// Tick, ms.
    pub cycle_ms: u32,
    /// Noise on.
    pub noise: bool,
    /// The file's lock-step deadline, ms, if it sets one.
    pub deadline_ms: Option<u64>,
}

/// One agent process.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentSpec {
    /// `iwsim agent KIND`.
    pub kind: String,
    /// Command-line options.
    #[serde(default)]
    pub options: toml::Table,
    /// A configuration passed as `--config FILE`.
    #[serde(default)]
    pub config: Option<toml::Table>,
}

/// Where a chair's agent gets its proximity readings: the adapter's `--mode` and the
/// navigator's `--sensors`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ChairMode {
    /// The simulator's readings on the chair's virtual twin.
    Virtual,
    /// The chair's own sensors only.
    Real,
    /// Per sensor, the nearer of real and virtual (thesis 5.4.3).
    Augmented,
}

impl ChairMode {
    /// The word the command lines and scenario files use.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Virtual => "virtual",
            Self::Real => "real",
            Self::Augmented => "augmented",
        }
    }
}

/// The physical chair of a mixed-reality run: the chair emulator plays it in a room of its
/// own, and the serial adapter registers it in the hub as the Real robot `robot`, which the
/// agent of that name then drives.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChairSpec {
    /// The robot's name, in the hub and for the agent that drives it.
    pub robot: String,
    /// The adapter's sensor mode.
    pub mode: ChairMode,
    /// The start pose in both worlds: x, y metres, heading degrees.
    pub pose: PoseDeg,
    /// The emulator's room: `builtin:NAME` or a lab file (relative to the scenario file);
    /// default the scenario's lab.
    #[serde(default)]
    pub lab: Option<String>,
    /// Whether the adapter steps the emulator's clock once per tick (default: when the run is
    /// lock-step).
    #[serde(default)]
    pub stepped: Option<bool>,
    /// Furniture only the emulator's room has.
    #[serde(default)]
    pub room: Vec<RoomBox>,
    /// Whether the adapter map-matches the chair's odometry to the walls its real sensors see
    /// (default true); false pushes raw odometry (`iwsim serial --odometry-only`).
    #[serde(default = "yes")]
    pub localise: bool,
}

/// What must hold at the end of a run.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expect {
    /// Contacts allowed per robot.
    #[serde(default)]
    pub max_collisions: Option<u64>,
    /// Per-robot expectations.
    #[serde(default)]
    pub robots: BTreeMap<String, RobotExpect>,
}

/// What must hold for one robot.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotExpect {
    /// Reaches every checkpoint of its route.
    #[serde(default)]
    pub route: bool,
    /// Top speed within [min, max], m/s.
    #[serde(default)]
    pub top_speed_mps: Option<[f64; 2]>,
    /// 10–90 % rise time within [min, max], s.
    #[serde(default)]
    pub rise_time_s: Option<[f64; 2]>,
    /// Final heading within [min, max], degrees.
    #[serde(default)]
    pub final_heading_deg: Option<[f64; 2]>,
    /// Final x within [min, max], metres.
    #[serde(default)]
    pub final_x_m: Option<[f64; 2]>,
}

/// The longest simulated run a scenario may ask for, seconds (a week): long enough for any
/// experiment, short enough that the tick count is exact and the run ends.
pub const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// No such built-in.
    #[error("no built-in scenario {name:?}; built in: {known}")]
    UnknownBuiltin {
        /// Asked for.
        name: String,
        /// Known names.
        known: String,
    },
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is too large or not UTF-8 text.
    #[error("{path}: {source}")]
    NotText {
        /// File.
        path: String,
        /// Why.
        source: places::files::TextReadError,
    },
    /// Bad TOML, or a field of the wrong type (the message carries line and column).
    #[error("{path}: {message}")]
    Toml {
        /// File.
        path: String,
        /// What the parser said.
        message: String,
    },
    /// The scenario is well-formed but does not make sense.
    #[error("{path}: {message}")]
    Invalid {
        /// File.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl Scenario {
    /// Loads `builtin:NAME` or a file.
    pub fn load(spec: &str) -> Result<Self, ScenarioError> {
        match spec.strip_prefix("builtin:") {
            Some(name) => {
                let text = BUILTINS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t).ok_or_else(|| {
                    ScenarioError::UnknownBuiltin {
                        name: name.into(),
                        known: BUILTINS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "),
                    }
                })?;
                Self::parse(text, spec, Path::new("."))
            }
            None => {
                let text = places::files::read_text(Path::new(spec)).map_err(|err| match err {
                    places::files::TextReadError::Io(source) => ScenarioError::Io { path: spec.into(), source },
                    source => ScenarioError::NotText { path: spec.into(), source },
                })?;
                let base = Path::new(spec).parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
                Self::parse(&text, spec, &base)
            }
        }
    }

    /// Parses and checks scenario text; `path` names it in errors.
    pub fn parse(text: &str, path: &str, base: &Path) -> Result<Self, ScenarioError> {
        let mut s: Scenario = toml::from_str(text)
            .map_err(|e| ScenarioError::Toml { path: path.into(), message: e.to_string().trim_end().to_owned() })?;
        s.base = base.to_path_buf();
        let bad = |message: String| ScenarioError::Invalid { path: path.into(), message };
        if !(s.seconds > 0.0 && s.seconds <= MAX_SECONDS) {
            return Err(bad(format!(
                "seconds = {}: must be more than 0 and at most {MAX_SECONDS} (a week)",
                s.seconds
            )));
        }
        if s.cycle_ms == 0 {
            return Err(bad("cycle_ms must be at least 1".into()));
        }
        if let Some(ms) = s.deadline_ms
            && !(1..=hub::cli::MAX_DEADLINE_MS).contains(&ms)
        {
            return Err(bad(format!("deadline_ms = {ms}: must be 1..={} (a day)", hub::cli::MAX_DEADLINE_MS)));
        }
        if s.agents.is_empty() && s.crowd.is_none() {
            return Err(bad("no [[agents]] and no [crowd]: a run needs at least one agent".into()));
        }
        if let Some(crowd) = &s.crowd {
            crowd.check().map_err(bad)?;
        }
        for (robot, route) in &s.routes {
            if let Some(n) = route.iter().find(|&&n| n == 0 || n > s.checkpoints.len()) {
                return Err(bad(format!(
                    "route of {robot}: checkpoint {n} does not exist (there are {})",
                    s.checkpoints.len()
                )));
            }
        }
        for robot in s.expect.robots.keys() {
            if s.expect.robots[robot].route && !s.routes.contains_key(robot) {
                return Err(bad(format!("expect.robots.{robot}.route: {robot} has no entry in [routes]")));
            }
        }
        for a in &s.agents {
            if !["navigator", "wheelchair", "door", "teleop", "ros2"].contains(&a.kind.as_str()) {
                return Err(bad(format!(
                    "agent kind {:?}: expected navigator, wheelchair, door, teleop or ros2",
                    a.kind
                )));
            }
            if a.kind == "ros2" && a.config.is_some() {
                return Err(bad("agent kind \"ros2\" takes options, not a config table".into()));
            }
        }
        if let Some(chair) = &s.chair {
            if chair.robot.is_empty() {
                return Err(bad("chair.robot: a robot name is needed".into()));
            }
            if !chair.pose.iter().all(|v| v.is_finite()) {
                return Err(bad(format!("chair.pose = {:?}: want three finite numbers [x, y, degrees]", chair.pose)));
            }
            if s.agent_of(&chair.robot).is_none() {
                return Err(bad(format!(
                    "chair.robot = {:?}: no [[agents]] has name = {:?} to drive it",
                    chair.robot, chair.robot
                )));
            }
        }
        Ok(s)
    }

    /// The index of the agent whose robot is `name` (its `name` option).
    pub fn agent_of(&self, name: &str) -> Option<usize> {
        self.agents.iter().position(|a| a.options.get("name").and_then(toml::Value::as_str) == Some(name))
    }

    /// Runs the chair in `mode` instead of the scenario's: the adapter's mode and, if the
    /// chair's agent chooses its sensors (`sensors` or its alias `mode`), that choice too.
    pub fn set_chair_mode(&mut self, mode: ChairMode) -> Result<(), String> {
        let Some(chair) = &mut self.chair else {
            return Err(format!("scenario {} has no [chair] whose mode could be set", self.name));
        };
        chair.mode = mode;
        let robot = chair.robot.clone();
        if let Some(k) = self.agent_of(&robot) {
            for key in ["sensors", "mode"] {
                if let Some(v) = self.agents[k].options.get_mut(key) {
                    *v = toml::Value::String(mode.as_str().into());
                }
            }
        }
        Ok(())
    }

    /// The chair emulator's room as it takes it (`builtin:NAME`, or a path made relative to
    /// the file); `None` without a chair.
    pub fn chair_lab_spec(&self) -> Option<String> {
        self.chair.as_ref().map(|c| self.resolve(c.lab.as_deref().unwrap_or(&self.lab)))
    }

    /// The lock-step deadline, ms: the file's, else [`DEFAULT_DEADLINE_MS`].
    pub fn deadline_ms(&self) -> u64 {
        self.deadline_ms.unwrap_or(DEFAULT_DEADLINE_MS)
    }

    /// What a learning environment runs of it (`iwsim run SCENARIO --describe`): the Python
    /// package reads scenario files through this, so there is one reader, with its checks and
    /// its errors.
    pub fn describe(&self) -> Description {
        let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
        Description {
            lab: self.lab_spec(),
            grid: self.grid_spec(),
            checkpoints: self.checkpoints.iter().map(|c| [c.x, c.y, c.radius]).collect(),
            obstacles: self.obstacles.iter().map(|o| [o.x0, o.y0, o.x1, o.y1]).collect(),
            starts: self
                .agents
                .iter()
                .filter_map(|a| a.options.get("pose").and_then(toml::Value::as_array))
                .filter_map(|p| Some([number(p.first()?)?, number(p.get(1)?)?, number(p.get(2)?)?]))
                .collect(),
            seconds: self.seconds,
            cycle_ms: self.cycle_ms,
            noise: self.noise,
            deadline_ms: self.deadline_ms,
        }
    }

    /// The lab as the hub takes it (`builtin:NAME`, or a path made relative to the file).
    pub fn lab_spec(&self) -> String {
        self.resolve(&self.lab)
    }

    /// The grid, likewise.
    pub fn grid_spec(&self) -> Option<String> {
        self.grid.as_ref().map(|g| self.resolve(g))
    }

    fn resolve(&self, spec: &str) -> String {
        if spec.starts_with("builtin:") || Path::new(spec).is_absolute() {
            spec.to_owned()
        } else {
            self.base.join(spec).display().to_string()
        }
    }

    /// The scenario with its crowd placed for `seed` (itself when it has none): per chair
    /// `chairN` a navigator from its start through its goals, a checkpoint at its start and one
    /// at each goal, the goals as its route, and every chair expected to finish it.
    ///
    /// # Errors
    /// When the lab cannot be read or has no room for the crowd.
    pub fn populated(&self, seed: u64) -> Result<Scenario, String> {
        let Some(crowd) = &self.crowd else { return Ok(self.clone()) };
        let lab = world::map::builtin::load_lab_spec(&self.lab_spec()).map_err(|e| format!("{}: {e}", self.lab))?;
        let boxes: Vec<[f64; 4]> = self.obstacles.iter().map(|o| [o.x0, o.y0, o.x1, o.y1]).collect();
        // Robots the scenario starts itself, where it says.
        let taken: Vec<[f64; 2]> = self
            .agents
            .iter()
            .filter_map(|a| a.options.get("pose").and_then(toml::Value::as_array))
            .filter_map(|p| Some([number(p.first()?)?, number(p.get(1)?)?]))
            .collect();
        let trips = crate::crowd::place(&lab, &boxes, &taken, crowd, seed)?;
        let mut s = self.clone();
        // chair1, chair2, …, skipping names the scenario's own robots have.
        let used = |name: &str| {
            self.agent_of(name).is_some() || self.routes.contains_key(name) || self.expect.robots.contains_key(name)
        };
        let mut names = (1..).map(|k| format!("chair{k}")).filter(|n| !used(n));
        for t in &trips {
            let name = names.next().unwrap_or_default();
            let mut points = vec![[t.start[0], t.start[1]]];
            points.extend(&t.goals);
            let mut route = Vec::new();
            for (j, p) in points.iter().enumerate() {
                s.checkpoints.push(Checkpoint { x: p[0], y: p[1], radius: crowd.radius_m });
                if j > 0 {
                    route.push(s.checkpoints.len());
                }
            }
            let mut options = crowd.options.clone();
            options.insert("name".into(), name.clone().into());
            let start: Vec<toml::Value> = t.start.iter().map(|&v| toml::Value::Float(v)).collect();
            options.insert("pose".into(), toml::Value::Array(start));
            let cps = points
                .iter()
                .map(|p| {
                    toml::Value::Array(vec![toml::Value::Float(p[0]), toml::Value::Float(p[1]), crowd.radius_m.into()])
                })
                .collect();
            options.insert("checkpoint".into(), toml::Value::Array(cps));
            s.agents.push(AgentSpec { kind: "navigator".into(), options, config: None });
            s.routes.insert(name.clone(), route);
            s.expect.robots.entry(name).or_default().route = true;
        }
        Ok(s)
    }

    /// Ticks in the run.
    pub fn ticks(&self) -> u64 {
        (self.seconds * 1000.0 / self.cycle_ms as f64).round().max(1.0) as u64
    }
}

/// A TOML number, integer or float.
fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

/// Turns an agent's options into command-line flags (see the module documentation).
pub fn option_flags(options: &toml::Table) -> Result<Vec<String>, String> {
    fn scalar(v: &toml::Value) -> Option<String> {
        match v {
            toml::Value::String(s) => Some(s.clone()),
            toml::Value::Integer(i) => Some(i.to_string()),
            toml::Value::Float(f) => Some(f.to_string()),
            _ => None,
        }
    }
    let mut out = Vec::new();
    for (k, v) in options {
        let flag = format!("--{k}");
        match v {
            toml::Value::Boolean(true) => out.push(flag),
            toml::Value::Boolean(false) => {}
            toml::Value::Array(items) if items.iter().all(|i| matches!(i, toml::Value::Array(_))) => {
                for item in items {
                    let toml::Value::Array(inner) = item else { continue };
                    let parts: Option<Vec<String>> = inner.iter().map(scalar).collect();
                    let parts = parts.ok_or_else(|| format!("option {k}: nested arrays must hold numbers"))?;
                    out.extend([flag.clone(), parts.join(",")]);
                }
            }
            toml::Value::Array(items) if items.iter().all(|i| matches!(i, toml::Value::String(_))) => {
                for item in items {
                    out.extend([flag.clone(), scalar(item).unwrap_or_default()]);
                }
            }
            toml::Value::Array(items) => {
                let parts: Option<Vec<String>> = items.iter().map(scalar).collect();
                let parts = parts.ok_or_else(|| format!("option {k}: an array must hold numbers or strings"))?;
                out.extend([flag, parts.join(",")]);
            }
            other => out.extend([flag, scalar(other).ok_or_else(|| format!("option {k}: unsupported value"))?]),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenario_file_larger_than_the_cap_or_not_a_file_is_refused() {
        let big = std::env::temp_dir().join(format!("iwsim-scenario-big-{}.toml", std::process::id()));
        std::fs::File::create(&big)
            .and_then(|f| f.set_len(places::files::MAX_TEXT_FILE_BYTES + 1))
            .expect("a sparse file");
        let name = big.display().to_string();
        let err = Scenario::load(&name).expect_err("too large");
        std::fs::remove_file(&big).expect("clean up");
        assert!(
            matches!(&err, ScenarioError::NotText { path, source: places::files::TextReadError::TooLarge { .. } }
                if *path == name),
            "{err:?}"
        );
        assert!(err.to_string().starts_with(&format!("{name}: the file is larger than 16777216 bytes")), "{err}");
        // /dev/zero once read until memory ran out.
        let err = Scenario::load("/dev/zero").expect_err("a device");
        assert!(err.to_string().contains("not a regular file but a device"), "{err}");
    }

    #[test]
    fn every_builtin_scenario_loads() {
        for (name, _) in BUILTINS {
            let s = Scenario::load(&format!("builtin:{name}")).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(&s.name, name);
        }
    }

    #[test]
    fn options_become_flags() {
        let t: toml::Table = toml::from_str(
            "name = \"chair1\"\npose = [10.0, 6.1, 0.0]\ncheckpoint = [[10.0, 6.1], [20, 6.1]]\nfast = true\nslow = false\ncruise = 0.8",
        )
        .expect("toml");
        let flags = option_flags(&t).expect("flags");
        assert_eq!(
            flags,
            [
                "--checkpoint",
                "10,6.1",
                "--checkpoint",
                "20,6.1",
                "--cruise",
                "0.8",
                "--fast",
                "--name",
                "chair1",
                "--pose",
                "10,6.1,0"
            ]
        );
    }

    #[test]
    fn the_lock_step_deadline_is_the_files_or_five_seconds() {
        let head = "name = \"x\"\nseconds = 1\n[[agents]]\nkind = \"navigator\"\n";
        let unset = Scenario::parse(head, "x.toml", Path::new(".")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(unset.deadline_ms(), 5000);
        assert_eq!(unset.describe().deadline_ms, None, "unset, so a learning environment keeps its own");
        let set = Scenario::parse(&format!("deadline_ms = 60000\n{head}"), "x.toml", Path::new("."))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(set.deadline_ms(), 60_000);
        assert_eq!(set.describe().deadline_ms, Some(60_000));
    }

    #[test]
    fn mistakes_are_named_with_their_place() {
        for forever in ["1e300", "inf", "nan", "0", "604801"] {
            let text = format!("name = \"x\"\nseconds = {forever}\n[[agents]]\nkind = \"navigator\"\n");
            let err = Scenario::parse(&text, "x.toml", Path::new(".")).expect_err(forever).to_string();
            assert!(err.contains("seconds") && err.contains("at most 604800"), "{forever}: {err}");
        }
        let err = Scenario::parse("name = \"x\"\nseconds = \"ten\"\n", "x.toml", Path::new(".")).expect_err("type");
        let msg = err.to_string();
        assert!(msg.starts_with("x.toml: ") && msg.contains("line 2"), "{msg}");
        let err = Scenario::parse(
            "name = \"x\"\nseconds = 1\n[[agents]]\nkind = \"navigator\"\n[routes]\nc = [3]\n",
            "x.toml",
            Path::new("."),
        )
        .expect_err("bad route");
        assert_eq!(err.to_string(), "x.toml: route of c: checkpoint 3 does not exist (there are 0)");
        for never in ["0", "86400001"] {
            let text = format!("name = \"x\"\nseconds = 1\ndeadline_ms = {never}\n[[agents]]\nkind = \"navigator\"\n");
            let err = Scenario::parse(&text, "x.toml", Path::new(".")).expect_err(never).to_string();
            assert_eq!(err, format!("x.toml: deadline_ms = {never}: must be 1..=86400000 (a day)"));
        }
        let err =
            Scenario::parse("name = \"x\"\nseconds = 1\nspeed = 2\n", "x.toml", Path::new(".")).expect_err("unknown");
        assert!(err.to_string().contains("unknown field"), "{err}");
        let err =
            Scenario::parse("name = \"x\"\nseconds = 1\n[[agents]]\nkind = \"robot\"\n", "x.toml", Path::new("."))
                .expect_err("kind");
        assert!(err.to_string().contains("agent kind \"robot\""), "{err}");
    }

    #[test]
    fn obstacles_and_checkpoints_are_checked_where_they_are_written() {
        let head = "name = \"x\"\nseconds = 1\n[[agents]]\nkind = \"navigator\"\n";
        let parse = |tail: &str| Scenario::parse(&format!("{head}{tail}"), "x.toml", Path::new("."));
        let s = parse(
            "[[obstacles]]\nname = \"A\"\nx0 = 17\ny0 = 6.1\nx1 = 17.6\ny1 = 6.4\n[[checkpoints]]\nx = 1\ny = 2\n",
        )
        .expect("valid");
        assert_eq!(s.obstacles, [Obstacle { name: "A".into(), ..Obstacle::new(17.0, 6.1, 17.6, 6.4, 1.0) }]);
        assert_eq!(s.checkpoints, [Checkpoint { x: 1.0, y: 2.0, radius: 0.5 }]);
        let msg = parse("[[obstacles]]\nname = \"B\"\nx0 = 3\ny0 = 2\nx1 = 1\ny1 = 4\n")
            .expect_err("upside down")
            .to_string();
        assert!(
            msg.starts_with("x.toml: ") && msg.contains("line 5") && msg.contains("B \"3,2,1,4,1\": want X0 < X1"),
            "{msg}"
        );
        let msg = parse("[[checkpoints]]\nx = 1\ny = 2\nradius = 0\n").expect_err("radius").to_string();
        assert!(msg.contains("line 5") && msg.contains("positive radius"), "{msg}");
        let msg = parse("[[checkpoints]]\nx = 1\ny = 2\nr = 1\n").expect_err("unknown key").to_string();
        assert!(msg.contains("unknown field `r`"), "{msg}");
    }

    #[test]
    fn a_crowd_beside_a_scenarios_own_chairs_takes_other_names_and_keeps_their_routes() {
        let mut s = Scenario::load("builtin:corridor-swap").expect("built in");
        s.crowd = Some(crate::crowd::Crowd::of(2));
        let p = s.populated(4).expect("room for two more");
        let names: Vec<&str> =
            p.agents.iter().filter_map(|a| a.options.get("name").and_then(toml::Value::as_str)).collect();
        assert_eq!(names, ["chair1", "chair2", "chair3", "chair4"]);
        assert_eq!((p.routes["chair1"].clone(), p.routes["chair2"].clone()), (vec![2], vec![1]), "theirs kept");
        assert_eq!((p.routes["chair3"].clone(), p.routes["chair4"].clone()), (vec![4], vec![6]));
        assert_eq!(p.checkpoints.len(), 2 + 4);
        // Nobody starts on the swap's chairs (14.5, 6) and (24.5, 6).
        for a in &p.agents[2..] {
            let pose = a.options["pose"].as_array().expect("a pose");
            let (x, y) = (number(&pose[0]).expect("x"), number(&pose[1]).expect("y"));
            assert!([(14.5, 6.0), (24.5, 6.0)].iter().all(|&(u, v)| (x - u).hypot(y - v) >= 2.0), "{x}, {y}");
        }
    }

    #[test]
    fn a_crowds_options_reach_every_chair_it_places_and_its_own_keys_are_refused() {
        let text = "name = \"c\"\nlab = \"builtin:ward\"\nseconds = 10\n\n[crowd]\nchairs = 2\n\
                    options = { zone-claims = true, keep-right = 2.0 }\n";
        let s = Scenario::parse(text, "c.toml", Path::new(".")).expect("valid");
        let p = s.populated(1).expect("room");
        for a in &p.agents {
            let flags = option_flags(&a.options).expect("flags");
            assert!(flags.contains(&"--zone-claims".to_owned()), "{flags:?}");
            assert!(flags.windows(2).any(|w| w == ["--keep-right", "2"]), "{flags:?}");
        }
        let bad = text.replace("zone-claims = true", "pose = [1, 2, 3]");
        let err = Scenario::parse(&bad, "c.toml", Path::new(".")).expect_err("the crowd places its chairs");
        assert!(err.to_string().contains("crowd.options.pose"), "{err}");
    }
}
