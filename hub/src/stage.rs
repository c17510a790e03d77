//! The world and its robots by id: every change the hub makes to its world goes through a
//! [`Stage`], which journals it when the run is recorded. Replaying a recording applies the
//! journal to a fresh `Stage` ([`Stage::apply`]), so a live run and its replay share one
//! definition of every change, and their state hashes agree tick for tick.

use std::collections::BTreeMap;

use ipc_types::MAX_ROBOTS;
use recorder::journal::{Event, RecordedAction};
use run_records::outcome::{HubOutcome, RobotAtEnd, ScoreAtEnd, StateHash};
use world::challenge::{Challenge, Standing, Turn};
use world::map::{Lab, Params};
use world::{
    Action, AddRobotError, BodyShape, Message, Robot, RobotHandle, RobotSpec, StepStats, World, WorldBuildError,
};

/// Why a journal event could not be applied to a stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageApplyError {
    /// A robot the journal adds was refused by the world (the recording does not belong to
    /// this version of iwsim, or it was altered).
    #[error("robot {id} cannot be added again: {reason}")]
    AddRefused {
        /// Robot id.
        id: u32,
        /// The world's refusal.
        reason: String,
    },
    /// A step's state hash differs from the recorded one.
    #[error("tick {tick}: state hash {replayed:016x} differs from the recorded {recorded:016x}")]
    HashDiffers {
        /// The tick the step ended on.
        tick: u64,
        /// The hash the recording holds.
        recorded: u64,
        /// The hash the replay computed.
        replayed: u64,
    },
    /// A step names a tick other than the world's.
    #[error("the journal steps from tick {recorded} but the replayed world is at tick {replayed}")]
    TickOutOfOrder {
        /// The tick the journal names.
        recorded: u64,
        /// The world's tick.
        replayed: u64,
    },
}

/// The world, its robots by id, and the journal of changes.
#[derive(Debug)]
pub struct Stage {
    world: World,
    seed: u64,
    dt_s: f64,
    handles: BTreeMap<u32, RobotHandle>,
    /// Robot id by world slot index (0: none), for message senders.
    id_by_slot: Vec<u32>,
    settled: bool,
    /// `Some` while recording: the changes since the last [`Stage::take_journal`].
    journal: Option<Vec<Event>>,
    /// Scratch for the world's actions of a step.
    scratch: Vec<Action>,
    /// The Ciber-Rato challenge every robot is scored in: a rule on the world's outcome, so a
    /// replay of the journal scores it again, identically.
    challenge: Challenge,
    /// Scratch for the challenge's view of a step.
    turns: Vec<Turn>,
    /// Scratch: this step's LEDs by world slot.
    leds: Vec<Option<u32>>,
}

impl Stage {
    /// The world as `iwsim hub --json` reports a run's end.
    pub fn outcome(&self) -> HubOutcome {
        let w = self.world();
        let robots = self
            .ids()
            .filter_map(|id| {
                let r = self.robot(id)?;
                let flags = (r.collision as u32 * ipc_types::ROBOT_COLLISION)
                    | (self.frozen_without_agent(id) as u32 * ipc_types::ROBOT_FROZEN);
                Some(RobotAtEnd { id, x_m: r.pose.x, y_m: r.pose.y, heading_deg: r.pose.heading_deg(), flags })
            })
            .collect();
        HubOutcome {
            ticks: w.tick(),
            state_hash: StateHash(w.state_hash()),
            robots,
            scoring: self.challenge().scoring().number(),
            scores: self.scores(),
            ..HubOutcome::default()
        }
    }

    /// An empty world on `lab` with `params`, seeded with `seed`; a tick lasts `cycle_ms`, and
    /// the run lasts `tick_limit` ticks (0: no limit; the challenge's time rule reads it).
    pub fn new(lab: &Lab, params: Params, seed: u64, tick_limit: u64) -> Result<Self, WorldBuildError> {
        let dt_s = params.cycle_ms.max(1) as f64 / 1000.0;
        let challenge = Challenge::new(lab, params.challenge.scoring, params.challenge, tick_limit);
        let mut world = World::new(lab, params, seed)?;
        world.set_capacity(MAX_ROBOTS);
        Ok(Self {
            world,
            seed,
            dt_s,
            handles: BTreeMap::new(),
            id_by_slot: Vec::new(),
            settled: false,
            journal: None,
            scratch: Vec::new(),
            challenge,
            turns: Vec::new(),
            leds: Vec::new(),
        })
    }

    /// The challenge the robots are scored in.
    pub fn challenge(&self) -> &Challenge {
        &self.challenge
    }

    /// Robot `id`'s standing in the challenge.
    pub fn standing(&self, id: u32) -> Option<Standing> {
        self.challenge.standing(id)
    }

    /// Whether robot `id` is frozen because its agent is gone (not because it finished its
    /// challenge, which also stops it).
    pub fn frozen_without_agent(&self, id: u32) -> bool {
        self.robot(id).is_some_and(|r| r.frozen) && !self.challenge.finished(id)
    }

    /// Every robot's standing as the run's final table gives it, in id order.
    pub fn scores(&self) -> Vec<ScoreAtEnd> {
        let targets = self.world.lab().targets.len();
        self.challenge
            .standings()
            .map(|(id, s)| ScoreAtEnd {
                id,
                name: self.robot(id).map(|r| r.spec.name.clone()).unwrap_or_default(),
                state: s.phase.wire_name().to_owned(),
                score: s.score,
                arrival_tick: s.arrival_tick,
                returning_ticks: s.returning_ticks,
                collisions: s.collisions,
                visited: (0..targets).map(|k| if k < 64 && s.visited >> k & 1 == 1 { '1' } else { '0' }).collect(),
            })
            .collect()
    }

    /// Lets the world's step use `threads` threads (0: one per core) from `parallel_min_robots`
    /// robots on; returns the threads it will use.
    pub fn set_threads(&mut self, threads: usize, parallel_min_robots: usize) -> usize {
        self.world.set_parallel_min_robots(parallel_min_robots);
        self.world.set_threads(threads)
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Simulated seconds per tick.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Robot `id`, if it is in the world.
    pub fn robot(&self, id: u32) -> Option<&Robot> {
        self.world.robot(*self.handles.get(&id)?)
    }

    /// The id of the robot in world slot `handle` (0 if none).
    pub fn id_of(&self, handle: RobotHandle) -> u32 {
        self.id_by_slot.get(handle.index() as usize).copied().unwrap_or(0)
    }

    /// Starts journaling every change (see [`Stage::take_journal`]).
    pub fn record(&mut self) {
        self.journal.get_or_insert_with(Vec::new);
    }

    /// The changes since the last call, oldest first (none unless recording).
    pub fn take_journal(&mut self, into: &mut Vec<Event>) {
        if let Some(j) = &mut self.journal {
            into.append(j);
        }
    }

    fn journal(&mut self, event: impl FnOnce() -> Event) {
        if let Some(j) = &mut self.journal {
            j.push(event());
        }
    }

    fn place(&mut self, id: u32, handle: RobotHandle) {
        let slot = handle.index() as usize;
        if self.id_by_slot.len() <= slot {
            self.id_by_slot.resize(slot + 1, 0);
        }
        self.id_by_slot[slot] = id;
        self.handles.insert(id, handle);
    }

    /// Adds robot `id` of agent `agent_id`.
    pub fn add(&mut self, id: u32, agent_id: u32, spec: RobotSpec) -> Result<(), AddRobotError> {
        let recorded = self.journal.is_some().then(|| spec.clone());
        let (home, half) = ((spec.pose.x, spec.pose.y), half_size(&spec));
        let handle = self.world.add_robot(spec)?;
        self.place(id, handle);
        self.challenge.add(id, home, half);
        if let Some(spec) = recorded {
            self.journal(|| Event::AddRobot { id, agent_id, spec });
        }
        Ok(())
    }

    /// Removes robot `id`; whether it was there.
    pub fn remove(&mut self, id: u32) -> bool {
        let Some(handle) = self.handles.remove(&id) else { return false };
        self.world.remove_robot(handle);
        self.challenge.remove(id);
        if let Some(slot) = self.id_by_slot.get_mut(handle.index() as usize) {
            *slot = 0;
        }
        self.journal(|| Event::RemoveRobot { id });
        true
    }

    /// Freezes or thaws robot `id`; whether it is there. A robot that finished its challenge
    /// stays frozen.
    pub fn set_frozen(&mut self, id: u32, frozen: bool) -> bool {
        let Some(&handle) = self.handles.get(&id) else { return false };
        self.world.set_frozen(handle, frozen || self.challenge.finished(id));
        self.journal(|| Event::Freeze { id, frozen });
        true
    }

    /// Measures every robot where it stands, without noise (before the first step).
    pub fn refresh_sensors(&mut self) {
        self.world.refresh_sensors();
    }

    /// Rebuilds the world with its robots added in name order (id order among equal names):
    /// registrations arrive in whatever order the agents' processes run, and the world's slot
    /// order fixes the order of every random draw, so without this two runs with one seed
    /// could differ. Names, not ids, because ids given out on request (id 0) also follow the
    /// order in which agents happened to register.
    fn settle(&mut self) {
        self.settled = true;
        let Ok(mut world) = World::new(self.world.lab(), self.world.params().clone(), self.seed) else {
            return; // the same lab and parameters built once already
        };
        world.set_capacity(MAX_ROBOTS);
        world.use_threads_of(&self.world);
        let mut order: Vec<(String, u32)> =
            self.handles.iter().filter_map(|(&id, &h)| Some((self.world.robot(h)?.spec.name.clone(), id))).collect();
        order.sort();
        let old = std::mem::take(&mut self.handles);
        self.id_by_slot.clear();
        for (_, id) in order {
            let Some(r) = old.get(&id).and_then(|&h| self.world.robot(h)) else { continue };
            let spec = RobotSpec { pose: r.pose, ..r.spec.clone() };
            let frozen = r.frozen;
            let Ok(handle) = world.add_robot(spec) else { continue };
            world.set_frozen(handle, frozen);
            self.place(id, handle);
        }
        self.world = world;
        self.journal(|| Event::Settle);
    }

    /// Steps the world once with `actions` (by robot id; unknown ids are skipped), settling
    /// the slots first if this is the first step.
    pub fn step(&mut self, actions: &[RecordedAction]) -> StepStats {
        if self.world.tick() == 0 && !self.settled {
            self.settle();
        }
        let tick = self.world.tick();
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        // Each robot's LEDs of this step by world slot (the last action of a robot counts),
        // for the challenge: read back beside the robots, no search per robot.
        let mut leds = std::mem::take(&mut self.leds);
        leds.clear();
        leds.resize(self.id_by_slot.len(), None);
        scratch.extend(actions.iter().filter_map(|a| {
            let robot = *self.handles.get(&a.id)?;
            if let Some(slot) = leds.get_mut(robot.index() as usize) {
                *slot = Some(a.leds);
            }
            Some(Action {
                robot,
                motors: a.motors,
                pose: a.pose,
                say: a.say.as_deref().and_then(|b| Message::new(b).ok()),
            })
        }));
        let stats = self.world.step(&scratch, self.dt_s);
        self.scratch = scratch;
        self.score(&leds);
        self.leds = leds;
        if self.journal.is_some() {
            let hash = self.world.state_hash();
            self.journal(|| Event::Step { tick, actions: actions.to_vec(), hash });
        }
        stats
    }

    /// Scores the step just taken with each robot's LEDs of the step by world slot, and
    /// stops the robots that finished.
    fn score(&mut self, leds: &[Option<u32>]) {
        let mut turns = std::mem::take(&mut self.turns);
        turns.clear();
        for (&id, &h) in &self.handles {
            let Some(r) = self.world.robot(h) else { continue };
            let led = leds.get(h.index() as usize).copied().flatten();
            turns.push(Turn { id, pose: r.pose, hit_wall: r.collision_wall, hit_robot: r.collision_robot, leds: led });
        }
        let world = &self.world;
        for id in self.challenge.update(world.tick(), &turns, |a, b| world.segment_clear(a, b)) {
            if let Some(&h) = self.handles.get(&id) {
                self.world.set_frozen(h, true);
            }
        }
        self.turns = turns;
    }

    /// The robots' ids, in id order.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.handles.keys().copied()
    }

    /// Applies one recorded event, checking a step's hash against the recorded one when
    /// `check` is set. Returns the tick a step ended on.
    pub fn apply(&mut self, event: &Event, check: bool) -> Result<Option<u64>, StageApplyError> {
        match event {
            Event::AddRobot { id, agent_id, spec } => self
                .add(*id, *agent_id, spec.clone())
                .map_err(|e| StageApplyError::AddRefused { id: *id, reason: e.to_string() })?,
            Event::RemoveRobot { id } => {
                self.remove(*id);
            }
            Event::Freeze { id, frozen } => {
                self.set_frozen(*id, *frozen);
            }
            Event::Settle => {
                if !self.settled {
                    self.settle();
                }
            }
            Event::Step { tick, actions, hash } => {
                if *tick != self.world.tick() {
                    return Err(StageApplyError::TickOutOfOrder { recorded: *tick, replayed: self.world.tick() });
                }
                self.step(actions);
                if !check {
                    return Ok(Some(self.world.tick()));
                }
                let replayed = self.world.state_hash();
                if replayed != *hash {
                    return Err(StageApplyError::HashDiffers { tick: self.world.tick(), recorded: *hash, replayed });
                }
                return Ok(Some(self.world.tick()));
            }
            Event::Finish { .. } => {}
        }
        Ok(None)
    }
}

/// A robot's half size, which Ciber-Rato's target rule subtracts from a target's radius: a
/// disc's radius, a rectangle's half width across (its smaller side).
fn half_size(spec: &RobotSpec) -> f64 {
    match spec.shape {
        BodyShape::Disc => spec.width_m / 2.0,
        BodyShape::Rectangle => spec.width_m.min(spec.height_m) / 2.0,
    }
}
