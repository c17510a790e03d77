//! The hub process: steps a [`world::World`] and serves it over iceoryx2 shared memory.
//!
//! [`core::HubCore`] holds the logic; this module owns the ports and the loop. The loop sleeps
//! in `poll(2)` on the hub's doorbell (rung by every client after it sends something) and on
//! one pidfd per agent process, so a crashed agent wakes the hub within a millisecond and a
//! lock-step run never waits for it. Every service is created with explicit limits by
//! `ipc_services`, the one place that also opens them for clients.

#![warn(missing_docs)]

pub mod cli;
pub mod core;
mod ports;
pub mod replay;
pub mod serve;
mod server;
pub mod stage;

use std::time::{Duration, Instant};

use ipc_services::ServicesError;
use ipc_types::{ActionBlock, Command, RobotRegistration, RobotState, RunState};

use self::core::{HubCore, MapAudience, Mode, Refused};
use self::server::{Host, IDLE_POLL, Server};
use recorder::{Recorder, RecorderOptions};
use world::WorldBuildError;
use world::map::{Grid, Lab, Params};

/// How to run a hub.
#[derive(Debug, Clone)]
pub struct HubConfig {
    /// Session name: the hub's services live under `iwsim/<session>/`.
    pub session: String,
    /// The lab.
    pub lab: Lab,
    /// Start poses.
    pub grid: Grid,
    /// Parameters (cycle time, noise, sensors…).
    pub params: Params,
    /// Seed of the world's generator.
    pub seed: u64,
    /// Real time or lock-step.
    pub mode: Mode,
    /// Lock-step: how long to wait for a lagging agent before stepping without it.
    pub deadline: Duration,
    /// Start once this many agents are ready (0: start at once unless `start_on_command`).
    pub wait_agents: usize,
    /// Wait for a Start command.
    pub start_on_command: bool,
    /// Stop after this many ticks (0: run until stopped).
    pub tick_limit: u64,
    /// Robots the hub accepts (at most `ipc_types::MAX_ROBOTS`).
    pub max_robots: usize,
    /// The lab's walls from this index on are a scenario's obstacles (`lab.walls.len()`: none).
    pub obstacle_from: usize,
    /// A scenario's checkpoints, published in the map for viewers and agents.
    pub checkpoints: Vec<places::Checkpoint>,
    /// Record the run to this MCAP file (see the `recorder` crate).
    pub record: Option<std::path::PathBuf>,
    /// Threads the world's step may use (0: one per core); never changes a run.
    pub threads: usize,
    /// The fewest robots a step is spread over threads for.
    pub parallel_min_robots: usize,
    /// Lock-step: how long to spin for answers before sleeping (see [`ANSWER_SPIN_US`]).
    pub answer_spin: Duration,
    /// The names a Real robot (a physical chair, its pose pushed) may register under.
    pub real: Vec<String>,
}

/// Why the hub stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum HubError {
    /// A service could not be set up.
    #[error(transparent)]
    Services(#[from] ServicesError),
    /// The lab or parameters were refused.
    #[error(transparent)]
    World(#[from] WorldBuildError),
    /// iceoryx2 failed while serving.
    #[error("iceoryx2 failed to {0}")]
    Ipc(String),
    /// The recording could not be started.
    #[error(transparent)]
    RecordCreate(#[from] recorder::RecorderCreateError),
    /// The recording could not be finished (what was written before is readable).
    #[error(transparent)]
    RecordFinish(#[from] recorder::RecorderFinishError),
}

/// How a hub run ended: the type `iwsim hub --json` prints, defined once with its JSON form.
pub use run_records::outcome::{HubOutcome, RobotAtEnd, StateHash};

fn ipc<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> HubError + '_ {
    move |e| HubError::Ipc(format!("{what}: {e:?}"))
}

/// How long (µs) a lock-step hub spins for its agents' answers, by default, before it sleeps in
/// poll(2). It spins only while every agent it waits for can have a core of its own, so the
/// spin takes no time from them; an answer that lands during the spin costs no wake-up of the
/// hub (tens of microseconds on a VM whose idle vCPU halts). 200 µs covers an agent of 100
/// robots that reads every sensor; a slower agent costs the spin once per tick, on a core no
/// agent needs.
pub const ANSWER_SPIN_US: u64 = 200;

/// How long registrations must pause before the hub republishes the tick they changed. An
/// agent registering many robots back to back (each answer takes a round trip) thus costs one
/// republication of the world, not one per robot (N robots: O(N) to set up, not O(N²)); a
/// step or a Ready publishes at once, whatever the pause.
const REGISTRATION_SETTLE: Duration = Duration::from_millis(2);

/// The threads a world steps on when `requested` (0: one per core).
pub fn threads_for(requested: usize) -> usize {
    match requested {
        0 => std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get),
        n => n,
    }
}

/// Lock-step ticks whose answer wait the outcome's percentiles count, at most (8 MB).
const MAX_ANSWER_WAITS: usize = 1 << 20;

/// Runs a hub until its tick limit, a Stop command, or SIGINT/SIGTERM.
pub fn run(cfg: HubConfig) -> Result<HubOutcome, HubError> {
    // The hub holds about 11 descriptors per agent.
    os::process::raise_fd_limit();
    let mut hub = Live::open(cfg)?;
    tracing::info!(
        "hub serving session {} ({:?}, lab {:?}, {} grid slots)",
        hub.cfg.session,
        hub.cfg.mode,
        hub.cfg.lab.name,
        hub.cfg.grid.poses.len()
    );
    loop {
        if hub.server.stop_requested() {
            hub.outcome.interrupted = true;
            break;
        }
        if hub.registered_at.is_some_and(|t| t.elapsed() >= REGISTRATION_SETTLE) {
            hub.publish = true;
        }
        if hub.publish && hub.publish()? {
            break;
        }
        let timeout = hub.timeout();
        hub.publish |= hub.server.accept(timeout, &mut hub.core);
        let admitted = hub.server.admit(&mut hub.core)?;
        if admitted.robot {
            // Its agent gets the new robot's readings without waiting a tick, once
            // registrations pause for REGISTRATION_SETTLE (or at a Ready).
            hub.registered_at = Some(Instant::now());
        }
        hub.publish |= admitted.ready;
        hub.start_when_ready();
        hub.publish |= hub.server.control(&mut hub.core)?;
        hub.server.collect(&mut hub.core)?;
        if hub.core.state() == RunState::Finished {
            hub.publish = true;
            continue;
        }
        hub.step();
    }
    hub.finish()
}

/// The live hub: its world, the server in front of it, its recording, and the loop's clocks.
/// [`run`] turns it through the phases; each method here is one of them.
struct Live {
    cfg: HubConfig,
    core: HubCore,
    server: Server,
    recording: Option<Recorder>,
    journal: Vec<recorder::journal::Event>,
    outcome: HubOutcome,
    /// The snapshot as the recorder takes it (filled only when recording).
    states: Vec<RobotState>,
    /// Whether the current tick is to be (re)published on the next turn.
    publish: bool,
    /// When the last robot was registered, while the republication it asks for is pending.
    registered_at: Option<Instant>,
    last_published: Option<u64>,
    published_at: Instant,
    first_step: Option<Instant>,
    cycle: Duration,
    next_tick_at: Instant,
    deadline_at: Instant,
    /// Cores for the hub and its agents: a recording's writer thread keeps one busy.
    cores: usize,
    /// The tick the hub last spun for answers on, and how long the last lock-step answers
    /// took to come in after their tick was published.
    spun_on: Option<u64>,
    last_answer_wait: Option<Duration>,
    /// Every lock-step tick's wait, for the outcome's percentiles (reserved up front for a run
    /// of known length, so the loop does not reallocate; a run without end grows it).
    answer_waits: Vec<u64>,
}

impl Live {
    /// Builds the world, starts the recording, and opens the session.
    fn open(cfg: HubConfig) -> Result<Self, HubError> {
        let mut core =
            HubCore::new(&cfg.lab, cfg.grid.clone(), cfg.params.clone(), cfg.seed, cfg.mode, cfg.tick_limit)?;
        core.set_threads(threads_for(cfg.threads), cfg.parallel_min_robots);
        core.set_max_robots(cfg.max_robots);
        core.set_real_names(cfg.real.iter().cloned());
        core.set_scenario(cfg.obstacle_from, cfg.checkpoints.clone());
        let deadline_ms = cfg.deadline.as_millis().min(u32::MAX as u128) as u32;
        let recording = match &cfg.record {
            Some(path) => {
                core.record();
                let options = RecorderOptions {
                    wall_clock_start: Some(std::time::SystemTime::now()),
                    // Lock-step keeps no wall-clock deadline: its people channels hold every tick.
                    keep_every_frame: cfg.mode == Mode::LockStep,
                    ..Default::default()
                };
                let rec = Recorder::create(path, &core.run_start(deadline_ms), options)?;
                tracing::info!("recording the run to {}", path.display());
                Some(rec)
            }
            None => None,
        };
        let server = Server::open(
            &cfg.session,
            core.map_items(cfg.params.cycle_ms, deadline_ms, MapAudience::Agents),
            core.map_items(cfg.params.cycle_ms, deadline_ms, MapAudience::Observers),
        )?;
        let mut answer_waits = Vec::new();
        if cfg.mode == Mode::LockStep {
            let known = if cfg.tick_limit == 0 { 4096 } else { cfg.tick_limit };
            answer_waits.reserve_exact(known.min(MAX_ANSWER_WAITS as u64) as usize);
        }
        let cycle = Duration::from_millis(cfg.params.cycle_ms.max(1) as u64);
        let now = Instant::now();
        Ok(Self {
            cores: threads_for(0).saturating_sub(recording.is_some() as usize),
            deadline_at: now + cfg.deadline,
            cfg,
            core,
            server,
            recording,
            journal: Vec::new(),
            outcome: HubOutcome::default(),
            states: Vec::new(),
            publish: true,
            registered_at: None,
            last_published: None,
            published_at: now,
            first_step: None,
            cycle,
            next_tick_at: now + cycle,
            spun_on: None,
            last_answer_wait: None,
            answer_waits,
        })
    }

    /// **Publish** and **record**: the current tick to observers and agents, its changes to
    /// the recording. Returns whether the run has finished (its last tick is out).
    fn publish(&mut self) -> Result<bool, HubError> {
        self.registered_at = None;
        self.publish = false;
        self.outcome.snapshots += 1;
        if self.core.world().tick() == 0 {
            self.core.prime_sensors();
        }
        // Agents may spin for the next tick while the step leaves them a core: it runs on
        // one thread.
        let agents_spin = self.spins_for_answers() && !self.core.world().steps_on_threads();
        let spin_us = if agents_spin { self.cfg.answer_spin.as_micros() as u32 } else { 0 };
        publish_tick(&self.core, &mut self.server, self.recording.is_some().then_some(&mut self.states), spin_us)?;
        if self.core.has_chairs() {
            let count = self.core.chair_states().count();
            self.server.publish_chairs(self.core.world().tick(), count, self.core.chair_states())?;
        }
        self.server.ring()?;
        if let Some(rec) = &mut self.recording {
            record_changes(&mut self.core, rec, &mut self.journal);
        }
        // The deadline runs from the tick's first publication: re-publishing the same tick
        // (a command, an agent joining) must not push it back, or lock-step could hang.
        let tick = self.core.world().tick();
        if self.last_published != Some(tick) {
            self.last_published = Some(tick);
            self.published_at = Instant::now();
            self.deadline_at = self.published_at + self.cfg.deadline;
            if let Some(rec) = &mut self.recording {
                rec.world(tick, &self.states, self.server.robot_info());
            }
        }
        Ok(self.core.state() == RunState::Finished)
    }

    /// How long the next wait may sleep; spins for lock-step answers first when that pays.
    fn timeout(&mut self) -> Duration {
        let now = Instant::now();
        let timeout = if !self.core.may_step() {
            Duration::from_millis(50)
        } else {
            match self.core.mode() {
                Mode::RealTime => self.next_tick_at.saturating_duration_since(now),
                // With no ready agent the deadline means nothing (there is no one to step
                // without), and once passed it would make every poll return at once: sleep
                // until a client rings instead.
                Mode::LockStep if self.core.ready_agents() == 0 && !self.core.has_orphans() => IDLE_POLL,
                Mode::LockStep => self.deadline_at.saturating_duration_since(now),
            }
        }
        .min(IDLE_POLL)
        .min(self.registered_at.map_or(Duration::MAX, |t| (t + REGISTRATION_SETTLE).saturating_duration_since(now)));
        // Lock-step with every agent on a core of its own (the hub on another): the answer is
        // tens of microseconds away, and a wake-up from poll(2) would add as much again. Spin
        // on the actions port, which needs no syscall, for a bounded time first: at most once
        // a tick (an agent slower than the spin is then waited for asleep), and only while
        // answers have been coming within the spin (an agent, or a UDP client behind the
        // bridge, slower than that would only lose the core the hub spins on).
        let spin = self.spun_on != Some(self.core.world().tick())
            && self.last_answer_wait.is_none_or(|w| w <= self.cfg.answer_spin)
            && self.core.may_step()
            && self.spins_for_answers()
            && !self.core.all_answered();
        if !spin {
            return timeout;
        }
        self.spun_on = Some(self.core.world().tick());
        let until = Instant::now() + self.cfg.answer_spin;
        while Instant::now() < until {
            if self.server.actions_waiting() {
                return Duration::ZERO;
            }
            std::hint::spin_loop();
        }
        timeout
    }

    /// Starts a run that waits for its agents once they are ready (unless it waits for a
    /// Start command).
    fn start_when_ready(&mut self) {
        if self.core.state() != RunState::Waiting || self.cfg.start_on_command {
            return;
        }
        if self.cfg.wait_agents == 0 {
            self.core.command(Command::Start, 0);
        } else {
            self.core.start_when_ready(self.cfg.wait_agents);
        }
        if self.core.state() == RunState::Running {
            self.next_tick_at = Instant::now() + self.cycle;
            self.publish = true;
        }
    }

    /// **Step**: the world moves on when its tick is due (real time), or when every agent
    /// has answered or the deadline passed (lock-step).
    fn step(&mut self) {
        if !self.core.may_step() {
            return;
        }
        let now = Instant::now();
        let due = match self.core.mode() {
            Mode::RealTime => now >= self.next_tick_at,
            // A dead agent's robots are stepped without it at the deadline, like a
            // laggard's, even when it was the last agent.
            Mode::LockStep => {
                self.core.all_answered() || (self.core.ready_agents() > 0 || self.core.has_orphans()) && self.late(now)
            }
        };
        if !due {
            return;
        }
        self.first_step.get_or_insert_with(Instant::now);
        if self.core.mode() == Mode::LockStep {
            let wait = now.saturating_duration_since(self.published_at);
            self.last_answer_wait = Some(wait);
            if self.answer_waits.len() < MAX_ANSWER_WAITS {
                self.answer_waits.push(wait.as_nanos() as u64);
            }
        }
        self.core.step();
        self.publish = true;
        if self.core.mode() == Mode::RealTime {
            self.next_tick_at += self.cycle;
            if self.next_tick_at < now {
                self.next_tick_at = now + self.cycle; // fell behind: do not try to catch up
            }
        }
    }

    /// Whether the lock-step deadline has passed; marks the agents it passed for.
    fn late(&mut self, now: Instant) -> bool {
        let late = now >= self.deadline_at;
        if late && self.core.ready_agents() == 0 {
            tracing::debug!("tick {}: no live agent; stepping its robots", self.core.world().tick());
        } else if late {
            let n = self.core.mark_laggards();
            tracing::warn!("tick {}: {n} agents missed the {:?} deadline", self.core.world().tick(), self.cfg.deadline);
        }
        late
    }

    /// Whether waiting for lock-step answers may spin: while every agent the hub waits for can
    /// have a core of its own (the hub has another, and a recording's writer a third), so
    /// spinning takes no core a process needs. Both the hub (for answers) and its agents (for
    /// the next tick, told by `TickHeader::spin_us`) then spin for at most `cfg.answer_spin`
    /// before they sleep.
    fn spins_for_answers(&self) -> bool {
        !self.cfg.answer_spin.is_zero()
            && self.core.mode() == Mode::LockStep
            && (1..self.cores).contains(&self.core.barrier_size())
    }

    /// **Linger** and the end: tells everyone an interrupted run is over, gives the agents
    /// time to read it, finishes the recording, and reports.
    fn finish(mut self) -> Result<HubOutcome, HubError> {
        // The run ends with its last step: the linger below (up to 2 s while an agent such as
        // the UDP bridge outlives the run) is not part of it, and every rate divides by this.
        let run_s = self.first_step.map_or(0.0, |t| t.elapsed().as_secs_f64());
        if self.outcome.interrupted {
            self.core.command(Command::Stop, 0);
            let _ = publish_tick(&self.core, &mut self.server, None, 0);
            let _ = self.server.ring();
        }
        self.server.linger(false);
        let mut outcome = self.outcome;
        let core = &mut self.core;
        outcome.scoring = core.stage().challenge().scoring().number();
        outcome.scores = core.stage().scores();
        if let Some(mut rec) = self.recording {
            record_changes(core, &mut rec, &mut self.journal);
            let reason = if outcome.interrupted { "interrupted" } else { "finished" };
            rec.event(&recorder::journal::Event::Finish { tick: core.world().tick(), reason: reason.to_owned() });
            rec.metadata(recorder::CHALLENGE_METADATA, challenge_table(outcome.scoring, &outcome.scores));
            let stats = rec.finish()?;
            if stats.dropped_world_frames > 0 || stats.replay_stalls > 0 {
                tracing::warn!(
                    "recording: {} world frames dropped for people (the replay journal is whole), the tick \
                     waited for the writer {} times",
                    stats.dropped_world_frames,
                    stats.replay_stalls
                );
            }
            outcome.recorded_bytes = stats.bytes;
            outcome.recording_dropped_frames = stats.dropped_world_frames;
        }
        let counts = self.server.counts();
        outcome.agents_seen = counts.agents_seen;
        outcome.agents_died = counts.agents_died;
        outcome.foreign_dropped = counts.foreign_dropped;
        outcome.refused_poses = core.refused_poses();
        outcome.ticks = core.world().tick();
        outcome.run_s = run_s;
        outcome.answer_wait = (self.cfg.mode == Mode::LockStep && !self.answer_waits.is_empty())
            .then(|| run_records::latency::Percentiles::of_ns(&self.answer_waits));
        outcome.state_hash = StateHash(core.world().state_hash());
        outcome.robots = core
            .robot_states()
            .map(|s| RobotAtEnd { id: s.id, x_m: s.x_m, y_m: s.y_m, heading_deg: s.heading_deg, flags: s.flags })
            .collect();
        drop(self.server);
        Ok(outcome)
    }
}

/// The run's final challenge standings as the recording's metadata table: the scoring mode,
/// and one JSON object per robot under its zero-padded id.
fn challenge_table(
    scoring: u32,
    scores: &[run_records::outcome::ScoreAtEnd],
) -> std::collections::BTreeMap<String, String> {
    let mut t = std::collections::BTreeMap::new();
    t.insert("scoring".to_owned(), scoring.to_string());
    for s in scores {
        t.insert(format!("robot {:05}", s.id), s.json());
    }
    t
}

/// Writes the world's changes since the last call to the recording's replay journal.
fn record_changes(core: &mut HubCore, rec: &mut Recorder, journal: &mut Vec<recorder::journal::Event>) {
    core.take_journal(journal);
    for e in journal.drain(..) {
        rec.event(&e);
    }
}

/// Publishes the current tick: the world snapshot and every agent's sensor blocks, each written
/// straight into its loaned sample (no scratch copy); `recorded` gets a copy of the snapshot
/// when the run is recorded.
fn publish_tick(
    core: &HubCore,
    server: &mut Server,
    recorded: Option<&mut Vec<RobotState>>,
    spin_us: u32,
) -> Result<(), HubError> {
    let header = core.world_header();
    server.publish_world(header, core.robot_count(), core.robot_states(), || core.robot_info(), recorded)?;
    server.publish_blocks(&header, spin_us, core.mode() == Mode::LockStep, |id| {
        core.agent_blocks(id).map(|r| core.sensor_block(r))
    })
}

/// The live world behind the server.
impl Host for HubCore {
    fn tick(&self) -> u64 {
        self.world().tick()
    }

    fn run_state(&self) -> RunState {
        self.state()
    }

    fn hello(&mut self, pid: u32) -> Result<u32, Refused> {
        HubCore::hello(self, pid)
    }

    fn register(&mut self, agent: u32, robot: &RobotRegistration) -> Result<(u32, u32), Refused> {
        HubCore::register(self, agent, robot)
    }

    fn ready(&mut self, agent: u32) -> Result<(), Refused> {
        HubCore::ready(self, agent)
    }

    fn bye(&mut self, agent: u32) {
        HubCore::bye(self, agent);
    }

    fn exited(&mut self, agent: u32) -> bool {
        let pid = self.agent_pid(agent);
        let died = self.agent_died(agent);
        if died {
            // Observers see the frozen flag even when no tick follows (a lock-step run whose
            // only agent died waits for the next one).
            tracing::warn!("agent {agent} (pid {pid:?}) died; its robots are frozen");
        }
        died
    }

    fn command(&mut self, command: Command, robot: u32) -> u32 {
        HubCore::command(self, command, robot)
    }

    fn actions(&mut self, agent: u32, tick: u64, blocks: &[ActionBlock]) -> usize {
        HubCore::actions(self, agent, tick, blocks)
    }
}
