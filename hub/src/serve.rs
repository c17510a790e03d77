//! `iwsim replay FILE --serve`: plays a recording as a live session, so the viewer (`iwsim
//! view`), the UDP bridge's Ciber-Rato viewers and any other observer watch a recorded run as
//! they would watch the hub that ran it.
//!
//! The session's services are created exactly as a hub creates them (so a replay refuses a
//! session a hub already serves, and a hub refuses one a replay serves). A [`Player`] rebuilds
//! the world from the recording's journal one tick at a time, and the loop publishes what the
//! hub published: both maps (the agents' without the scenario's obstacles, the observers' with
//! them), a world snapshot per tick paced at the recorded cycle divided by the speed, the tick
//! doorbell, and the robots' sensor geometry whenever the set of robots changes. Agents may say
//! hello (the UDP bridge does), but every robot registration is refused with
//! [`Refusal::RunStarted`]: a recorded world takes no new robots. Run control works as on the
//! hub: Pause, Start (resume), Step (one tick while paused or waiting), Stop (end).
//!
//! At the end of the recording (or `--until`, or a Stop) the replay publishes the `Finished`
//! run state, as a hub does at its tick limit, so viewers and the bridge end too; it then waits
//! up to 2 s for its observers and agents to read it and leave, and exits. With `--loop` it
//! starts over from tick 0 instead of finishing.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use ipc_services::ServicesError;
use ipc_types::{
    ActionBlock, Command, MAX_AGENTS, MapHeader, MapItem, Refusal, RobotInfo, RobotRegistration, RobotState, RunState,
    WorldHeader,
};
use recorder::Recording;
use recorder::journal::Event;
use world::WorldBuildError;

use crate::core::{MapAudience, Mode, Refused, hub_params, pack_map_for, robot_info, robot_state};
use crate::server::{Host, IDLE_POLL, Server};
use crate::stage::{Stage, StageApplyError};
use crate::{HubError, HubOutcome};

/// How to serve a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct ServeOptions {
    /// Session name: the replay's services live under `iwsim/<session>/`.
    pub session: String,
    /// Playback rate: 1 plays a tick per recorded cycle, 2 twice as fast. Above 0.
    pub speed: f64,
    /// Start over from tick 0 at the end instead of finishing.
    pub looped: bool,
    /// Wait for a Start (or Step) command before the first tick.
    pub start_on_command: bool,
    /// Compare every tick's state hash with the recording's; the first that differs ends it.
    pub check: bool,
    /// End after the step that reaches this tick.
    pub until: Option<u64>,
}

/// Why a replay could not be served.
#[derive(Debug, thiserror::Error)]
pub enum ReplayServeError {
    /// A service could not be set up (another hub or replay serves the session, a bad name).
    #[error(transparent)]
    Services(#[from] ServicesError),
    /// The recorded lab or parameters no longer build a world.
    #[error("rebuilding the recorded world: {0}")]
    World(#[from] WorldBuildError),
    /// The recording's tick length disagrees with the one its parameters give.
    #[error("the recording steps {recorded} s a tick but its parameters give {rebuilt} s")]
    CycleDiffers {
        /// The recording's seconds per tick.
        recorded: f64,
        /// The rebuilt world's.
        rebuilt: f64,
    },
    /// The journal cannot be applied (a robot refused, ticks out of order).
    #[error(transparent)]
    Journal(StageApplyError),
    /// The playback rate is not above 0.
    #[error("the speed must be a number above 0, not {0}")]
    BadSpeed(f64),
    /// iceoryx2 failed while serving.
    #[error("iceoryx2 failed to {0}")]
    Ipc(String),
}

impl From<HubError> for ReplayServeError {
    fn from(e: HubError) -> Self {
        match e {
            HubError::Services(e) => Self::Services(e),
            HubError::World(e) => Self::World(e),
            HubError::Ipc(what) => Self::Ipc(what),
            e => Self::Ipc(e.to_string()),
        }
    }
}

/// A recording played tick by tick, with the hub's run states and commands, and no I/O: the
/// serving loop asks it what to publish.
#[derive(Debug)]
pub struct Player<'a> {
    recording: &'a Recording,
    stage: Stage,
    /// The agent id each robot was registered by, as recorded.
    owners: BTreeMap<u32, u32>,
    /// The next journal event to apply.
    next: usize,
    state: RunState,
    single_steps: u32,
    check: bool,
    until: Option<u64>,
    looped: bool,
    steps: u64,
    mismatch: Option<StageApplyError>,
    /// Agents attached to the replay (they watch: a recorded world takes no robots).
    agents: BTreeSet<u32>,
    next_agent_id: u32,
}

impl<'a> Player<'a> {
    /// The recording at tick 0 (its robots added): `Waiting` when `start_on_command`,
    /// otherwise `Running`.
    pub fn new(recording: &'a Recording, options: &ServeOptions) -> Result<Self, ReplayServeError> {
        let mut p = Self {
            recording,
            stage: Self::fresh_stage(recording)?,
            owners: BTreeMap::new(),
            next: 0,
            state: if options.start_on_command { RunState::Waiting } else { RunState::Running },
            single_steps: 0,
            check: options.check,
            until: options.until,
            looped: options.looped,
            steps: 0,
            mismatch: None,
            agents: BTreeSet::new(),
            next_agent_id: 1,
        };
        p.apply_changes()?;
        Ok(p)
    }

    fn fresh_stage(recording: &Recording) -> Result<Stage, ReplayServeError> {
        let start = &recording.start;
        let stage = Stage::new(&start.lab, start.params.clone(), start.seed, start.tick_limit)?;
        if stage.dt_s() != start.dt_s {
            return Err(ReplayServeError::CycleDiffers { recorded: start.dt_s, rebuilt: stage.dt_s() });
        }
        Ok(stage)
    }

    /// Applies the changes up to the next step (robots added, removed, frozen): the hub
    /// published each such change at once, so they show with the tick they happened in.
    fn apply_changes(&mut self) -> Result<(), ReplayServeError> {
        while let Some(event) = self.recording.events.get(self.next) {
            match event {
                Event::Step { .. } | Event::Finish { .. } => break,
                Event::AddRobot { id, agent_id, .. } => {
                    self.owners.insert(*id, *agent_id);
                }
                Event::RemoveRobot { id } => {
                    self.owners.remove(id);
                }
                Event::Freeze { .. } | Event::Settle => {}
            }
            self.stage.apply(event, false).map_err(ReplayServeError::Journal)?;
            self.next += 1;
        }
        if self.stage.world().tick() == 0 {
            // What the hub published before its first step: every robot measured where it
            // stands (the journal leaves this out: it changes nothing a step depends on).
            self.stage.refresh_sensors();
        }
        Ok(())
    }

    /// Whether the recording has a step left to play (within `until`).
    fn step_left(&self) -> bool {
        match self.recording.events.get(self.next) {
            Some(Event::Step { tick, .. }) => self.until.is_none_or(|u| *tick < u),
            _ => false,
        }
    }

    /// Whether the loop should step now (the caller adds the pacing).
    pub fn may_step(&self) -> bool {
        self.state == RunState::Running || (self.state != RunState::Finished && self.single_steps > 0)
    }

    /// Plays one tick: its step and the changes that followed it. At the end of the recording
    /// the run finishes, or starts over from tick 0 when looping.
    pub fn step(&mut self) -> Result<(), ReplayServeError> {
        if self.state != RunState::Running {
            self.single_steps = self.single_steps.saturating_sub(1);
        }
        let Some(event) = self.recording.events.get(self.next).filter(|_| self.step_left()) else {
            // Only a looping replay gets here after its last tick (and one with no step at
            // all): the last tick has been shown for a tick, now start over.
            if self.looped && self.steps > 0 {
                self.stage = Self::fresh_stage(self.recording)?;
                self.owners.clear();
                self.next = 0;
                self.apply_changes()?;
            } else {
                self.state = RunState::Finished;
            }
            return Ok(());
        };
        self.next += 1;
        match self.stage.apply(event, self.check) {
            Ok(_) => self.steps += 1,
            Err(e @ StageApplyError::HashDiffers { .. }) => {
                self.steps += 1;
                self.mismatch = Some(e);
                self.state = RunState::Finished;
                return Ok(());
            }
            Err(e) => return Err(ReplayServeError::Journal(e)),
        }
        self.apply_changes()?;
        if !self.step_left() && !self.looped {
            self.state = RunState::Finished;
        }
        Ok(())
    }

    /// Applies a run-control command as the hub does; returns 0 when done, 3 when the command
    /// makes no sense now (removing a recorded robot is one).
    pub fn command(&mut self, command: Command) -> u32 {
        match command {
            Command::Start if self.state != RunState::Finished => self.state = RunState::Running,
            Command::Pause if self.state == RunState::Running => self.state = RunState::Paused,
            Command::Step if self.state != RunState::Finished && self.state != RunState::Running => {
                self.single_steps += 1
            }
            Command::Stop => self.state = RunState::Finished,
            _ => return 3,
        }
        0
    }

    /// The run state.
    pub fn state(&self) -> RunState {
        self.state
    }

    /// The replayed world and its robots.
    pub fn stage(&self) -> &Stage {
        &self.stage
    }

    /// Steps played (counting every lap when looping).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The first step whose state hash differs from the recording's (when checking).
    pub fn mismatch(&self) -> Option<&StageApplyError> {
        self.mismatch.as_ref()
    }

    /// The world header of the current tick; `agent_count` is the agents attached to the
    /// replay (the recorded ones are long gone).
    pub fn world_header(&self, agent_count: usize) -> WorldHeader {
        let w = self.stage.world();
        WorldHeader {
            tick: w.tick(),
            sim_time_s: w.time_s(),
            state_hash: w.state_hash(),
            run_state: self.state as u32,
            robot_count: self.stage.ids().count() as u32,
            agent_count: agent_count as u32,
            lockstep: self.recording.start.lockstep as u32,
        }
    }

    /// Every robot's state as the hub published it, in id order (no robot is lagging: the
    /// recording keeps what the agents did, not how late they were).
    pub fn robot_states(&self) -> impl Iterator<Item = RobotState> + '_ {
        self.stage.ids().filter_map(|id| {
            let r = self.stage.robot(id)?;
            Some(robot_state(
                r,
                id,
                self.owners.get(&id).copied().unwrap_or(0),
                false,
                self.stage.standing(id),
                self.state,
            ))
        })
    }

    /// How many robots [`Player::robot_states`] yields.
    pub fn robot_count(&self) -> usize {
        self.stage.ids().filter(|&id| self.stage.robot(id).is_some()).count()
    }

    /// Every robot's proximity-sensor geometry, in id order.
    pub fn robot_info(&self) -> impl Iterator<Item = RobotInfo> + '_ {
        let range = self.stage.world().params().proximity_range();
        self.stage.ids().filter_map(move |id| Some(robot_info(self.stage.robot(id)?, id, range)))
    }

    /// The map for `audience` as the recorded hub published it, its start grid included.
    pub fn map_items(&self, audience: MapAudience) -> (MapHeader, Vec<MapItem>) {
        let s = &self.recording.start;
        let mode = if s.lockstep { Mode::LockStep } else { Mode::RealTime };
        let params = hub_params(&s.params, mode, s.tick_limit, s.deadline_ms);
        pack_map_for(audience, &s.lab, &s.grid, s.obstacle_from, &s.checkpoints, s.cycle_ms, params)
    }
}

/// How a served replay ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Served {
    /// Steps played.
    pub steps: u64,
    /// The world shown last, as `iwsim hub --json` reports a run's end (`interrupted` when
    /// SIGINT or SIGTERM ended it).
    pub outcome: HubOutcome,
    /// The first step whose hash differs (when checking).
    pub mismatch: Option<StageApplyError>,
    /// Agents that said hello.
    pub agents_seen: u64,
    /// Robot registrations refused.
    pub robots_refused: u64,
}

/// The longest a tick lasts, whatever the speed (a speed near 0 would otherwise overflow the
/// clock).
const LONGEST_TICK: Duration = Duration::from_secs(86_400);

/// Serves `recording` as session `options.session` until its end, a Stop command, or
/// SIGINT/SIGTERM.
pub fn serve(recording: &Recording, options: &ServeOptions) -> Result<Served, ReplayServeError> {
    if !(options.speed > 0.0 && options.speed.is_finite()) {
        return Err(ReplayServeError::BadSpeed(options.speed));
    }
    let mut player = Player::new(recording, options)?;
    let cycle_s = recording.start.cycle_ms.max(1) as f64 / 1000.0;
    let period = Duration::try_from_secs_f64(cycle_s / options.speed).unwrap_or(LONGEST_TICK).min(LONGEST_TICK);
    // Both maps are kept for late subscribers, like the hub's; nobody's actions move a recorded
    // robot, but agents wait for the actions subscriber to exist.
    let mut server = Server::open(
        &options.session,
        player.map_items(MapAudience::Agents),
        player.map_items(MapAudience::Observers),
    )?;
    let mut interrupted = false;
    let mut next_tick_at = Instant::now() + period;
    let mut publish = true;

    tracing::info!(
        "replaying {} ticks of lab {:?} on session {} at {}x",
        recording.events.iter().filter(|e| matches!(e, Event::Step { .. })).count(),
        recording.start.lab.name,
        options.session,
        options.speed
    );
    loop {
        if server.stop_requested() {
            interrupted = true;
            player.command(Command::Stop);
            publish = true;
        }
        if publish {
            publish = false;
            let header = player.world_header(server.agent_count());
            server.publish_world(header, player.robot_count(), player.robot_states(), || player.robot_info(), None)?;
            // The agents have no robots here: they hear only the end.
            server.publish_blocks(&header, 0, false, |_| std::iter::empty())?;
            server.ring()?;
            if player.state() == RunState::Finished {
                break;
            }
        }

        let timeout = if !player.may_step() {
            IDLE_POLL
        } else if player.state() == RunState::Running {
            next_tick_at.saturating_duration_since(Instant::now())
        } else {
            Duration::ZERO // a single step is due at once
        }
        .min(IDLE_POLL);
        server.accept(timeout, &mut player);
        server.admit(&mut player)?;
        let before = player.state();
        publish |= server.control(&mut player)?;
        if before != RunState::Running && player.state() == RunState::Running {
            next_tick_at = Instant::now() + period;
        }
        // Drained so a sender's queue never fills; a recorded world takes no actions.
        server.collect(&mut player)?;

        if player.may_step() {
            let now = Instant::now();
            let due = player.state() != RunState::Running || now >= next_tick_at;
            if due {
                player.step()?;
                publish = true;
                if player.state() == RunState::Running {
                    next_tick_at += period;
                    if next_tick_at < now {
                        next_tick_at = now + period; // fell behind: do not try to catch up
                    }
                }
            }
        }
    }

    // Observers and agents read the last tick from this process's shared memory.
    server.linger(true);
    let counts = server.counts();
    drop(server);
    Ok(Served {
        steps: player.steps(),
        outcome: HubOutcome { interrupted, ..player.stage().outcome() },
        mismatch: player.mismatch().cloned(),
        agents_seen: counts.agents_seen as u64,
        robots_refused: counts.robots_refused,
    })
}

/// A recorded world behind the server: agents may attach and watch, but it takes no robots
/// and no actions.
impl Host for Player<'_> {
    fn tick(&self) -> u64 {
        self.stage.world().tick()
    }

    fn run_state(&self) -> RunState {
        self.state
    }

    fn hello(&mut self, _pid: u32) -> Result<u32, Refused> {
        if self.agents.len() >= MAX_AGENTS {
            return Err(Refused::new(Refusal::Capacity, format!("the replay serves at most {MAX_AGENTS} agents")));
        }
        let id = self.next_agent_id;
        self.next_agent_id += 1;
        self.agents.insert(id);
        Ok(id)
    }

    fn register(&mut self, _agent: u32, _robot: &RobotRegistration) -> Result<(u32, u32), Refused> {
        Err(Refused::new(Refusal::RunStarted, "a replay takes no robots"))
    }

    fn ready(&mut self, agent: u32) -> Result<(), Refused> {
        if self.agents.contains(&agent) {
            Ok(())
        } else {
            Err(Refused::new(Refusal::UnknownAgent, format!("agent {agent} is unknown")))
        }
    }

    fn bye(&mut self, agent: u32) {
        self.agents.remove(&agent);
    }

    fn exited(&mut self, agent: u32) -> bool {
        tracing::info!("agent {agent} exited");
        self.agents.remove(&agent);
        false
    }

    fn command(&mut self, command: Command, _robot: u32) -> u32 {
        Player::command(self, command)
    }

    fn actions(&mut self, _agent: u32, _tick: u64, blocks: &[ActionBlock]) -> usize {
        blocks.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::HubCore;
    use ipc_types::{ActionBlock, RobotRegistration};
    use world::map::{Params, builtin};

    /// A 20-tick lock-step run of two robots, recorded, and the hub that ran it.
    fn recorded_run() -> (Recording, HubCore) {
        let map = builtin::map("liacc").expect("built in");
        let mut core = HubCore::new(&map.lab, map.grid, Params::default(), 7, Mode::LockStep, 20).expect("valid");
        core.record();
        let start = core.run_start(1000);
        let a = core.hello(1).expect("room");
        let r1 = core.register(a, &RobotRegistration::new("left")).expect("ok").0;
        let r2 = core.register(a, &RobotRegistration::new("right")).expect("ok").0;
        core.command(Command::Start, 0);
        for t in 0..20 {
            core.actions(a, t, &[ActionBlock::motors(r1, 0.5, 0.4), ActionBlock::motors(r2, 0.3, 0.3)]);
            core.step();
        }
        let mut events = Vec::new();
        core.take_journal(&mut events);
        events.push(Event::Finish { tick: 20, reason: "finished".into() });
        let recording = Recording { start, events, truncated: None, metadata: Default::default() };
        (recording, core)
    }

    fn options() -> ServeOptions {
        ServeOptions {
            session: "unused".into(),
            speed: 1.0,
            looped: false,
            start_on_command: false,
            check: true,
            until: None,
        }
    }

    #[test]
    fn a_played_recording_shows_the_hubs_snapshots_bit_for_bit_and_then_finishes() {
        let (recording, hub) = recorded_run();
        let mut p = Player::new(&recording, &options()).expect("plays");
        assert_eq!(p.robot_states().count(), 2, "the robots are there at tick 0");
        while p.state() != RunState::Finished {
            p.step().expect("applies");
        }
        assert_eq!((p.steps(), p.mismatch()), (20, None));
        let played: Vec<RobotState> = p.robot_states().collect();
        let live: Vec<RobotState> = hub.robot_states().collect();
        assert_eq!(bytemuck::cast_slice::<_, u8>(&played), bytemuck::cast_slice::<_, u8>(&live));
        assert_eq!(p.world_header(0).state_hash, hub.world_header().state_hash);
        let sensors: Vec<RobotInfo> = p.robot_info().collect();
        assert_eq!(
            bytemuck::cast_slice::<_, u8>(&sensors),
            bytemuck::cast_slice::<_, u8>(&hub.robot_info().collect::<Vec<_>>())
        );
    }

    #[test]
    fn commands_pause_resume_single_step_and_stop_a_replay() {
        let (recording, _) = recorded_run();
        let mut p = Player::new(&recording, &ServeOptions { start_on_command: true, ..options() }).expect("plays");
        assert_eq!(p.state(), RunState::Waiting);
        assert!(!p.may_step());
        assert_eq!(p.command(Command::Step), 0);
        assert!(p.may_step());
        p.step().expect("applies");
        assert!(!p.may_step(), "one step only");
        assert_eq!(p.stage().world().tick(), 1);
        p.command(Command::Start);
        assert_eq!(p.command(Command::Pause), 0);
        assert_eq!(p.state(), RunState::Paused);
        assert_eq!(p.command(Command::RemoveRobot), 3, "a recorded robot stays");
        p.command(Command::Stop);
        assert_eq!(p.state(), RunState::Finished);
        assert!(!p.may_step());
    }

    #[test]
    fn until_ends_early_and_loop_starts_over() {
        let (recording, _) = recorded_run();
        let mut p = Player::new(&recording, &ServeOptions { until: Some(5), ..options() }).expect("plays");
        while p.state() != RunState::Finished {
            p.step().expect("applies");
        }
        assert_eq!(p.stage().world().tick(), 5);

        let mut p = Player::new(&recording, &ServeOptions { looped: true, ..options() }).expect("plays");
        for _ in 0..20 {
            p.step().expect("applies");
        }
        assert_eq!((p.stage().world().tick(), p.state()), (20, RunState::Running), "the last tick is shown");
        p.step().expect("applies");
        assert_eq!((p.stage().world().tick(), p.state()), (0, RunState::Running), "back at the start");
        assert_eq!(p.robot_states().count(), 2);
    }

    #[test]
    fn maps_keep_the_obstacles_from_agents_only() {
        let (mut recording, _) = recorded_run();
        recording.start.obstacle_from = 20;
        let p = Player::new(&recording, &options()).expect("plays");
        let (agents, _) = p.map_items(MapAudience::Agents);
        let (observers, _) = p.map_items(MapAudience::Observers);
        assert_eq!((agents.wall_count, observers.wall_count), (20, 23));
        assert_eq!(observers.cycle_ms, recording.start.cycle_ms);
    }
}
