//! The hub's logic without I/O: agents and their robots, registration rules, the lock-step
//! barrier, the run state, and the conversion of the world into the shared-memory layouts.
//! The process loop in [`super`] feeds it what arrived and publishes what it fills.

use std::collections::{BTreeMap, BTreeSet};

use bytemuck::Zeroable;
use ipc_types::{
    ACT_GHOST, ACT_LINK_DOWN, ACT_MOTORS, ACT_POSE, ACT_REAL, ACT_SAY, ActionBlock, CHAIR_CONTROLLED, CHAIR_GHOST,
    CHAIR_LINK_UP, COLLISION, ChairState, ChallengeStanding, Command, DRIVE_CONTROLLED, DRIVE_FRESH,
    DRIVE_RESUMES_SHIFT, FixedName, HAS_COMPASS, HAS_GPS, HAS_GROUND, HAS_SCORE, HubParams, InboxEntry, MAP_BEACON,
    MAP_CHECKPOINT, MAP_CORNER, MAP_GRID, MAP_TARGET, MAP_WALL, MAX_AGENTS, MAX_INBOX_MESSAGES, MAX_PROXIMITY,
    MAX_ROBOTS, MapHeader, MapItem, REG_CHAIR, REG_DISC, REG_HAS_POSE, ROBOT_COLLISION, ROBOT_DISC, ROBOT_FROZEN,
    ROBOT_LAGGING, Refusal, RobotInfo, RobotKind as WireKind, RobotRegistration, RobotState, RunState, SENSOR_BEACON,
    SENSOR_COLLISION, SENSOR_COMPASS, SENSOR_GPS, SENSOR_GROUND, SENSOR_OBSTACLE, SENSOR_SCORE, SensorBlock,
    SensorGeometry, SensorMode, WorldHeader,
};

use places::Checkpoint;
use recorder::journal::{Event, RecordedAction, RunStart};
use sim_model::PoseDeg;
use world::challenge::{Phase, Standing};
use world::map::{Grid, Lab, Params};
use world::math::Pose;
use world::{BodyShape, Message, ProximitySpec, RobotKind, RobotSpec, World, WorldBuildError};

use crate::stage::Stage;

/// How the hub steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A tick every cycle; late agents keep their last action.
    RealTime,
    /// A tick as soon as every live agent has answered (or the deadline passed).
    LockStep,
}

/// A refused registration: the reason and a sentence for the agent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refused {
    /// Why.
    pub reason: Refusal,
    /// What was wrong.
    pub detail: String,
}

impl Refused {
    pub(crate) fn new(reason: Refusal, detail: impl Into<String>) -> Self {
        Self { reason, detail: detail.into() }
    }
}

/// A live agent. An agent that says goodbye or dies leaves the table at once, so the table
/// holds at most `MAX_AGENTS` entries and the per-tick scans stay as short as the live set.
#[derive(Debug, Clone)]
struct AgentEntry {
    pid: u32,
    ready: bool,
    robots: Vec<u32>,
    /// Physical chairs this agent controls (registered by their adapters, not by it).
    controls: Vec<u32>,
    /// The last tick this agent answered.
    answered: Option<u64>,
    lagging: bool,
}

impl AgentEntry {
    /// Whether the agent has robots or chairs to answer for each tick.
    fn drives_something(&self) -> bool {
        !self.robots.is_empty() || !self.controls.is_empty()
    }
}

impl ChairLink {
    /// Takes what the chair's adapter reports for a tick.
    fn take_report(&mut self, b: &ActionBlock) {
        if b.flags & ACT_REAL != 0 {
            for (held, &v) in self.real_m.iter_mut().zip(&b.real_m) {
                // NaN: no fresh reading this tick; keep the last. Negative is nonsense.
                if !v.is_nan() && v >= 0.0 {
                    *held = v;
                }
            }
            self.real_encoders = Some(b.real_encoders);
        }
        if b.flags & ACT_GHOST != 0 && b.ghost.iter().all(|v| v.is_finite()) {
            self.ghost = Some(b.ghost);
        }
        self.link_up = b.flags & ACT_LINK_DOWN == 0;
    }
}

/// A robot and the agent that drives it. When that agent dies the robot stays, frozen, with
/// the dead agent's id (which is never given out again): an orphan, until an agent registers
/// a robot of the same name (and id, when it asks for one) and so takes it back.
#[derive(Debug, Clone)]
struct RobotEntry {
    agent_id: u32,
    leds: u32,
    /// A physical chair's link, when the robot was registered by a chair adapter.
    chair: Option<Box<ChairLink>>,
}

/// A physical chair in the world (thesis §5.4): its adapter (the robot's owner) pushes the
/// pose its odometry measures and the chair's real readings; the agent that attached to it by
/// name (its controller) drives it and gets the readings its sensor mode selects.
#[derive(Debug, Clone)]
struct ChairLink {
    controller: Option<u32>,
    mode: SensorMode,
    /// The controller's last motor powers, sanitised, and the tick it sent them for.
    drive: [f64; 2],
    drive_tick: Option<u64>,
    /// The last real reading of each sensor, metres (NaN: none yet; +∞: no echo).
    real_m: [f32; MAX_PROXIMITY],
    real_encoders: Option<[i64; 2]>,
    /// The chair's true pose as its adapter last reported it (a chair emulator's SimTruth),
    /// kept in the wire form it came in and is published in, for observers only.
    ghost: Option<PoseDeg>,
    link_up: bool,
    /// The operator's resume requests so far (wrapping), published in `drive_flags`.
    resumes: u16,
}

impl ChairLink {
    fn new(mode: SensorMode) -> Self {
        Self {
            controller: None,
            mode,
            drive: [0.0; 2],
            drive_tick: None,
            real_m: [f32::NAN; MAX_PROXIMITY],
            real_encoders: None,
            ghost: None,
            link_up: false,
            resumes: 0,
        }
    }

    /// Lets go of the controller: the chair's powers go to zero, which its adapter forwards.
    fn detach(&mut self) {
        self.controller = None;
        self.drive = [0.0; 2];
        self.drive_tick = None;
    }
}

/// The hub's state apart from its ports.
#[derive(Debug)]
pub struct HubCore {
    /// The world and its robots by id; every change to the world goes through it.
    stage: Stage,
    grid: Grid,
    mode: Mode,
    state: RunState,
    agents: BTreeMap<u32, AgentEntry>,
    robots: BTreeMap<u32, RobotEntry>,
    /// Robots whose agent died and that no agent has taken back: a registration looks for
    /// its robot among these, not among every robot (so N registrations cost O(N log N)).
    orphans: BTreeSet<u32>,
    /// Physical chairs' robots (an adapter's), which a controller's registration may attach to.
    chairs: BTreeSet<u32>,
    /// No id below this is free for a registration asking for any id.
    free_from: u32,
    next_agent_id: u32,
    tick_limit: u64,
    max_robots: usize,
    /// The actions taken since the last step, as they will be applied (and recorded).
    pending: Vec<RecordedAction>,
    /// Steps left to take while paused (from `Step` commands).
    single_steps: u32,
    /// Walls from this index on are a scenario's obstacles (the map's walls come first).
    obstacle_from: usize,
    /// A scenario's checkpoints.
    checkpoints: Vec<Checkpoint>,
    /// The names a Real robot may have (`--real NAME`); none by default.
    real_names: BTreeSet<String>,
    /// Poses pushed for Real robots that their bodies could not have reached (refused).
    refused_poses: u64,
}

impl HubCore {
    /// A hub on `lab` with `grid` and `params`, seeded with `seed`. `tick_limit` 0 = no limit.
    pub fn new(
        lab: &Lab,
        grid: Grid,
        params: Params,
        seed: u64,
        mode: Mode,
        tick_limit: u64,
    ) -> Result<Self, WorldBuildError> {
        Ok(Self {
            stage: Stage::new(lab, params, seed, tick_limit)?,
            grid,
            mode,
            state: RunState::Waiting,
            agents: BTreeMap::new(),
            robots: BTreeMap::new(),
            orphans: BTreeSet::new(),
            chairs: BTreeSet::new(),
            free_from: 1,
            next_agent_id: 1,
            tick_limit,
            max_robots: MAX_ROBOTS,
            real_names: BTreeSet::new(),
            refused_poses: 0,
            pending: Vec::new(),
            single_steps: 0,
            obstacle_from: lab.walls.len(),
            checkpoints: Vec::new(),
        })
    }

    /// The names a Real robot may register under: a Real robot's agent pushes its pose, so it
    /// is for the physical chairs a run expects (a scenario's, `--real NAME`), never for any
    /// agent that asks.
    pub fn set_real_names(&mut self, names: impl IntoIterator<Item = String>) {
        self.real_names = names.into_iter().collect();
    }

    /// Poses pushed for Real robots that were refused because the body could not have got there.
    pub fn refused_poses(&self) -> u64 {
        self.refused_poses
    }

    /// Lowers how many robots the hub accepts (never above `MAX_ROBOTS`).
    pub fn set_max_robots(&mut self, max: usize) {
        self.max_robots = max.min(MAX_ROBOTS);
    }

    /// Marks the lab's walls from `obstacle_from` on as a scenario's obstacles and sets its
    /// checkpoints; both are only published in the map (the walls are already in the world).
    pub fn set_scenario(&mut self, obstacle_from: usize, checkpoints: Vec<Checkpoint>) {
        self.obstacle_from = obstacle_from;
        self.checkpoints = checkpoints;
    }

    /// Lets the world's step use `threads` threads (0: one per core) from `parallel_min_robots`
    /// robots on; returns the threads it will use. Never changes a run.
    pub fn set_threads(&mut self, threads: usize, parallel_min_robots: usize) -> usize {
        self.stage.set_threads(threads, parallel_min_robots)
    }

    /// The world.
    pub fn world(&self) -> &World {
        self.stage.world()
    }

    /// The world with its robots by id and their challenge.
    pub fn stage(&self) -> &Stage {
        &self.stage
    }

    /// The simulated duration of one tick, seconds (the cycle time, also in lock-step).
    pub fn dt_s(&self) -> f64 {
        self.stage.dt_s()
    }

    /// The run state.
    pub fn state(&self) -> RunState {
        self.state
    }

    /// The stepping mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// A new agent process; its id, or a refusal when the hub is full.
    pub fn hello(&mut self, pid: u32) -> Result<u32, Refused> {
        if self.agents.len() >= MAX_AGENTS {
            return Err(Refused::new(Refusal::Capacity, format!("the hub serves at most {MAX_AGENTS} agents")));
        }
        let id = self.next_agent_id;
        self.next_agent_id += 1;
        self.agents.insert(
            id,
            AgentEntry { pid, ready: false, robots: Vec::new(), controls: Vec::new(), answered: None, lagging: false },
        );
        Ok(id)
    }

    /// The process id a live agent said hello with.
    pub fn agent_pid(&self, agent_id: u32) -> Option<u32> {
        self.agents.get(&agent_id).map(|a| a.pid)
    }

    /// Live agents: the size of the agent table.
    pub fn live_agents(&self) -> usize {
        self.agents.len()
    }

    /// Live agents that said they are ready.
    pub fn ready_agents(&self) -> usize {
        self.agents.values().filter(|a| a.ready).count()
    }

    /// Registers a robot for an agent: its id and sensor count, or why not.
    ///
    /// A robot left behind by a dead agent is taken back instead of a new one being added
    /// when the registration names it: the same name, and either the same id or id 0. The
    /// restarted agent gets it where it stands, with the body and sensors it was registered
    /// with, thawed and with its motors at rest.
    pub fn register(&mut self, agent_id: u32, reg: &RobotRegistration) -> Result<(u32, u32), Refused> {
        if !self.agents.contains_key(&agent_id) {
            return Err(Refused::new(Refusal::UnknownAgent, format!("agent {agent_id} has not said hello")));
        }
        if let Some(attached) = self.attach(agent_id, reg)? {
            return Ok(attached);
        }
        if let Some(taken_back) = self.take_back(agent_id, reg)? {
            return Ok(taken_back);
        }
        if WireKind::from_u32(reg.kind) == Some(WireKind::Real) {
            let name = reg.name.as_str().unwrap_or("");
            if !self.real_names.contains(name) {
                let expected = if self.real_names.is_empty() {
                    "none".to_owned()
                } else {
                    self.real_names.iter().map(|n| format!("{n:?}")).collect::<Vec<_>>().join(", ")
                };
                // The agent's answer holds 64 bytes: the way out first; the hub's log says more.
                tracing::warn!(
                    "refused Real robot {name:?}: a Real robot's agent pushes its pose, so the hub takes one only \
                     under a name it was told to expect (iwsim hub --real NAME); expected: {expected}"
                );
                return Err(Refused::new(
                    Refusal::NotAllowed,
                    format!("Real only as iwsim hub --real NAME, not {name:?}"),
                ));
            }
        }
        let chair = if reg.flags & REG_CHAIR != 0 {
            if WireKind::from_u32(reg.kind) != Some(WireKind::Real) {
                return Err(Refused::new(Refusal::BadParameters, "a chair adapter registers a Real robot"));
            }
            Some(Box::new(ChairLink::new(Self::mode_of(reg)?.unwrap_or_default())))
        } else {
            None
        };
        if self.robots.len() >= self.max_robots {
            return Err(Refused::new(Refusal::Capacity, format!("the hub serves at most {} robots", self.max_robots)));
        }
        let has_pose = reg.flags & REG_HAS_POSE != 0;
        let id = if reg.requested_id == 0 {
            let free = (self.free_from..).find(|id| !self.robots.contains_key(id)).unwrap_or(u32::MAX);
            if !has_pose && free as usize > self.grid.poses.len() {
                return Err(Refused::new(
                    Refusal::GridFull,
                    format!("all {} grid slots are taken; give a pose", self.grid.poses.len()),
                ));
            }
            free
        } else {
            if self.robots.contains_key(&reg.requested_id) {
                return Err(Refused::new(Refusal::DuplicateId, format!("robot id {} is taken", reg.requested_id)));
            }
            if !has_pose && reg.requested_id as usize > self.grid.poses.len() {
                return Err(Refused::new(
                    Refusal::NoSuchSlot,
                    format!("id {} is past the grid's {} slots; give a pose", reg.requested_id, self.grid.poses.len()),
                ));
            }
            reg.requested_id
        };
        let spec = self.spec_of(id, reg)?;
        let sensors = if spec.sensors.is_empty() { 4 } else { spec.sensors.len() as u32 };
        self.stage.add(id, agent_id, spec).map_err(|e| match e {
            world::AddRobotError::Full { .. } => Refused::new(Refusal::Capacity, e.to_string()),
            _ => Refused::new(Refusal::BadParameters, e.to_string()),
        })?;
        if chair.is_some() {
            self.chairs.insert(id);
        }
        if reg.requested_id == 0 {
            self.free_from = id.saturating_add(1);
        }
        self.robots.insert(id, RobotEntry { agent_id, leds: 0, chair });
        if let Some(a) = self.agents.get_mut(&agent_id) {
            a.robots.push(id);
        }
        Ok((id, sensors))
    }

    /// The sensor mode registration flags ask for, if any.
    fn mode_of(reg: &RobotRegistration) -> Result<Option<SensorMode>, Refused> {
        let both = ipc_types::REG_SENSORS_REAL | ipc_types::REG_SENSORS_AUGMENTED;
        if reg.flags & both == both {
            return Err(Refused::new(Refusal::Malformed, "a sensor mode cannot be both real and augmented"));
        }
        Ok(SensorMode::from_reg_flags(reg.flags))
    }

    /// Attaches `agent_id` as the controller of the physical chair `reg` names (same name, and
    /// the chair's id or id 0) when no live agent controls it: its id and sensor count, or
    /// `None` when `reg` names no chair. The chair keeps its adapter's body and sensors; a
    /// sensor mode in `reg` replaces the adapter's.
    fn attach(&mut self, agent_id: u32, reg: &RobotRegistration) -> Result<Option<(u32, u32)>, Refused> {
        if reg.flags & REG_CHAIR != 0 {
            return Ok(None);
        }
        let name = reg.name.as_str().ok_or_else(|| Refused::new(Refusal::Malformed, "the name is not UTF-8"))?;
        if name.is_empty() {
            return Ok(None);
        }
        let found = self.chairs.iter().find_map(|id| {
            let (id, e) = self.robots.get_key_value(id)?;
            let id = *id;
            let chair = e.chair.as_ref()?;
            let named = self.stage.robot(id).is_some_and(|r| r.spec.name == name);
            (named && (reg.requested_id == 0 || reg.requested_id == id) && e.agent_id != agent_id)
                .then_some((id, chair.controller))
        });
        let Some((id, controller)) = found else { return Ok(None) };
        if controller.is_some_and(|c| self.agents.contains_key(&c)) {
            return Err(Refused::new(
                Refusal::DuplicateId,
                format!("the chair {name} (robot {id}) is already controlled by another agent"),
            ));
        }
        let mode = Self::mode_of(reg)?;
        let Some(chair) = self.robots.get_mut(&id).and_then(|e| e.chair.as_mut()) else { return Ok(None) };
        chair.detach();
        chair.controller = Some(agent_id);
        if let Some(m) = mode {
            chair.mode = m;
        }
        if let Some(a) = self.agents.get_mut(&agent_id) {
            a.controls.push(id);
        }
        let sensors = self.stage.robot(id).map_or(0, |r| r.readings.proximity_count as u32);
        Ok(Some((id, sensors)))
    }

    /// Lets `agent_id` go of the chairs it controls.
    fn release_controls(&mut self, controls: &[u32], agent_id: u32) {
        for id in controls {
            if let Some(c) = self.robots.get_mut(id).and_then(|e| e.chair.as_mut())
                && c.controller == Some(agent_id)
            {
                c.detach();
            }
        }
    }

    /// Hands an orphan robot that `reg` names to `agent_id`; its id and sensor count, or
    /// `None` when `reg` names no orphan.
    fn take_back(&mut self, agent_id: u32, reg: &RobotRegistration) -> Result<Option<(u32, u32)>, Refused> {
        let name = reg.name.as_str().ok_or_else(|| Refused::new(Refusal::Malformed, "the name is not UTF-8"))?;
        let orphan = |&id: &u32| {
            let named = |want: &str| self.stage.robot(id).is_some_and(|r| r.spec.name == want);
            let matches = match reg.requested_id {
                0 => !name.is_empty() && named(name),
                wanted => id == wanted && (if name.is_empty() { named(&format!("robot{id}")) } else { named(name) }),
            };
            matches.then_some(id)
        };
        let found = match reg.requested_id {
            0 => self.orphans.iter().find_map(orphan),
            wanted => self.orphans.get(&wanted).and_then(orphan),
        };
        let Some(id) = found else { return Ok(None) };
        self.orphans.remove(&id);
        let Some(entry) = self.robots.get_mut(&id) else { return Ok(None) };
        entry.agent_id = agent_id;
        entry.leds = 0;
        self.stage.set_frozen(id, false);
        // The dead agent's last powers would drive it until the new agent's first action.
        self.pending.push(RecordedAction { id, motors: Some([0.0, 0.0]), pose: None, say: None, leds: 0 });
        let sensors = self.stage.robot(id).map_or(0, |r| r.readings.proximity_count as u32);
        if let Some(a) = self.agents.get_mut(&agent_id) {
            a.robots.push(id);
        }
        Ok(Some((id, sensors)))
    }

    fn spec_of(&self, id: u32, reg: &RobotRegistration) -> Result<RobotSpec, Refused> {
        let name = reg.name.as_str().ok_or_else(|| Refused::new(Refusal::Malformed, "the name is not UTF-8"))?;
        let kind = match WireKind::from_u32(reg.kind) {
            Some(WireKind::Simulated) => RobotKind::Simulated,
            Some(WireKind::Real) => RobotKind::Real,
            Some(WireKind::Door) => RobotKind::Door,
            None => return Err(Refused::new(Refusal::Malformed, format!("unknown robot kind {}", reg.kind))),
        };
        let pose = if reg.flags & REG_HAS_POSE != 0 {
            Pose::from_deg(reg.pose[0], reg.pose[1], reg.pose[2])
        } else {
            let p = self.grid.poses[id as usize - 1];
            Pose::from_deg(p.pos.x, p.pos.y, p.heading_deg)
        };
        if reg.sensor_count as usize > reg.sensors.len() {
            return Err(Refused::new(
                Refusal::BadParameters,
                format!("{} sensors given; at most {}", reg.sensor_count, reg.sensors.len()),
            ));
        }
        let sensors = reg.sensors[..reg.sensor_count as usize]
            .iter()
            .map(|s| ProximitySpec {
                x_m: s.x_m,
                y_m: s.y_m,
                angle_rad: s.angle_deg.to_radians(),
                cone_rad: s.cone_deg.to_radians(),
                range_m: (s.range_m != 0.0).then_some(s.range_m),
            })
            .collect();
        let spec = RobotSpec {
            name: if name.is_empty() { format!("robot{id}") } else { name.to_owned() },
            kind,
            shape: BodyShape::Rectangle,
            width_m: reg.width_m,
            height_m: reg.height_m,
            com: reg.com,
            max_speed_mps: reg.max_speed_mps,
            accel_curve: reg.accel_curve,
            pose,
            sensors,
        };
        // A disc is its diameter alone: its height and COM follow from it.
        Ok(if reg.flags & REG_DISC != 0 { spec.disc(reg.width_m) } else { spec })
    }

    /// An agent has registered all its robots.
    pub fn ready(&mut self, agent_id: u32) -> Result<(), Refused> {
        match self.agents.get_mut(&agent_id) {
            Some(a) => {
                a.ready = true;
                Ok(())
            }
            None => Err(Refused::new(Refusal::UnknownAgent, format!("agent {agent_id} is unknown"))),
        }
    }

    /// An agent leaves: its robots are removed from the world and it from the table.
    pub fn bye(&mut self, agent_id: u32) {
        if let Some(a) = self.agents.remove(&agent_id) {
            self.release_controls(&a.controls, agent_id);
            for id in a.robots {
                self.remove_robot(id);
            }
        }
    }

    /// Removes a robot from the world and from its controller's list.
    fn remove_robot(&mut self, id: u32) -> Option<RobotEntry> {
        let entry = self.robots.remove(&id)?;
        self.orphans.remove(&id);
        self.chairs.remove(&id);
        self.free_from = self.free_from.min(id);
        self.stage.remove(id);
        if let Some(a) = entry.chair.as_ref().and_then(|c| c.controller).and_then(|c| self.agents.get_mut(&c)) {
            a.controls.retain(|&x| x != id);
        }
        Some(entry)
    }

    /// An agent's process died: it leaves the table, its robots stay frozen and flagged (until
    /// a restarted agent takes them back, see [`HubCore::register`], or a `RemoveRobot`
    /// command removes them), and the run goes on without waiting for it. Returns whether the
    /// agent was alive.
    pub fn agent_died(&mut self, agent_id: u32) -> bool {
        let Some(a) = self.agents.remove(&agent_id) else { return false };
        // A chair whose controller died stops (its adapter sees no controller), but stays the
        // adapter's, ready for the next controller.
        self.release_controls(&a.controls, agent_id);
        for &id in &a.robots {
            if self.robots.contains_key(&id) {
                self.stage.set_frozen(id, true);
                self.orphans.insert(id);
            }
        }
        true
    }

    /// Robots whose agent died and that no agent has taken back, in id order.
    pub fn orphan_robots(&self) -> impl Iterator<Item = u32> + '_ {
        self.orphans.iter().copied()
    }

    /// Agents whose process id is `pid` (normally one).
    pub fn agents_with_pid(&self, pid: u32) -> Vec<u32> {
        self.agents.iter().filter(|(_, a)| a.pid == pid).map(|(&id, _)| id).collect()
    }

    /// Takes an agent's actions for `tick`. Actions for robots it does not own are ignored;
    /// returns how many were.
    pub fn actions(&mut self, agent_id: u32, tick: u64, blocks: &[ActionBlock]) -> usize {
        let now = self.stage.world().tick();
        let Some(agent) = self.agents.get_mut(&agent_id) else { return blocks.len() };
        // Only an answer to the tick in hand counts for the barrier: a tick from the future
        // (a buggy or hostile agent) must not excuse it from later ticks. Late answers still
        // set the robots' inputs for the next step.
        if tick == now {
            agent.answered = Some(now);
            agent.lagging = false;
        }
        let mut ignored = 0;
        for b in blocks {
            let Some(r) = self.robots.get_mut(&b.robot_id) else {
                ignored += 1;
                continue;
            };
            if let Some(chair) = r.chair.as_mut() {
                if r.agent_id == agent_id {
                    // The adapter: where the chair is, what it reads. Its motor powers are not
                    // the chair's (the controller's are), and it says nothing.
                    chair.take_report(b);
                    self.pending.push(RecordedAction {
                        id: b.robot_id,
                        motors: None,
                        pose: (b.flags & ACT_POSE != 0).then(|| Pose::from_deg(b.pose[0], b.pose[1], b.pose[2])),
                        say: None,
                        leds: r.leds,
                    });
                    continue;
                }
                if chair.controller != Some(agent_id) {
                    ignored += 1;
                    continue;
                }
                // The controller: the powers its adapter forwards to the chair. Only finite
                // powers count as an answer; a chair is never sent NaN.
                if b.flags & ACT_MOTORS != 0 && b.motors.iter().all(|m| m.is_finite()) {
                    chair.drive = b.motors.map(|m| m.clamp(-1.0, 1.0));
                    chair.drive_tick = Some(tick.min(now));
                }
            } else if r.agent_id != agent_id {
                ignored += 1;
                continue;
            }
            r.leds = b.flags & 0xff00;
            let say = (b.flags & ACT_SAY != 0).then(|| {
                let len = (b.say_len as usize).min(b.say_bytes.len());
                b.say_bytes[..len].to_vec()
            });
            self.pending.push(RecordedAction {
                id: b.robot_id,
                motors: (b.flags & ACT_MOTORS != 0).then_some(b.motors),
                // A chair's pose is its adapter's to push, never its controller's.
                pose: (b.flags & ACT_POSE != 0 && r.chair.is_none())
                    .then(|| Pose::from_deg(b.pose[0], b.pose[1], b.pose[2])),
                // A message too long for the world is not said (the world's rule).
                say: say.filter(|m| Message::new(m).is_ok()),
                leds: r.leds,
            });
        }
        ignored
    }

    /// Whether every live, ready agent with robots has answered the current tick. With no
    /// such agent there is nothing to step for: a lock-step hub waits for one instead of
    /// racing ahead on its own.
    pub fn all_answered(&self) -> bool {
        let t = self.stage.world().tick();
        let mut waiting_on = self.agents.values().filter(|a| a.ready && a.drives_something()).peekable();
        waiting_on.peek().is_some() && waiting_on.all(|a| a.answered.is_some_and(|x| x >= t))
    }

    /// Measures every robot where it stands (before the first step), with the run's noise.
    pub fn prime_sensors(&mut self) {
        self.stage.refresh_sensors();
    }

    /// Agents the lock-step barrier waits for: live, ready, with robots.
    pub fn barrier_size(&self) -> usize {
        self.agents.values().filter(|a| a.ready && a.drives_something()).count()
    }

    /// Marks the agents that have not answered the current tick as lagging (called when the
    /// lock-step deadline passes); returns how many.
    pub fn mark_laggards(&mut self) -> usize {
        let t = self.stage.world().tick();
        let mut n = 0;
        for a in self.agents.values_mut().filter(|a| a.ready && a.drives_something()) {
            a.lagging = a.answered.is_none_or(|x| x < t);
            n += a.lagging as usize;
        }
        n
    }

    /// Whether robots are left whose agent died and that no agent has taken back: a lock-step
    /// hub with no ready agent still steps them at the deadline's pace (frozen where they
    /// stand until their agent comes back), so a run whose last agent died reaches its end
    /// instead of waiting for ever.
    pub fn has_orphans(&self) -> bool {
        !self.orphans.is_empty()
    }

    /// Whether the run should step now (the caller adds the timing rule of its mode).
    pub fn may_step(&self) -> bool {
        self.state == RunState::Running || (self.state != RunState::Finished && self.single_steps > 0)
    }

    /// Starts the run if it is waiting for `wait_agents` ready agents and they are there.
    pub fn start_when_ready(&mut self, wait_agents: usize) {
        if self.state == RunState::Waiting && wait_agents > 0 && self.ready_agents() >= wait_agents {
            self.state = RunState::Running;
        }
    }

    /// Applies a run-control command; returns 0 when done, 2 for an unknown robot, 3 when the
    /// command makes no sense now.
    pub fn command(&mut self, command: Command, robot_id: u32) -> u32 {
        match command {
            Command::Start if self.state != RunState::Finished => self.state = RunState::Running,
            Command::Pause if self.state == RunState::Running => self.state = RunState::Paused,
            Command::Step if self.state != RunState::Finished && self.state != RunState::Running => {
                self.single_steps += 1
            }
            Command::Stop => self.state = RunState::Finished,
            Command::RemoveRobot => match self.remove_robot(robot_id) {
                Some(r) => {
                    if let Some(a) = self.agents.get_mut(&r.agent_id) {
                        a.robots.retain(|&id| id != robot_id);
                    }
                }
                None => return 2,
            },
            Command::ResumeChair => match self.robots.get_mut(&robot_id) {
                Some(RobotEntry { chair: Some(c), .. }) => c.resumes = c.resumes.wrapping_add(1),
                Some(_) => return 3,
                None => return 2,
            },
            _ => return 3,
        }
        0
    }

    /// Steps the world once with the actions taken since the last step.
    pub fn step(&mut self) {
        if self.state != RunState::Running {
            self.single_steps = self.single_steps.saturating_sub(1);
        }
        let stats = self.stage.step(&self.pending);
        if stats.unknown_robot_actions > 0 || stats.bad_values > 0 {
            tracing::debug!(?stats, "tick {}", self.stage.world().tick());
        }
        if stats.refused_poses > 0 {
            // Said the first time and every thousandth: a broken adapter says it each tick.
            if self.refused_poses.is_multiple_of(1000) {
                tracing::warn!(
                    "tick {}: refused a pose pushed for a Real robot that its body could not have reached \
                     since its last pose ({} refused so far)",
                    self.stage.world().tick(),
                    self.refused_poses + u64::from(stats.refused_poses)
                );
            }
            self.refused_poses += u64::from(stats.refused_poses);
        }
        self.pending.clear();
        if self.tick_limit > 0 && self.stage.world().tick() >= self.tick_limit {
            self.state = RunState::Finished;
        }
    }

    /// Starts journaling every change to the world, for a recording.
    pub fn record(&mut self) {
        self.stage.record();
    }

    /// The world's changes since the last call (none unless recording), oldest first.
    pub fn take_journal(&mut self, into: &mut Vec<Event>) {
        self.stage.take_journal(into);
    }

    /// What a recording of this run starts from.
    pub fn run_start(&self, deadline_ms: u32) -> RunStart {
        let w = self.stage.world();
        RunStart {
            iwsim_version: env!("CARGO_PKG_VERSION").to_owned(),
            seed: self.stage.seed(),
            dt_s: self.stage.dt_s(),
            lockstep: self.mode == Mode::LockStep,
            tick_limit: self.tick_limit,
            cycle_ms: w.params().cycle_ms,
            deadline_ms,
            lab: w.lab().clone(),
            params: w.params().clone(),
            grid: self.grid.clone(),
            obstacle_from: self.obstacle_from,
            checkpoints: self.checkpoints.clone(),
        }
    }

    /// The world header for the current tick.
    pub fn world_header(&self) -> WorldHeader {
        WorldHeader {
            tick: self.stage.world().tick(),
            sim_time_s: self.stage.world().time_s(),
            state_hash: self.stage.world().state_hash(),
            run_state: self.state as u32,
            robot_count: self.robots.len() as u32,
            agent_count: self.live_agents() as u32,
            lockstep: (self.mode == Mode::LockStep) as u32,
        }
    }

    /// Robots in the world.
    pub fn robot_count(&self) -> usize {
        self.robots.len()
    }

    /// The robot state of every robot, in id order.
    pub fn robot_states(&self) -> impl Iterator<Item = RobotState> + '_ {
        // Both in id order: the standings are read in one pass beside the robots.
        let mut standings = self.stage.challenge().standings().peekable();
        self.robots.iter().filter_map(move |(&id, e)| {
            let r = self.stage.robot(id)?;
            let lagging = self.agents.get(&e.agent_id).is_some_and(|a| a.lagging);
            while standings.next_if(|&(i, _)| i < id).is_some() {}
            let standing = standings.next_if(|&(i, _)| i == id).map(|(_, s)| s);
            Some(robot_state(r, id, e.agent_id, lagging, standing, self.state))
        })
    }

    /// Every robot's proximity-sensor geometry, in id order.
    pub fn robot_info(&self) -> impl Iterator<Item = RobotInfo> + '_ {
        let default_range = self.stage.world().params().proximity_range();
        self.robots.keys().filter_map(move |&id| Some(robot_info(self.stage.robot(id)?, id, default_range)))
    }

    /// An agent's robot ids, in registration order.
    pub fn agent_robots(&self, agent_id: u32) -> &[u32] {
        self.agents.get(&agent_id).map_or(&[], |a| a.robots.as_slice())
    }

    /// The robots an agent gets sensor blocks for: its own, then the chairs it controls.
    pub fn agent_blocks(&self, agent_id: u32) -> impl Iterator<Item = u32> + Clone + '_ {
        self.agents.get(&agent_id).into_iter().flat_map(|a| a.robots.iter().chain(&a.controls).copied())
    }

    /// Every physical chair as observers see it, in id order.
    pub fn chair_states(&self) -> impl Iterator<Item = ChairState> + '_ {
        self.robots.iter().filter_map(|(&id, e)| {
            let c = e.chair.as_ref()?;
            let r = self.stage.robot(id)?;
            let controlled = c.controller.is_some_and(|a| self.agents.contains_key(&a));
            let mut virtual_m = [f32::NAN; MAX_PROXIMITY];
            for (o, v) in virtual_m.iter_mut().zip(r.readings.proximity()) {
                *o = *v as f32;
            }
            Some(ChairState {
                robot_id: id,
                sensor_mode: c.mode as u32,
                flags: (controlled as u32 * CHAIR_CONTROLLED)
                    | (c.link_up as u32 * CHAIR_LINK_UP)
                    | (c.ghost.is_some() as u32 * CHAIR_GHOST),
                controller: if controlled { c.controller.unwrap_or(0) } else { 0 },
                ghost: c.ghost.unwrap_or([f64::NAN; 3]),
                real_m: c.real_m,
                virtual_m,
            })
        })
    }

    /// Whether the run has physical chairs.
    pub fn has_chairs(&self) -> bool {
        self.robots.values().any(|e| e.chair.is_some())
    }

    /// The sensor block of a robot for the current tick.
    pub fn sensor_block(&self, robot_id: u32) -> SensorBlock {
        let tick = self.stage.world().tick();
        let Some((entry, r)) = self.robots.get(&robot_id).and_then(|e| Some((e, self.stage.robot(robot_id)?))) else {
            return SensorBlock { robot_id, tick, ..SensorBlock::zeroed() };
        };
        let mut b = pack_sensor_block(r, robot_id, tick, |h| self.stage.id_of(h));
        if self.stage.world().params().challenge.score_sensor
            && let Some(s) = self.stage.standing(robot_id)
        {
            b.present |= HAS_SCORE;
            b.standing = challenge_standing(s, self.state);
        }
        if let Some(c) = &entry.chair {
            let default_range = self.stage.world().params().proximity_range();
            // Borrowed, not cloned: this runs for every chair at every publication.
            let defaults;
            let specs = if r.spec.sensors.is_empty() {
                defaults = r.spec.default_sensors();
                &defaults
            } else {
                &r.spec.sensors
            };
            let controlled = c.controller.is_some_and(|a| self.agents.contains_key(&a));
            merge_chair_readings(&mut b, c.mode, &c.real_m, |i| {
                specs.get(i).map_or(default_range, |s| s.range_m.unwrap_or(default_range))
            });
            // A chair's encoders are its own wheels', whatever the range sensors' mode: its twin
            // in the world only follows the pose the adapter pushes.
            if let Some(e) = c.real_encoders {
                b.encoder_ticks = e;
            }
            // A chair's position fix is its adapter's: the pose it pushes (the odometry,
            // map-matched to the walls its real sensors see), exactly. The hub holds no truer
            // pose of a physical chair to draw a GPS reading from, and its controller must know
            // the frame its virtual obstacles stand in, which is this pose.
            b.present |= HAS_GPS;
            (b.gps_x_m, b.gps_y_m, b.gps_heading_deg) = (r.pose.x, r.pose.y, sim_model::wire_deg(r.pose.theta));
            b.sensor_mode = c.mode as u32;
            if controlled {
                b.drive = c.drive.map(|v| v as f32);
                b.drive_flags = DRIVE_CONTROLLED | (c.drive_tick.is_some_and(|t| t + 1 >= tick) as u32 * DRIVE_FRESH);
            }
            b.drive_flags |= u32::from(c.resumes) << DRIVE_RESUMES_SHIFT;
        }
        b
    }

    /// The map as a header and items, for agents and viewers; `deadline_ms` is the lock-step
    /// deadline the process uses.
    pub fn map_items(&self, cycle_ms: u32, deadline_ms: u32, audience: MapAudience) -> (MapHeader, Vec<MapItem>) {
        let params = hub_params(self.stage.world().params(), self.mode, self.tick_limit, deadline_ms);
        let lab = self.stage.world().lab();
        pack_map_for(audience, lab, &self.grid, self.obstacle_from, &self.checkpoints, cycle_ms, params)
    }
}

/// The map packed for `audience`: [`pack_map`] of the whole lab for observers, of the lab
/// without the scenario's obstacles (walls from `obstacle_from` on) for agents.
pub fn pack_map_for(
    audience: MapAudience,
    lab: &Lab,
    grid: &Grid,
    obstacle_from: usize,
    checkpoints: &[Checkpoint],
    cycle_ms: u32,
    params: HubParams,
) -> (MapHeader, Vec<MapItem>) {
    match audience {
        MapAudience::Observers => pack_map(lab, grid, obstacle_from, checkpoints, cycle_ms, params),
        MapAudience::Agents => {
            // The scenario's obstacles are the world's truth: an agent's sensors find them.
            let known = obstacle_from.min(lab.walls.len());
            let walls = Lab { walls: lab.walls[..known].to_vec(), ..lab.clone() };
            pack_map(&walls, grid, known, checkpoints, cycle_ms, params)
        }
    }
}

/// Robot `id` of agent `agent_id` as observers see it in a world snapshot: what
/// [`HubCore::robot_states`] publishes, public so that a replay publishes the same.
pub fn robot_state(
    r: &world::Robot,
    id: u32,
    agent_id: u32,
    lagging: bool,
    standing: Option<Standing>,
    run_state: RunState,
) -> RobotState {
    let standing = standing.map(|s| challenge_standing(s, run_state)).unwrap_or_default();
    // A finished robot stands still by the challenge's rule; "frozen" says its agent is gone.
    let finished = standing.phase == Phase::Finished as u32;
    RobotState {
        id,
        kind: match r.spec.kind {
            RobotKind::Simulated => WireKind::Simulated,
            RobotKind::Real => WireKind::Real,
            RobotKind::Door => WireKind::Door,
        } as u32,
        flags: (r.collision as u32 * ROBOT_COLLISION)
            | ((r.frozen && !finished) as u32 * ROBOT_FROZEN)
            | (lagging as u32 * ROBOT_LAGGING)
            | ((r.spec.shape == BodyShape::Disc) as u32 * ROBOT_DISC),
        collision_count: r.collision_count.min(u32::MAX as u64) as u32,
        x_m: r.pose.x,
        y_m: r.pose.y,
        heading_deg: r.pose.heading_deg(),
        width_m: r.spec.width_m as f32,
        height_m: r.spec.height_m as f32,
        com: r.spec.com as f32,
        agent_id,
        motor_out: [r.motor_out[0] as f32, r.motor_out[1] as f32],
        proximity_m: {
            let mut p = [f32::NAN; MAX_PROXIMITY];
            for (o, v) in p.iter_mut().zip(r.readings.proximity()) {
                *o = *v as f32;
            }
            p
        },
        standing,
    }
}

/// A robot's challenge standing as published, its phase as shown while the run is in
/// `run_state` (Stopped while it waits or is paused).
pub fn challenge_standing(s: Standing, run_state: RunState) -> ChallengeStanding {
    let narrow = |v: u64| v.min(u64::from(u32::MAX)) as u32;
    ChallengeStanding {
        phase: s.phase.shown(matches!(run_state, RunState::Waiting | RunState::Paused)) as u32,
        // Ciber-Rato keeps the score in 32 bits.
        score: s.score as i32,
        arrival_tick: narrow(s.arrival_tick),
        returning_ticks: narrow(s.returning_ticks),
        collisions: s.collisions,
        _reserved: 0,
        visited_mask: s.visited,
    }
}

/// Robot `id`'s name and proximity-sensor geometry (`default_range_m` for sensors without a
/// range of their own): what [`HubCore::robot_info`] publishes, public so that a replay does
/// too.
pub fn robot_info(r: &world::Robot, id: u32, default_range_m: f64) -> RobotInfo {
    let specs = if r.spec.sensors.is_empty() { r.spec.default_sensors() } else { r.spec.sensors.clone() };
    let mut out = RobotInfo {
        robot_id: id,
        count: 0,
        sensors: [SensorGeometry::default(); MAX_PROXIMITY],
        name: FixedName::truncated(&r.spec.name),
    };
    for (o, s) in out.sensors.iter_mut().zip(&specs) {
        *o = SensorGeometry {
            x_m: s.x_m as f32,
            y_m: s.y_m as f32,
            angle_deg: s.angle_rad.to_degrees() as f32,
            cone_deg: s.cone_rad.to_degrees() as f32,
            range_m: s.range_m.unwrap_or(default_range_m) as f32,
        };
        out.count += 1;
    }
    out
}

/// Who a map is packed for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapAudience {
    /// Agents: the lab as their robots would know it, without the scenario's obstacles.
    Agents,
    /// Observers (viewer, recorder, runner): everything, obstacles flagged.
    Observers,
}

/// A robot's readings packed into the block its agent reads: what [`HubCore::sensor_block`]
/// publishes, public so that closed-loop tests drive agents with the hub's own packing.
/// `speaker_id` gives the robot id of a message's speaker.
pub fn pack_sensor_block(
    r: &world::Robot,
    robot_id: u32,
    tick: u64,
    speaker_id: impl Fn(world::RobotHandle) -> u32,
) -> SensorBlock {
    let mut b = SensorBlock::zeroed();
    b.robot_id = robot_id;
    b.tick = tick;
    let rd = &r.readings;
    b.proximity_count = rd.proximity_count as u32;
    b.proximity_m[..rd.proximity().len()].copy_from_slice(rd.proximity());
    if let Some(c) = rd.compass_deg {
        b.present |= HAS_COMPASS;
        b.compass_deg = c;
    }
    if let Some(g) = rd.gps {
        b.present |= HAS_GPS;
        (b.gps_x_m, b.gps_y_m, b.gps_heading_deg) = (g.x_m, g.y_m, g.heading_deg);
    }
    b.line_bits = u32::from(rd.line);
    if let Some(t) = rd.ground {
        b.present |= HAS_GROUND;
        b.ground = t as u32;
    }
    if rd.collision {
        b.present |= COLLISION;
    }
    b.beacon_count = rd.beacon_count as u32;
    for (k, v) in rd.beacons().iter().enumerate() {
        b.beacons_deg[k] = v.unwrap_or(f64::NAN);
    }
    b.encoder_ticks = rd.encoder_ticks;
    b.collision_count = r.collision_count.min(u32::MAX as u64) as u32;
    let mut offset = 0usize;
    for heard in &r.inbox {
        let bytes = heard.message.as_bytes();
        if b.inbox_count as usize >= MAX_INBOX_MESSAGES || offset + bytes.len() > b.inbox_bytes.len() {
            b.inbox_dropped += 1;
            continue;
        }
        let from_id = speaker_id(heard.from);
        b.inbox[b.inbox_count as usize] = InboxEntry { from_id, offset: offset as u16, len: bytes.len() as u16 };
        b.inbox_bytes[offset..offset + bytes.len()].copy_from_slice(bytes);
        offset += bytes.len();
        b.inbox_count += 1;
    }
    b
}

/// Puts a chair's readings of `mode` into `b` (which holds the virtual ones): *real* takes the
/// chair's own, *augmented* the nearer of the two per sensor (thesis §5.4.3: virtual 0.3 m and
/// real 0.6 m read 0.3 m). A real sensor that has not read yet, or read no echo, reads the
/// sensor's `range(i)`, as a virtual one with nothing in reach does.
pub fn merge_chair_readings(
    b: &mut SensorBlock,
    mode: SensorMode,
    real_m: &[f32; MAX_PROXIMITY],
    range: impl Fn(usize) -> f64,
) {
    let n = (b.proximity_count as usize).min(MAX_PROXIMITY);
    for (i, out) in b.proximity_m[..n].iter_mut().enumerate() {
        let reach = range(i);
        let real = if real_m[i].is_finite() { (real_m[i] as f64).min(reach) } else { reach };
        match mode {
            SensorMode::Virtual => {}
            SensorMode::Real => *out = real,
            SensorMode::Augmented => *out = out.min(real),
        }
    }
}

// The world's line sensor fits the sensor block's bits.
const _: () = assert!(world::LINE_ELEMENTS == ipc_types::LINE_ELEMENTS && ipc_types::LINE_ELEMENTS <= 32);
// Every name the world accepts fits the wire's name field whole.
const _: () = assert!(world::MAX_NAME_LEN == ipc_types::NAME_BYTES - 1);
// The world's limits are the wire's: a robot's sensors, beacons, messages and inbox all fit
// the sensor block's fixed arrays, so a mismatch fails the build, not a run.
const _: () = assert!(world::MAX_PROXIMITY == ipc_types::MAX_PROXIMITY);
const _: () = assert!(world::MAX_BEACONS == ipc_types::MAX_BEACONS);
const _: () = assert!(world::MAX_MESSAGE_BYTES == ipc_types::MESSAGE_BYTES);
const _: () = assert!(world::MAX_INBOX_BYTES == ipc_types::INBOX_BYTES);

/// The run parameters agents learn from the map header.
pub fn hub_params(p: &Params, mode: Mode, tick_limit: u64, deadline_ms: u32) -> HubParams {
    let bit = |on: bool, b: u32| if on { b } else { 0 };
    let r = &p.requests;
    HubParams {
        noise_proximity_m: p.noise.proximity_m,
        noise_beacon_deg: p.noise.beacon_deg,
        noise_compass_deg: p.noise.compass_deg,
        noise_gps_pos_m: p.noise.gps_pos_m,
        noise_gps_heading_deg: p.noise.gps_heading_deg,
        noise_motors_pct: p.noise.motor_frac * 100.0,
        beacon_aperture_rad: p.beacon_aperture_rad,
        sim_time_ticks: tick_limit,
        deadline_ms,
        lockstep: (mode == Mode::LockStep) as u32,
        sensors_on: bit(p.sensors.gps, SENSOR_GPS)
            | bit(p.sensors.beacon, SENSOR_BEACON)
            | bit(p.sensors.compass, SENSOR_COMPASS)
            | SENSOR_OBSTACLE
            | SENSOR_GROUND
            | SENSOR_COLLISION
            | bit(p.challenge.score_sensor, SENSOR_SCORE),
        requestable: bit(r.obstacle, SENSOR_OBSTACLE)
            | bit(r.beacon, SENSOR_BEACON)
            | bit(r.ground, SENSOR_GROUND)
            | bit(r.compass, SENSOR_COMPASS)
            | bit(r.collision, SENSOR_COLLISION),
        requests_per_cycle: r.per_cycle,
        latency: [
            p.latency.proximity,
            p.latency.beacon,
            p.latency.ground,
            p.latency.compass,
            p.latency.collision,
            p.latency.gps,
        ],
        scoring_mode: p.challenge.scoring.number(),
        encoder_ticks_per_m: sim_model::encoder_ticks_per_m(p.encoder_ticks_per_rev as f64, p.wheel_radius_m),
        key_time_ticks: p.challenge.key_time_ticks,
        scoring: [
            p.challenge.return_time_penalty,
            p.challenge.arrival_time_penalty,
            p.challenge.collision_wall_penalty,
            p.challenge.collision_robot_penalty,
            p.challenge.target_reward,
            p.challenge.home_reward,
        ],
        obstacle_range_m: p.proximity_range_m.unwrap_or(0.0),
    }
}

/// The map as [`HubCore::map_items`] publishes it: the lab's walls (from `obstacle_from` on
/// flagged as a scenario's obstacles), beacons, targets, grid and checkpoints.
pub fn pack_map(
    lab: &Lab,
    grid: &Grid,
    obstacle_from: usize,
    checkpoints: &[Checkpoint],
    cycle_ms: u32,
    params: HubParams,
) -> (MapHeader, Vec<MapItem>) {
    let mut items = Vec::new();
    let item = |kind, index: usize, a, b, c| MapItem { kind, index: index as u32, a, b, c };
    for (i, w) in lab.walls.iter().enumerate() {
        let obstacle = if i >= obstacle_from { 1.0 } else { 0.0 };
        items.push(item(MAP_WALL, i, w.height_m, w.corners.len() as f64, obstacle));
        for c in &w.corners {
            items.push(item(MAP_CORNER, i, c.x, c.y, 0.0));
        }
    }
    for (i, b) in lab.beacons.iter().enumerate() {
        items.push(item(MAP_BEACON, i, b.pos.x, b.pos.y, b.height_m));
    }
    for (i, t) in lab.targets.iter().enumerate() {
        items.push(item(MAP_TARGET, i, t.pos.x, t.pos.y, t.radius_m));
    }
    for (i, p) in grid.poses.iter().enumerate() {
        items.push(item(MAP_GRID, i, p.pos.x, p.pos.y, p.heading_deg));
    }
    for (i, c) in checkpoints.iter().enumerate() {
        items.push(item(MAP_CHECKPOINT, i, c.x, c.y, c.radius));
    }
    let header = MapHeader {
        width_m: lab.width_m,
        height_m: lab.height_m,
        item_count: items.len() as u32,
        wall_count: lab.walls.len() as u32,
        beacon_count: lab.beacons.len() as u32,
        target_count: lab.targets.len() as u32,
        grid_count: grid.poses.len() as u32,
        cycle_ms,
        name: FixedName::truncated(&lab.name),
        params,
    };
    (header, items)
}

/// What [`pack_map`] packed, read back from an observers' map: the lab (the scenario's
/// obstacles last), the grid, where the obstacles start and the checkpoints. For a recorder
/// that has only the map a bridge serves (`iwsim record --zenoh`). The error says which item
/// does not fit.
pub fn unpack_map(header: &MapHeader, items: &[MapItem]) -> Result<(Lab, Grid, usize, Vec<Checkpoint>), String> {
    use nalgebra::Point2;
    use world::map::{Beacon, StartPose, Target, Wall};
    if header.item_count as usize != items.len() {
        return Err(format!("the header counts {} items, the map holds {}", header.item_count, items.len()));
    }
    let mut lab = Lab {
        name: header.name.as_str().unwrap_or("").to_owned(),
        width_m: header.width_m,
        height_m: header.height_m,
        walls: Vec::new(),
        beacons: Vec::new(),
        targets: Vec::new(),
    };
    let (mut grid, mut checkpoints, mut obstacle_from) = (Grid::default(), Vec::new(), None);
    let mut corners_due = 0usize;
    for (k, it) in items.iter().enumerate() {
        let bad = |what: &str| format!("map item {k} (kind {}, index {}): {what}", it.kind, it.index);
        if corners_due > 0 && it.kind != MAP_CORNER {
            return Err(bad(&format!("the wall before it lacks {corners_due} corners")));
        }
        match it.kind {
            MAP_WALL => {
                if !(it.b >= 3.0 && it.b <= items.len() as f64) {
                    return Err(bad(&format!("a wall of {} corners", it.b)));
                }
                corners_due = it.b as usize;
                if it.c != 0.0 {
                    obstacle_from.get_or_insert(lab.walls.len());
                } else if obstacle_from.is_some() {
                    return Err(bad("a map wall after the scenario's obstacles"));
                }
                lab.walls.push(Wall { height_m: it.a, corners: Vec::with_capacity(corners_due) });
            }
            MAP_CORNER => {
                let Some(w) = lab.walls.last_mut().filter(|_| corners_due > 0) else {
                    return Err(bad("a corner of no wall"));
                };
                w.corners.push(Point2::new(it.a, it.b));
                corners_due -= 1;
            }
            MAP_BEACON => lab.beacons.push(Beacon { pos: Point2::new(it.a, it.b), height_m: it.c }),
            MAP_TARGET => lab.targets.push(Target { pos: Point2::new(it.a, it.b), radius_m: it.c }),
            MAP_GRID => grid.poses.push(StartPose { pos: Point2::new(it.a, it.b), heading_deg: it.c }),
            MAP_CHECKPOINT => checkpoints.push(Checkpoint { x: it.a, y: it.b, radius: it.c }),
            _ => return Err(bad("an unknown kind")),
        }
    }
    if corners_due > 0 {
        return Err(format!("the last wall lacks {corners_due} corners"));
    }
    let obstacle_from = obstacle_from.unwrap_or(lab.walls.len());
    Ok((lab, grid, obstacle_from, checkpoints))
}

#[cfg(test)]
mod tests {
    use super::*;
    use world::map::builtin;

    #[test]
    fn an_observers_map_unpacks_to_the_lab_grid_obstacles_and_checkpoints_it_packs() {
        let map = builtin::map("liacc").expect("built in");
        let mut lab = map.lab.clone();
        let obstacle_from = lab.walls.len();
        lab.walls.push(world::map::Wall::rectangle(1.0, 1.0, 2.0, 2.5, 0.8));
        let checkpoints = vec![Checkpoint { x: 3.0, y: 4.0, radius: 0.5 }];
        let params = hub_params(&Params::default(), Mode::LockStep, 100, 250);
        let (h, items) = pack_map(&lab, &map.grid, obstacle_from, &checkpoints, 100, params);
        let (lab2, grid2, from2, checkpoints2) = unpack_map(&h, &items).expect("unpacks");
        assert_eq!((lab2, grid2, from2, checkpoints2), (lab, map.grid.clone(), obstacle_from, checkpoints));
        // A wall cut short is named.
        let cut: Vec<MapItem> = items.iter().copied().filter(|i| !(i.kind == MAP_CORNER && i.index == 0)).collect();
        let h2 = MapHeader { item_count: cut.len() as u32, ..h };
        let e = unpack_map(&h2, &cut).expect_err("wall 0 lost its corners");
        assert!(e.contains("lacks"), "{e}");
    }

    fn core(mode: Mode) -> HubCore {
        let map = builtin::map("liacc").expect("built in");
        let params = Params { noise: world::map::NoiseParams::NONE, ..Params::default() };
        HubCore::new(&map.lab, map.grid, params, 1, mode, 0).expect("valid")
    }

    #[test]
    fn a_lab_name_too_long_for_the_header_reaches_agents_cut_like_a_robot_name() {
        let mut map = builtin::map("liacc").expect("built in");
        // 254 ASCII bytes, then "é" (2 bytes) straddles the 255-byte limit: the cut drops it
        // whole.
        map.lab.name = format!("{}éé and more", "L".repeat(254));
        let c = HubCore::new(&map.lab, map.grid, Params::default(), 1, Mode::LockStep, 0).expect("valid");
        let (header, _) = c.map_items(100, 0, MapAudience::Observers);
        assert_eq!(header.name.as_str(), Some("L".repeat(254).as_str()));
        assert_eq!(FixedName::truncated("short lab").as_str(), Some("short lab"));
        assert_eq!(FixedName::truncated("nul\0after").as_str(), Some("nul"));
    }

    #[test]
    fn registration_follows_ciber_rato_id_rules() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(100).expect("room");
        let reg = RobotRegistration::new("r");
        assert_eq!(c.register(a, &reg).map(|r| r.0), Ok(1), "id 0 takes the first free slot");
        let mut two = reg;
        two.requested_id = 3;
        assert_eq!(c.register(a, &two).map(|r| r.0), Ok(3));
        assert_eq!(c.register(a, &two).map_err(|e| e.reason), Err(Refusal::DuplicateId));
        two.requested_id = 99;
        assert_eq!(c.register(a, &two).map_err(|e| e.reason), Err(Refusal::NoSuchSlot));
        two.flags = REG_HAS_POSE;
        two.pose = [20.0, 6.1, 0.0];
        assert_eq!(c.register(a, &two).map(|r| r.0), Ok(99), "with a pose any id goes");
        let mut bad = RobotRegistration::new("bad");
        bad.com = 1.5;
        let refused = c.register(a, &bad).expect_err("com out of range");
        assert_eq!(refused.reason, Refusal::BadParameters);
        assert!(refused.detail.contains("com"), "{}", refused.detail);
        assert_eq!(c.register(77, &reg).map_err(|e| e.reason), Err(Refusal::UnknownAgent));
        bad = reg;
        bad.kind = 9;
        assert_eq!(c.register(a, &bad).map_err(|e| e.reason), Err(Refusal::Malformed));
    }

    #[test]
    fn a_disc_registration_becomes_a_disc_and_observers_are_told() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(100).expect("room");
        // A stale height and COM are overridden by the diameter.
        let mut reg = RobotRegistration::new("plain").disc(1.0).motors(3.0, 0.5).at(Some([10.0, 6.1, 0.0]));
        (reg.height_m, reg.com) = (0.3, 0.9);
        let id = c.register(a, &reg).expect("accepted").0;
        let spec = &c.stage.robot(id).expect("in the world").spec;
        assert_eq!((spec.shape, spec.width_m, spec.height_m, spec.com), (BodyShape::Disc, 1.0, 1.0, 0.5));
        assert_eq!((spec.max_speed_mps, spec.accel_curve), (3.0, 0.5));
        let state = c.robot_states().find(|s| s.id == id).expect("published");
        assert_ne!(state.flags & ROBOT_DISC, 0);
        assert_eq!((state.width_m, state.height_m), (1.0, 1.0));
        // A rectangle is not flagged.
        let rect = c.register(a, &RobotRegistration::new("chair")).expect("accepted").0;
        assert_eq!(c.robot_states().find(|s| s.id == rect).expect("published").flags & ROBOT_DISC, 0);
    }

    #[test]
    fn the_barrier_waits_for_every_ready_agent_and_skips_dead_ones() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let b = c.hello(2).expect("room");
        let ra = c.register(a, &RobotRegistration::new("a")).expect("ok").0;
        let rb = c.register(b, &RobotRegistration::new("b")).expect("ok").0;
        c.ready(a).expect("known");
        c.ready(b).expect("known");
        c.start_when_ready(2);
        assert_eq!(c.state(), RunState::Running);
        assert!(!c.all_answered());
        c.actions(a, 0, &[ActionBlock::motors(ra, 1.0, 1.0)]);
        assert!(!c.all_answered());
        c.actions(b, 0, &[ActionBlock::motors(rb, 1.0, 1.0)]);
        assert!(c.all_answered());
        c.step();
        assert!(!c.all_answered(), "tick 1 needs new answers");
        c.actions(a, 1, &[ActionBlock::motors(ra, 1.0, 1.0)]);
        assert_eq!(c.mark_laggards(), 1);
        assert!(c.agent_died(b));
        assert!(c.all_answered(), "a dead agent is not waited for");
        c.step();
        let frozen: Vec<_> = c.robot_states().filter(|s| s.flags & ROBOT_FROZEN != 0).map(|s| s.id).collect();
        assert_eq!(frozen, vec![rb]);
        assert!(c.agent_died(a));
        assert!(!c.all_answered(), "with no live agent lock-step waits instead of racing");
    }

    #[test]
    fn agents_that_leave_or_die_leave_the_table_and_free_their_place() {
        let mut c = core(Mode::LockStep);
        for round in 0..3 * MAX_AGENTS {
            let a = c.hello(round as u32).expect("a place is free again");
            if round % 2 == 0 {
                c.bye(a);
            } else {
                assert!(c.agent_died(a));
                assert!(!c.agent_died(a), "dies once");
            }
        }
        assert_eq!((c.agents.len(), c.live_agents()), (0, 0));
        let a = c.hello(1).expect("room");
        c.register(a, &RobotRegistration::new("a")).expect("ok");
        c.bye(a);
        assert_eq!((c.agents.len(), c.robot_count()), (0, 0), "goodbye takes the robots too");
        assert_eq!(c.register(a, &RobotRegistration::new("a")).map_err(|e| e.reason), Err(Refusal::UnknownAgent));
    }

    #[test]
    fn any_id_is_the_lowest_free_one_and_a_dead_agents_robots_wait_to_be_taken_back() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let mut reg = RobotRegistration::new("");
        reg.flags |= REG_HAS_POSE;
        let ids: Vec<u32> = (0..5)
            .map(|k| {
                reg.pose = [3.0 + 3.0 * k as f64, 3.0, 0.0];
                c.register(a, &reg).expect("room").0
            })
            .collect();
        assert_eq!(ids, [1, 2, 3, 4, 5]);
        c.remove_robot(2);
        c.remove_robot(4);
        reg.pose = [3.0, 9.0, 0.0];
        assert_eq!(c.register(a, &reg).expect("room").0, 2, "the lowest free id");
        reg.pose = [6.0, 9.0, 0.0];
        assert_eq!(c.register(a, &reg).expect("room").0, 4);
        reg.pose = [9.0, 9.0, 0.0];
        assert_eq!(c.register(a, &reg).expect("room").0, 6);
        // A dead agent's named robot is waiting for a restarted agent, by name, among orphans.
        let b = c.hello(2).expect("room");
        let mut named = RobotRegistration::new("kept");
        named.flags |= REG_HAS_POSE;
        named.pose = [12.0, 9.0, 0.0];
        let (kept, _) = c.register(b, &named).expect("room");
        assert!(c.agent_died(b));
        assert_eq!(c.orphan_robots().collect::<Vec<_>>(), [kept]);
        let b2 = c.hello(3).expect("room");
        assert_eq!(c.register(b2, &named).expect("taken back").0, kept);
        assert_eq!(c.orphan_robots().count(), 0, "taken back once");
        named.pose = [15.0, 9.0, 0.0];
        assert_ne!(c.register(b2, &named).expect("a new robot").0, kept, "a second registration adds one");
    }

    #[test]
    fn a_restarted_agent_takes_its_robot_back_where_it_stands() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let reg = RobotRegistration::new("chair1").id(1);
        assert_eq!(c.register(a, &reg), Ok((1, 4)));
        c.ready(a).expect("known");
        c.command(Command::Start, 0);
        for t in 0..10 {
            c.actions(a, t, &[ActionBlock::motors(1, 1.0, 1.0)]);
            c.step();
        }
        assert!(c.agent_died(a));
        let before = c.robot_states().next().expect("robot stays");
        assert_ne!(before.flags & ROBOT_FROZEN, 0);
        assert_eq!(c.orphan_robots().collect::<Vec<_>>(), vec![1]);
        c.step();

        // Another name, or another id, does not take it.
        let b = c.hello(2).expect("room");
        assert_eq!(
            c.register(b, &RobotRegistration::new("chair2").id(1)).map_err(|e| e.reason),
            Err(Refusal::DuplicateId)
        );
        assert_eq!(c.register(b, &RobotRegistration::new("chair1").id(2)).map(|r| r.0), Ok(2));
        c.bye(b);

        let restarted = c.hello(1).expect("room");
        assert_eq!(c.register(restarted, &reg), Ok((1, 4)), "same name and id: the robot comes back");
        assert_eq!(c.orphan_robots().count(), 0);
        assert_eq!(c.robot_count(), 1);
        let after = c.robot_states().next().expect("robot");
        assert_eq!((after.id, after.agent_id, after.flags & ROBOT_FROZEN), (1, restarted, 0));
        assert_eq!((after.x_m, after.y_m, after.heading_deg), (before.x_m, before.y_m, before.heading_deg));
        c.ready(restarted).expect("known");
        let t = c.world().tick();
        c.actions(restarted, t, &[ActionBlock::motors(1, 1.0, 1.0)]);
        assert!(c.all_answered(), "the barrier waits for the new owner");
        c.step();
        assert!(c.robot_states().next().expect("robot").x_m > before.x_m, "it drives again");

        // A live agent's robot is never taken: the same name with id 0 gets a new robot.
        let other = c.hello(3).expect("room");
        assert_eq!(c.register(other, &RobotRegistration::new("chair1")).map(|r| r.0), Ok(2));
    }

    #[test]
    fn a_restarted_agent_asking_for_any_id_takes_back_the_robot_of_its_name() {
        let mut c = core(Mode::RealTime);
        let a = c.hello(1).expect("room");
        assert_eq!(c.register(a, &RobotRegistration::new("left")).map(|r| r.0), Ok(1));
        assert_eq!(c.register(a, &RobotRegistration::new("right")).map(|r| r.0), Ok(2));
        assert!(c.agent_died(a));
        let b = c.hello(1).expect("room");
        assert_eq!(c.register(b, &RobotRegistration::new("right")).map(|r| r.0), Ok(2));
        assert_eq!(c.agent_robots(b), &[2]);
        assert_eq!(c.orphan_robots().collect::<Vec<_>>(), vec![1]);
        // The orphan left can still be removed by command.
        assert_eq!(c.command(Command::RemoveRobot, 1), 0);
        assert_eq!(c.orphan_robots().count(), 0);
    }

    #[test]
    fn only_an_answer_to_the_tick_in_hand_counts_and_clears_lagging() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let ra = c.register(a, &RobotRegistration::new("a")).expect("ok").0;
        c.ready(a).expect("known");
        c.command(Command::Start, 0);
        // A future tick excuses nothing.
        c.actions(a, u64::MAX, &[ActionBlock::motors(ra, 1.0, 1.0)]);
        assert!(!c.all_answered());
        assert_eq!(c.mark_laggards(), 1);
        assert_ne!(c.robot_states().next().expect("robot").flags & ipc_types::ROBOT_LAGGING, 0);
        c.actions(a, 0, &[ActionBlock::motors(ra, 1.0, 1.0)]);
        assert!(c.all_answered());
        assert_eq!(
            c.robot_states().next().expect("robot").flags & ipc_types::ROBOT_LAGGING,
            0,
            "answering clears the flag"
        );
    }

    /// A chair adapter's registration: a Real robot in the liacc corridor, in `mode`.
    fn chair_reg(name: &str, mode: SensorMode) -> RobotRegistration {
        let mut reg = RobotRegistration::new(name);
        reg.kind = WireKind::Real as u32;
        reg.flags |= REG_CHAIR | REG_HAS_POSE | mode.reg_flags();
        reg.pose = [10.0, 6.1, 0.0];
        reg
    }

    fn report(id: u32, x: f64, real: [f32; MAX_PROXIMITY]) -> ActionBlock {
        let mut b = ActionBlock::pose(id, x, 6.1, 0.0);
        b.flags |= ACT_REAL | ACT_GHOST;
        b.real_m = real;
        b.real_encoders = [100, 120];
        b.ghost = [x + 0.1, 6.0, 2.0];
        b
    }

    #[test]
    fn a_controller_attaches_to_a_chair_by_name_and_drives_it_through_its_adapter() {
        let mut c = core(Mode::LockStep);
        c.set_real_names(["chair1".to_owned()]);
        let adapter = c.hello(1).expect("room");
        let agent = c.hello(2).expect("room");
        let (id, sensors) = c.register(adapter, &chair_reg("chair1", SensorMode::Virtual)).expect("a chair");
        assert_eq!(sensors, 4);
        // The controller's own body and sensors do not matter: the chair is the adapter's.
        let (attached, _) = c.register(agent, &RobotRegistration::new("chair1").disc(1.0)).expect("attached");
        assert_eq!(attached, id);
        assert_eq!(c.robot_count(), 1, "attaching adds no robot");
        assert_eq!(c.agent_blocks(agent).collect::<Vec<_>>(), vec![id]);
        assert_eq!(c.agent_blocks(adapter).collect::<Vec<_>>(), vec![id]);
        // A second agent cannot take a chair that is driven.
        let third = c.hello(3).expect("room");
        let refused = c.register(third, &RobotRegistration::new("chair1")).expect_err("already controlled");
        assert_eq!(refused.reason, Refusal::DuplicateId);
        for a in [adapter, agent] {
            c.ready(a).expect("ready");
        }
        c.command(Command::Start, 0);
        assert_eq!(c.barrier_size(), 2, "the lock-step waits for the adapter and the controller");
        // The controller's powers reach the adapter's block; its pushed pose is ignored.
        let mut drive = ActionBlock::motors(id, 0.5, f64::NAN);
        assert_eq!(c.actions(agent, 0, &[drive]), 0);
        drive.motors = [0.5, -2.0];
        drive.flags |= ACT_POSE;
        drive.pose = [30.0, 2.0, 0.0];
        c.actions(agent, 0, &[drive]);
        // The adapter's motors are not the chair's.
        let mut own = report(id, 10.1, [f32::NAN; MAX_PROXIMITY]);
        own.flags |= ACT_MOTORS;
        own.motors = [1.0, 1.0];
        c.actions(adapter, 0, &[own]);
        c.step();
        let b = c.sensor_block(id);
        assert_eq!(b.drive, [0.5, -1.0], "clamped to [-1, 1]");
        assert_eq!(b.drive_flags, DRIVE_CONTROLLED | DRIVE_FRESH);
        assert_eq!(b.encoder_ticks, [100, 120], "a chair's encoders are its wheels'");
        assert_ne!(b.present & HAS_GPS, 0, "a chair has a fix whatever the hub's GPS setting");
        assert_eq!((b.gps_x_m, b.gps_y_m, b.gps_heading_deg), (10.1, 6.1, 0.0), "its adapter's pose, exactly");
        let state = c.robot_states().next().expect("one");
        assert_eq!((state.x_m, state.y_m), (10.1, 6.1), "the adapter's pose, not the controller's");
        // A tick without an answer makes the powers stale.
        c.actions(adapter, 1, &[report(id, 10.1, [f32::NAN; MAX_PROXIMITY])]);
        c.step();
        c.step();
        assert_eq!(c.sensor_block(id).drive_flags, DRIVE_CONTROLLED, "stale: not fresh");
        // The controller dies: the chair stays, uncontrolled, with zero powers.
        assert!(c.agent_died(agent));
        let b = c.sensor_block(id);
        assert_eq!((b.drive, b.drive_flags), ([0.0, 0.0], 0));
        assert_eq!(c.robot_count(), 1);
        // The operator's resume requests reach the adapter as a count, controlled or not.
        assert_eq!(c.command(Command::ResumeChair, id), 0);
        assert_eq!(c.command(Command::ResumeChair, id), 0);
        assert_eq!(ipc_types::drive_resumes(c.sensor_block(id).drive_flags), 2);
        assert_eq!(c.command(Command::ResumeChair, 99), 2, "no such robot");
        let chair = c.chair_states().next().expect("one chair");
        assert_eq!((chair.controller, chair.flags & CHAIR_CONTROLLED), (0, 0));
        assert_eq!(chair.ghost, [10.2, 6.0, 2.0]);
        // And a new controller may attach.
        let next = c.hello(4).expect("room");
        assert_eq!(c.register(next, &RobotRegistration::new("chair1")).expect("attached").0, id);
    }

    #[test]
    fn a_chairs_sensor_mode_picks_real_virtual_or_the_nearer_of_both() {
        let mut c = core(Mode::LockStep);
        c.set_real_names(["chair1".to_owned()]);
        let adapter = c.hello(1).expect("room");
        let agent = c.hello(2).expect("room");
        let id = c.register(adapter, &chair_reg("chair1", SensorMode::Augmented)).expect("a chair").0;
        c.register(agent, &RobotRegistration::new("chair1")).expect("attached");
        c.prime_sensors();
        let virtual_m = c.sensor_block(id).proximity_m;
        let v0 = virtual_m[0];
        assert!(v0 > 0.3 && v0 <= 3.0, "the corridor is in reach: {v0}");
        // Thesis §5.4.3's example, both ways round: the nearer reading wins.
        let mut real = [f32::NAN; MAX_PROXIMITY];
        real[0] = 0.3;
        real[1] = f32::INFINITY;
        c.actions(adapter, 0, &[report(id, 10.0, real)]);
        let b = c.sensor_block(id);
        assert_eq!(b.sensor_mode, SensorMode::Augmented as u32);
        assert_eq!(b.proximity_m[0], 0.3_f32 as f64, "real nearer than virtual");
        assert_eq!(b.proximity_m[1], virtual_m[1], "no echo: the virtual reading stands");
        assert_eq!(b.proximity_m[2], virtual_m[2], "no real reading yet: the virtual one");
        // A controller asking for real mode gets the chair's own readings only.
        let other = c.hello(3).expect("room");
        c.bye(agent);
        let mut reg = RobotRegistration::new("chair1");
        reg.flags |= ipc_types::REG_SENSORS_REAL;
        c.register(other, &reg).expect("attached");
        let b = c.sensor_block(id);
        assert_eq!(b.sensor_mode, SensorMode::Real as u32);
        assert_eq!(b.proximity_m[0], 0.3_f32 as f64);
        let range = c.world().params().proximity_range();
        assert_eq!(b.proximity_m[1], range, "no echo reads the sensor's range");
        assert_eq!(c.robot_count(), 1, "the controller leaving removed nothing");
        // A NaN report keeps the last real reading.
        c.actions(adapter, 0, &[report(id, 10.0, [f32::NAN; MAX_PROXIMITY])]);
        assert_eq!(c.sensor_block(id).proximity_m[0], 0.3_f32 as f64);
        // The adapter leaving takes the chair away, and its controller's block with it.
        c.bye(adapter);
        assert_eq!(c.robot_count(), 0);
        assert_eq!(c.agent_blocks(other).count(), 0);
    }

    #[test]
    fn a_chair_registration_must_be_a_real_robot_with_one_mode() {
        let mut c = core(Mode::LockStep);
        let adapter = c.hello(1).expect("room");
        // A Real robot (its pose pushed) only under a name the hub expects.
        let refused = c.register(adapter, &chair_reg("chair1", SensorMode::Real)).expect_err("not expected");
        assert_eq!(refused.reason, Refusal::NotAllowed);
        assert_eq!(refused.detail, "Real only as iwsim hub --real NAME, not \"chair1\"");
        assert!(refused.detail.len() <= 64, "it fits the answer's 64 bytes");
        c.set_real_names(["chair2".to_owned()]);
        let refused = c.register(adapter, &chair_reg("chair1", SensorMode::Real)).expect_err("another name");
        assert_eq!(refused.reason, Refusal::NotAllowed);
        c.set_real_names(["chair1".to_owned()]);
        let mut reg = chair_reg("chair1", SensorMode::Real);
        reg.kind = WireKind::Simulated as u32;
        assert_eq!(c.register(adapter, &reg).expect_err("not Real").reason, Refusal::BadParameters);
        let mut reg = chair_reg("chair1", SensorMode::Real);
        reg.flags |= ipc_types::REG_SENSORS_AUGMENTED;
        assert_eq!(c.register(adapter, &reg).expect_err("two modes").reason, Refusal::Malformed);
    }

    #[test]
    fn agents_drive_only_their_own_robots() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let b = c.hello(2).expect("room");
        let ra = c.register(a, &RobotRegistration::new("a")).expect("ok").0;
        assert_eq!(c.actions(b, 0, &[ActionBlock::motors(ra, 1.0, 1.0)]), 1);
        c.command(Command::Start, 0);
        c.step();
        assert_eq!(c.robot_states().next().expect("one").motor_out, [0.0, 0.0]);
    }

    #[test]
    fn sensor_blocks_carry_readings_and_messages_with_speaker_ids() {
        let mut c = core(Mode::LockStep);
        let a = c.hello(1).expect("room");
        let r1 = c.register(a, &RobotRegistration::new("a")).expect("ok").0;
        let r2 = c.register(a, &RobotRegistration::new("b")).expect("ok").0;
        c.command(Command::Start, 0);
        let mut say = ActionBlock::motors(r1, 0.0, 0.0);
        assert!(say.with_say(b"go first"));
        c.actions(a, 0, &[say]);
        c.step();
        let b = c.sensor_block(r2);
        assert_eq!((b.tick, b.robot_id, b.proximity_count), (1, r2, 4));
        assert!(b.present & HAS_COMPASS != 0);
        let heard: Vec<_> = b.messages().collect();
        assert_eq!(heard, vec![(r1, &b"go first"[..])]);
        // Where robot 2 is, only observers learn: grid slot 2 of LIACC.
        assert_eq!(c.robot_states().find(|s| s.id == r2).map(|s| s.x_m), Some(14.0));
    }

    #[test]
    fn the_first_step_orders_robots_by_id_whatever_the_registration_order() {
        let run = |first_b: bool| {
            let mut c = core(Mode::LockStep);
            let params = Params::default(); // noise on: slot order decides the draws
            c = HubCore::new(c.world().lab(), c.grid.clone(), params, 5, Mode::LockStep, 0).expect("valid");
            let a = c.hello(1).expect("room");
            let b = c.hello(2).expect("room");
            let mut ra = RobotRegistration::new("a");
            ra.requested_id = 1;
            let mut rb = RobotRegistration::new("b");
            rb.requested_id = 2;
            if first_b {
                c.register(b, &rb).expect("ok");
                c.register(a, &ra).expect("ok");
            } else {
                c.register(a, &ra).expect("ok");
                c.register(b, &rb).expect("ok");
            }
            c.command(Command::Start, 0);
            for t in 0..20 {
                c.actions(a, t, &[ActionBlock::motors(1, 0.9, 0.4)]);
                c.actions(b, t, &[ActionBlock::motors(2, 0.2, 0.8)]);
                c.step();
            }
            c.world().state_hash()
        };
        assert_eq!(run(false), run(true));
    }

    #[test]
    fn commands_drive_the_run_state() {
        let mut c = core(Mode::RealTime);
        assert!(!c.may_step());
        assert_eq!(c.command(Command::Step, 0), 0);
        assert!(c.may_step());
        c.step();
        assert!(!c.may_step(), "one step only");
        assert_eq!(c.world().tick(), 1);
        c.command(Command::Start, 0);
        assert_eq!(c.command(Command::Pause, 0), 0);
        assert_eq!(c.state(), RunState::Paused);
        assert_eq!(c.command(Command::RemoveRobot, 42), 2);
        let agent = c.hello(7).expect("room");
        let (robot, _) = c.register(agent, &RobotRegistration::new("r1")).expect("registered");
        assert_eq!(c.command(Command::ResumeChair, robot), 3, "a simulated robot has no latch to resume");
        c.command(Command::Stop, 0);
        assert_eq!(c.state(), RunState::Finished);
        assert!(!c.may_step());
    }

    #[test]
    fn the_map_lists_every_wall_corner_and_grid_slot() {
        let c = core(Mode::RealTime);
        let (h, items) = c.map_items(100, 1000, MapAudience::Observers);
        assert_eq!((h.wall_count, h.grid_count), (23, 9));
        assert_eq!(items.iter().filter(|i| i.kind == MAP_CORNER).count(), 92);
        assert_eq!(h.item_count as usize, items.len());
        assert_eq!(h.name.as_str(), Some("IW_LIACC"));
    }

    #[test]
    fn agents_get_the_map_without_the_scenarios_obstacles() {
        let mut c = core(Mode::RealTime);
        c.set_scenario(20, Vec::new());
        let walls = |audience| {
            let (h, items) = c.map_items(100, 1000, audience);
            let flagged = items.iter().filter(|i| i.kind == MAP_WALL && i.c != 0.0).count();
            (h.wall_count, flagged)
        };
        assert_eq!(walls(MapAudience::Observers), (23, 3));
        assert_eq!(walls(MapAudience::Agents), (20, 0));
    }
}
