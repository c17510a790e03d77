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
pub mod stage;

use std::collections::BTreeMap;
use std::os::fd::{AsRawFd, OwnedFd};
use std::time::{Duration, Instant};

use ipc_services::iceoryx2::port::publisher::Publisher;
use ipc_services::{HUB_NODE_NAME, ServicesError, Session, Svc, clean_dead_nodes};
use ipc_types::{
    Command, ControlResponse, Refusal, RegisterKind, RegisterRequest, RegisterResponse, RobotState, RunState,
    SensorBlock, TickHeader,
};

use self::core::{HubCore, MapAudience, Mode};
use self::ports::{HubPorts, agent_sensor_port};
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
    pub checkpoints: Vec<records::places::Checkpoint>,
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
pub use records::outcome::{HubOutcome, RobotAtEnd, StateHash};

fn ipc<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> HubError + '_ {
    move |e| HubError::Ipc(format!("{what}: {e:?}"))
}

/// The longest the loop sleeps: how often it looks for a termination signal and for
/// subscribers that joined without ringing.
const IDLE_POLL: Duration = Duration::from_millis(50);

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

/// A Linux pidfd: readable once the process has exited.
#[derive(Debug)]
struct PidFd(OwnedFd);

impl PidFd {
    fn open(pid: u32) -> Option<Self> {
        os::process::pidfd_open(pid).map(Self)
    }
}

/// Waits until one of `fds` is readable or `timeout` passes; `ready` gets the indexes of the
/// readable ones. An error of the wait (none is expected of open descriptors) reads as a
/// timeout: the loop looks at everything again on its next turn.
fn readable(poller: &mut os::poll::Poller, fds: &[i32], timeout: Duration, ready: &mut Vec<usize>) {
    ready.clear();
    if poller.wait(fds, Some(timeout)).is_ok() {
        poller.ready_into(ready);
    }
}

struct AgentPorts {
    publisher: Publisher<Svc, [SensorBlock], TickHeader>,
    _service: ipc_services::SensorService,
    pidfd: Option<PidFd>,
    /// The register client that said hello: only its requests speak for this agent.
    client: u128,
    /// The publisher the hello named: only its actions drive this agent's robots.
    actions: u128,
}

/// The iceoryx2 publisher id a register request names (see `RegisterRequest::actions_publisher`).
fn named_publisher(r: &RegisterRequest) -> u128 {
    r.actions_publisher[0] as u128 | (r.actions_publisher[1] as u128) << 64
}

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
    let session = Session::new(&cfg.session)?;
    // Dropped last, on every way out (a refused lab, a failed port, the end of the run): the
    // last process of a session leaves nothing in /dev/shm.
    let _release = session.release_on_drop();
    let cleaned = clean_dead_nodes(&session);
    if cleaned > 0 {
        tracing::info!("removed {cleaned} dead iceoryx2 nodes left by an earlier run of session {}", cfg.session);
    }
    let node = session.node(HUB_NODE_NAME)?;
    let mut core = HubCore::new(&cfg.lab, cfg.grid.clone(), cfg.params.clone(), cfg.seed, cfg.mode, cfg.tick_limit)?;
    core.set_threads(threads_for(cfg.threads), cfg.parallel_min_robots);
    core.set_max_robots(cfg.max_robots);
    core.set_real_names(cfg.real.iter().cloned());
    core.set_scenario(cfg.obstacle_from, cfg.checkpoints.clone());
    let deadline_ms = cfg.deadline.as_millis().min(u32::MAX as u128) as u32;
    let mut recording = match &cfg.record {
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
    let mut journal: Vec<recorder::journal::Event> = Vec::new();

    let mut ports = HubPorts::open(
        &session,
        &node,
        core.map_items(cfg.params.cycle_ms, deadline_ms, MapAudience::Agents),
        core.map_items(cfg.params.cycle_ms, deadline_ms, MapAudience::Observers),
    )?;
    let doorbell_fd = ports.doorbell_fd();

    let hub_pid = std::process::id();
    let mut agents: BTreeMap<u32, AgentPorts> = BTreeMap::new();
    let mut outcome = HubOutcome::default();
    let mut first_step: Option<Instant> = None;
    // The snapshot as the recorder takes it (filled only when recording).
    let mut states: Vec<RobotState> = Vec::new();
    let cycle = Duration::from_millis(cfg.params.cycle_ms.max(1) as u64);
    let mut next_tick_at = Instant::now() + cycle;
    let mut deadline_at = Instant::now() + cfg.deadline;
    let mut fds: Vec<i32> = Vec::new();
    let mut fd_agents: Vec<u32> = Vec::new();
    let mut poller = os::poll::Poller::default();
    let mut ready = Vec::new();
    let mut dead_agents: Vec<u32> = Vec::new();
    let mut publish = true;
    // When the last robot was registered, while the republication it asks for is pending.
    let mut registered_at: Option<Instant> = None;
    let mut last_published: Option<u64> = None;
    // Cores for the hub and its agents: a recording's writer thread keeps one busy.
    let cores = threads_for(0).saturating_sub(recording.is_some() as usize);
    // The tick the hub last spun for answers on, and how long the last lock-step answers took
    // to come in after their tick was published.
    let mut spun_on: Option<u64> = None;
    let mut last_answer_wait: Option<Duration> = None;
    // Every lock-step tick's wait, for the outcome's percentiles (reserved up front for a run
    // of known length, so the loop does not reallocate; a run without end grows it).
    let mut answer_waits: Vec<u64> = Vec::new();
    if cfg.mode == Mode::LockStep {
        let known = if cfg.tick_limit == 0 { 4096 } else { cfg.tick_limit };
        answer_waits.reserve_exact(known.min(MAX_ANSWER_WAITS as u64) as usize);
    }
    let mut published_at = Instant::now();

    tracing::info!(
        "hub serving session {} ({:?}, lab {:?}, {} grid slots)",
        cfg.session,
        cfg.mode,
        cfg.lab.name,
        cfg.grid.poses.len()
    );
    loop {
        if ipc_services::stop_requested(&node) {
            outcome.interrupted = true;
            break;
        }
        if registered_at.is_some_and(|t| t.elapsed() >= REGISTRATION_SETTLE) {
            publish = true;
        }
        if publish {
            registered_at = None;
            outcome.snapshots += 1;
            if core.world().tick() == 0 {
                core.prime_sensors();
            }
            let recorded = recording.is_some().then_some(&mut states);
            // Agents may spin for the next tick while the step leaves them a core: it runs on
            // one thread.
            let agents_spin = spins_for_answers(&cfg, &core, cores) && !core.world().steps_on_threads();
            let spin_us = if agents_spin { cfg.answer_spin.as_micros() as u32 } else { 0 };
            publish_tick(&core, &ports.world_pub, &agents, &mut ports.roster, recorded, spin_us)?;
            if core.has_chairs() {
                let count = core.chair_states().count();
                ports::publish_chairs(&ports.chairs_pub, core.world().tick(), count, core.chair_states())?;
            }
            ports.tick_notifier.notify().map_err(ipc("ring the tick"))?;
            publish = false;
            if let Some(rec) = &mut recording {
                record_changes(&mut core, rec, &mut journal);
            }
            // The deadline runs from the tick's first publication: re-publishing the same tick
            // (a command, an agent joining) must not push it back, or lock-step could hang.
            if last_published != Some(core.world().tick()) {
                last_published = Some(core.world().tick());
                published_at = Instant::now();
                deadline_at = published_at + cfg.deadline;
                if let Some(rec) = &mut recording {
                    rec.world(core.world().tick(), &states, &ports.roster.scratch);
                }
            }
            if core.state() == RunState::Finished {
                break;
            }
        }

        let now = Instant::now();
        let timeout = if !core.may_step() {
            Duration::from_millis(50)
        } else {
            match core.mode() {
                Mode::RealTime => next_tick_at.saturating_duration_since(now),
                // With no ready agent the deadline means nothing (there is no one to step
                // without), and once passed it would make every poll return at once: sleep
                // until a client rings instead.
                Mode::LockStep if core.ready_agents() == 0 && !core.has_orphans() => IDLE_POLL,
                Mode::LockStep => deadline_at.saturating_duration_since(now),
            }
        }
        .min(IDLE_POLL)
        .min(registered_at.map_or(Duration::MAX, |t| (t + REGISTRATION_SETTLE).saturating_duration_since(now)));
        fds.clear();
        fd_agents.clear();
        fds.push(doorbell_fd);
        for (&id, a) in &agents {
            if let Some(p) = &a.pidfd {
                fds.push(p.0.as_raw_fd());
                fd_agents.push(id);
            }
        }
        // Lock-step with every agent on a core of its own (the hub on another): the answer is
        // tens of microseconds away, and a wake-up from poll(2) would add as much again. Spin
        // on the actions port, which needs no syscall, for a bounded time first: at most once
        // a tick (an agent slower than the spin is then waited for asleep), and only while
        // answers have been coming within the spin (an agent, or a UDP client behind the
        // bridge, slower than that would only lose the core the hub spins on).
        let spin = spun_on != Some(core.world().tick())
            && last_answer_wait.is_none_or(|w| w <= cfg.answer_spin)
            && core.may_step()
            && spins_for_answers(&cfg, &core, cores)
            && !core.all_answered();
        let timeout = if spin {
            spun_on = Some(core.world().tick());
            let until = Instant::now() + cfg.answer_spin;
            let mut arrived = false;
            while !arrived && Instant::now() < until {
                arrived = ports.actions_sub.has_samples().unwrap_or(true);
                std::hint::spin_loop();
            }
            if arrived { Duration::ZERO } else { timeout }
        } else {
            timeout
        };
        readable(&mut poller, &fds, timeout, &mut ready);
        let _ = ports.doorbell.try_wait(|_| {});
        // A new subscriber gets the kept (history) sample only when the publisher next looks
        // at its connections: the map is sent once, and the world not while paused.
        ports.update_connections();
        dead_agents.clear();
        dead_agents.extend(ready.iter().filter(|&&i| i > 0).map(|&i| fd_agents[i - 1]));

        for id in dead_agents.drain(..) {
            let pid = core.agent_pid(id);
            if core.agent_died(id) {
                outcome.agents_died += 1;
                tracing::warn!("agent {id} (pid {pid:?}) died; its robots are frozen");
                // Observers see the frozen flag even when no tick follows (a lock-step run
                // whose only agent died waits for the next one).
                publish = true;
            }
            agents.remove(&id);
            let _ = node.try_cleanup_dead_nodes();
        }

        // Registrations.
        while let Some(req) = ports.register_server.receive().map_err(ipc("receive a registration"))? {
            let r = *req.payload();
            let origin = req.origin().value();
            tracing::debug!("registration request kind {} from pid {} agent {}", r.kind, r.pid, r.agent_id);
            let mut resp =
                RegisterResponse { hub_pid, tick: core.world().tick() as u32, ..bytemuck::Zeroable::zeroed() };
            let kind = RegisterKind::from_u32(r.kind);
            // A request in an agent's name from a port other than the one that said hello for
            // it (another process, or a stale client) is refused and changes nothing.
            let foreign = kind.is_some_and(|k| k != RegisterKind::Hello)
                && agents.get(&r.agent_id).is_some_and(|a| a.client != origin);
            if foreign {
                outcome.foreign_dropped += 1;
                tracing::warn!("a {kind:?} request in agent {}'s name came from another port; refused", r.agent_id);
                resp.status = Refusal::NotYours as u32;
                resp.set_detail("this agent id belongs to another process's port");
                req.send_copy(resp).map_err(ipc("answer a registration"))?;
                continue;
            }
            match kind {
                Some(RegisterKind::Hello) if named_publisher(&r) == 0 => {
                    resp.status = Refusal::Malformed as u32;
                    resp.set_detail("a hello must name its actions publisher");
                }
                Some(RegisterKind::Hello) => match core.hello(r.pid) {
                    Ok(id) => {
                        match agent_sensor_port(&session, &node, id) {
                            Ok((service, publisher)) => {
                                let pidfd = PidFd::open(r.pid);
                                if pidfd.is_none() {
                                    tracing::warn!(
                                        "agent {id}: pid {} cannot be watched; only the deadline guards it",
                                        r.pid
                                    );
                                }
                                agents.insert(
                                    id,
                                    AgentPorts {
                                        publisher,
                                        _service: service,
                                        pidfd,
                                        client: origin,
                                        actions: named_publisher(&r),
                                    },
                                );
                                outcome.agents_seen += 1;
                                resp.agent_id = id;
                            }
                            Err(e) => {
                                // Out of shared memory or file descriptors: refuse this agent, serve the rest.
                                tracing::warn!("agent {id}: cannot create its sensor service: {e}");
                                core.bye(id);
                                resp.status = Refusal::Capacity as u32;
                                resp.set_detail("the hub cannot create this agent's sensor service");
                            }
                        }
                    }
                    Err(refused) => {
                        resp.status = refused.reason as u32;
                        resp.set_detail(&refused.detail);
                    }
                },
                Some(RegisterKind::Robot) => {
                    resp.agent_id = r.agent_id;
                    match core.register(r.agent_id, &r.robot) {
                        Ok((robot_id, sensors)) => {
                            resp.robot_id = robot_id;
                            resp.sensor_count = sensors;
                            // Its agent gets the new robot's readings without waiting a tick,
                            // once registrations pause for REGISTRATION_SETTLE (or at a Ready).
                            registered_at = Some(Instant::now());
                        }
                        Err(refused) => {
                            resp.status = refused.reason as u32;
                            resp.set_detail(&refused.detail);
                        }
                    }
                }
                Some(RegisterKind::Ready) => {
                    resp.agent_id = r.agent_id;
                    if let Err(refused) = core.ready(r.agent_id) {
                        resp.status = refused.reason as u32;
                        resp.set_detail(&refused.detail);
                    }
                    // The new agent's first sensor blocks: the current tick.
                    publish = true;
                }
                Some(RegisterKind::Bye) => {
                    core.bye(r.agent_id);
                    agents.remove(&r.agent_id);
                }
                None => {
                    resp.status = Refusal::Malformed as u32;
                    resp.set_detail("unknown request kind");
                }
            }
            req.send_copy(resp).map_err(ipc("answer a registration"))?;
            tracing::debug!(
                "answered pid {}: status {} agent {} robot {}",
                r.pid,
                resp.status,
                resp.agent_id,
                resp.robot_id
            );
        }
        if core.state() == RunState::Waiting && !cfg.start_on_command {
            if cfg.wait_agents == 0 {
                core.command(Command::Start, 0);
            } else {
                core.start_when_ready(cfg.wait_agents);
            }
            if core.state() == RunState::Running {
                next_tick_at = Instant::now() + cycle;
                publish = true;
            }
        }

        // Run control.
        while let Some(req) = ports.control_server.receive().map_err(ipc("receive a command"))? {
            let c = *req.payload();
            let status = match Command::from_u32(c.command) {
                Some(cmd) => core.command(cmd, c.robot_id),
                None => 1,
            };
            let resp = ControlResponse { status, run_state: core.state() as u32, tick: core.world().tick() };
            req.send_copy(resp).map_err(ipc("answer a command"))?;
            publish = true;
        }

        // Actions.
        while let Some(sample) = ports.actions_sub.receive().map_err(ipc("receive actions"))? {
            let h = *sample.user_header();
            if agents.get(&h.agent_id).is_none_or(|a| a.actions != sample.origin().value()) {
                // Not from the publisher this agent's hello named: another process acting in
                // its name, or a port of an agent that has left. Its robots keep their inputs.
                outcome.foreign_dropped += 1;
                if outcome.foreign_dropped.is_power_of_two() {
                    tracing::warn!(
                        "actions in agent {}'s name from a port that is not its own dropped ({} so far)",
                        h.agent_id,
                        outcome.foreign_dropped
                    );
                }
                continue;
            }
            let ignored = core.actions(h.agent_id, h.tick, sample.payload());
            if ignored > 0 {
                tracing::debug!("agent {}: {ignored} actions for robots it does not own were ignored", h.agent_id);
            }
        }

        if core.state() == RunState::Finished {
            publish = true;
            continue;
        }
        if core.may_step() {
            let now = Instant::now();
            let step = match core.mode() {
                Mode::RealTime => now >= next_tick_at,
                Mode::LockStep => {
                    core.all_answered()
                        // A dead agent's robots are stepped without it at the deadline, like a
                        // laggard's, even when it was the last agent.
                        || (core.ready_agents() > 0 || core.has_orphans()) && {
                            let late = now >= deadline_at;
                            if late && core.ready_agents() == 0 {
                                tracing::debug!("tick {}: no live agent; stepping its robots", core.world().tick());
                            } else if late {
                                let n = core.mark_laggards();
                                tracing::warn!(
                                    "tick {}: {n} agents missed the {:?} deadline",
                                    core.world().tick(),
                                    cfg.deadline
                                );
                            }
                            late
                        }
                }
            };
            if step {
                first_step.get_or_insert_with(Instant::now);
                if core.mode() == Mode::LockStep {
                    let wait = now.saturating_duration_since(published_at);
                    last_answer_wait = Some(wait);
                    if answer_waits.len() < MAX_ANSWER_WAITS {
                        answer_waits.push(wait.as_nanos() as u64);
                    }
                }
                core.step();
                publish = true;
                if core.mode() == Mode::RealTime {
                    next_tick_at += cycle;
                    if next_tick_at < now {
                        next_tick_at = now + cycle; // fell behind: do not try to catch up
                    }
                }
            }
        }
    }

    // Interrupted: tell everyone the run is over before the services go away.
    if outcome.interrupted {
        core.command(Command::Stop, 0);
        let _ = publish_tick(&core, &ports.world_pub, &agents, &mut ports.roster, None, 0);
        let _ = ports.tick_notifier.notify();
    }
    // An agent reads the final tick from the hub's shared memory, which goes when the hub does:
    // give every agent process up to 2 s to read it and leave.
    let linger_until = Instant::now() + Duration::from_secs(2);
    let mut waiting: Vec<i32> = agents.values().filter_map(|a| a.pidfd.as_ref().map(|p| p.0.as_raw_fd())).collect();
    while !waiting.is_empty() && Instant::now() < linger_until {
        readable(&mut poller, &waiting, linger_until.saturating_duration_since(Instant::now()), &mut ready);
        if ready.is_empty() {
            break;
        }
        let done: Vec<i32> = ready.iter().map(|&i| waiting[i]).collect();
        waiting.retain(|fd| !done.contains(fd));
    }
    outcome.scoring = core.stage().challenge().scoring().number();
    outcome.scores = core.stage().scores();
    if let Some(mut rec) = recording {
        record_changes(&mut core, &mut rec, &mut journal);
        let reason = if outcome.interrupted { "interrupted" } else { "finished" };
        rec.event(&recorder::journal::Event::Finish { tick: core.world().tick(), reason: reason.to_owned() });
        rec.metadata(recorder::CHALLENGE_METADATA, challenge_table(outcome.scoring, &outcome.scores));
        let stats = rec.finish()?;
        if stats.dropped_world_frames > 0 || stats.replay_stalls > 0 {
            tracing::warn!(
                "recording: {} world frames dropped for people (the replay journal is whole), the tick waited \
                 for the writer {} times",
                stats.dropped_world_frames,
                stats.replay_stalls
            );
        }
        outcome.recorded_bytes = stats.bytes;
        outcome.recording_dropped_frames = stats.dropped_world_frames;
    }
    outcome.refused_poses = core.refused_poses();
    outcome.ticks = core.world().tick();
    outcome.run_s = first_step.map_or(0.0, |t| t.elapsed().as_secs_f64());
    outcome.answer_wait = (cfg.mode == Mode::LockStep && !answer_waits.is_empty())
        .then(|| records::latency::Percentiles::of_ns(&answer_waits));
    outcome.state_hash = StateHash(core.world().state_hash());
    outcome.robots = core
        .robot_states()
        .map(|s| RobotAtEnd { id: s.id, x_m: s.x_m, y_m: s.y_m, heading_deg: s.heading_deg, flags: s.flags })
        .collect();
    drop((agents, ports, node));
    Ok(outcome)
}

/// The run's final challenge standings as the recording's metadata table: the scoring mode,
/// and one JSON object per robot under its zero-padded id.
fn challenge_table(
    scoring: u32,
    scores: &[records::outcome::ScoreAtEnd],
) -> std::collections::BTreeMap<String, String> {
    let mut t = std::collections::BTreeMap::new();
    t.insert("scoring".to_owned(), scoring.to_string());
    for s in scores {
        t.insert(format!("robot {:05}", s.id), s.json());
    }
    t
}

/// Whether waiting for lock-step answers may spin: while every agent the hub waits for can have
/// a core of its own (the hub has another, and a recording's writer a third), so spinning takes
/// no core a process needs. Both the hub (for answers) and its agents (for the next tick, told
/// by `TickHeader::spin_us`) then spin for at most `cfg.answer_spin` before they sleep.
fn spins_for_answers(cfg: &HubConfig, core: &HubCore, cores: usize) -> bool {
    !cfg.answer_spin.is_zero() && core.mode() == Mode::LockStep && (1..cores).contains(&core.barrier_size())
}

/// Writes the world's changes since the last call to the recording's replay journal.
fn record_changes(core: &mut HubCore, rec: &mut Recorder, journal: &mut Vec<recorder::journal::Event>) {
    core.take_journal(journal);
    for e in journal.drain(..) {
        rec.event(&e);
    }
}

/// Publishes the current tick: the world snapshot and every agent's sensor blocks, each written
/// straight into its loaned sample (no scratch copy). The roster notes the snapshot's robot ids
/// (published by the caller if they changed); `recorded` gets a copy of the snapshot when the
/// run is recorded.
fn publish_tick(
    core: &HubCore,
    world_pub: &Publisher<Svc, [RobotState], ipc_types::WorldHeader>,
    agents: &BTreeMap<u32, AgentPorts>,
    roster: &mut ports::Roster,
    recorded: Option<&mut Vec<RobotState>>,
    spin_us: u32,
) -> Result<(), HubError> {
    let header = core.world_header();
    let mut sample = world_pub.loan_slice_uninit(core.robot_count()).map_err(ipc("loan a world snapshot"))?;
    *sample.user_header_mut() = header;
    let sample = ports::fill(sample, core.robot_states());
    roster.note(sample.payload().iter().map(|s| s.id));
    if let Some(states) = recorded {
        states.clear();
        states.extend_from_slice(sample.payload());
    }
    // Before the snapshot: an observer that reads a snapshot finds every robot's info (its
    // name) already published.
    roster.publish_if_changed(|| core.robot_info())?;
    sample.send().map_err(ipc("send a world snapshot"))?;
    let finished = header.run_state == RunState::Finished as u32;
    for (&id, ports) in agents {
        let count = core.agent_blocks(id).count();
        // Agents without robots get nothing per tick, but every agent hears the end.
        if count == 0 && !finished {
            continue;
        }
        let mut sample = ports.publisher.loan_slice_uninit(count).map_err(ipc("loan sensor blocks"))?;
        *sample.user_header_mut() = TickHeader {
            tick: header.tick,
            sim_time_s: header.sim_time_s,
            run_state: header.run_state,
            count: count as u32,
            t_pub_ns: 0,
            spin_us,
            flags: if core.mode() == Mode::LockStep { ipc_types::TICK_LOCKSTEP } else { 0 },
        };
        let mut sample = ports::fill(sample, core.agent_blocks(id).map(|r| core.sensor_block(r)));
        // Stamped last, so the latency figure starts at the send itself.
        sample.user_header_mut().t_pub_ns = ipc_services::monotonic_ns();
        sample.send().map_err(ipc("send sensor blocks"))?;
    }
    Ok(())
}
