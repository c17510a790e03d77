//! `iwsim run`: a scenario as real processes — the hub, every agent and (unless headless) the
//! viewer — then a summary judged from the hub's record of the run.
//!
//! The hub records every run (`run.mcap`): the replay journal holds every change it made to
//! its world, so replaying it gives the truth at every tick — true poses, the world's contact
//! count — whatever the tick rate. The summary (checkpoints reached, contacts, times, speeds)
//! is measured from that truth, never from what the agents under test write about themselves
//! (their per-robot CSV logs stay, for people and `iwsim plot`), and the same seed in
//! lock-step gives the same summary, bit for bit.

/// The recording's file name in a run's output folder.
pub const RECORDING: &str = "run.mcap";

use std::fmt::Write as _;
use std::io::{BufRead, IsTerminal, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use run_records::outcome::HubOutcome;
pub use run_records::summary::{RobotSummary, RunSummary};
use sim_model::PoseDeg;

use crate::args::RunArgs;
use crate::chair::{self, ChairSummary};
use crate::metrics;
use crate::scenario::{ChairSpec, Scenario, option_flags};
use crate::signals::{Signal, Signals};

/// One robot's truth over a run, measured as the summary reports it.
struct Judge {
    s: RobotSummary,
    /// Whether the robot has been outside the next checkpoint of its route since it last
    /// reached one (or since it started): a checkpoint counts when the robot enters it, so one
    /// at its start pose is not reached at t = 0.
    armed: bool,
    speeds: Vec<(f64, f64)>,
    last: Option<(f64, f64, f64)>,
}

impl Judge {
    fn new(name: &str, route: &[usize], log: String) -> Self {
        Self {
            s: RobotSummary {
                name: name.to_owned(),
                log,
                route: route.to_vec(),
                checkpoints_reached: 0,
                checkpoints_total: route.len(),
                reached_at_s: Vec::new(),
                time_s: None,
                collisions: 0,
                ticks: 0,
                distance_m: 0.0,
                top_speed_mps: 0.0,
                rise_time_s: 0.0,
                final_pose: [0.0; 3],
                ..Default::default()
            },
            armed: false,
            speeds: Vec::new(),
            last: None,
        }
    }

    /// The robot at `t` seconds: where it truly is and how many contacts it has had.
    fn observe(&mut self, scenario: &Scenario, t: f64, [x, y, heading_deg]: PoseDeg, contacts: u64) {
        let s = &mut self.s;
        if let Some(&n) = s.route.get(s.checkpoints_reached)
            && let Some(c) = scenario.checkpoints.get(n.wrapping_sub(1))
        {
            if !c.contains(x, y) {
                self.armed = true;
            } else if self.armed {
                s.checkpoints_reached += 1;
                s.reached_at_s.push(t);
                self.armed = false;
            }
        }
        if let Some((t0, x0, y0)) = self.last {
            let d = (x - x0).hypot(y - y0);
            s.distance_m += d;
            if t > t0 {
                self.speeds.push((t, d / (t - t0)));
            }
        }
        s.ticks += 1;
        s.collisions = contacts;
        s.final_pose = [x, y, heading_deg];
        self.last = Some((t, x, y));
    }

    fn finish(mut self) -> RobotSummary {
        let s = &mut self.s;
        s.time_s = s.reached_at_s.last().copied();
        s.top_speed_mps = self.speeds.iter().map(|&(_, v)| v).fold(0.0, f64::max);
        let top = s.top_speed_mps;
        let first = |f: f64| self.speeds.iter().find(|&&(_, v)| v >= f * top).map(|&(t, _)| t);
        if let (Some(t10), Some(t90)) = (first(0.1), first(0.9)) {
            s.rise_time_s = t90 - t10;
        }
        self.s
    }
}

/// What a run's record says: every robot measured from the hub's truth (true poses, the
/// world's contact count), the world's final tick and state hash, and what a cut-short file
/// lost.
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    /// Every robot that was in the run, by name.
    pub robots: Vec<RobotSummary>,
    /// The world's last tick.
    pub ticks: u64,
    /// Its state hash then.
    pub state_hash: run_records::outcome::StateHash,
    /// Where a cut-short recording ends.
    pub truncated: Option<String>,
    /// The run's traffic, with two or more robots on routes.
    pub traffic: Option<run_records::summary::TrafficSummary>,
}

/// Replays a run's recording and measures every robot from the truth it holds (never from
/// what the agents under test wrote). `logs` is where the agents' CSV logs are, named in
/// each robot's summary when present.
pub fn judge_recording(path: &Path, scenario: &Scenario, logs: &Path) -> anyhow::Result<Judged> {
    let recording = recorder::Recording::open(path).with_context(|| format!("reading {}", path.display()))?;
    let dt = recording.start.dt_s;
    let mut judges: std::collections::BTreeMap<String, (usize, Judge)> = std::collections::BTreeMap::new();
    let start = &recording.start;
    let fixed = metrics::Fixed::new(
        start.lab.walls.iter().map(|w| metrics::Shape::new(w.corners.iter().map(|c| [c.x, c.y]))).collect(),
        start.obstacle_from,
        start.lab.width_m,
        start.lab.height_m,
    );
    let mut traffic = metrics::Traffic::new(fixed);
    let mut seen = Vec::new();
    let replayed = hub::replay::replay_observed(&recording, false, None, |stage| {
        let t = stage.world().tick() as f64 * dt;
        seen.clear();
        for id in stage.ids() {
            let Some(r) = stage.robot(id) else { continue };
            let next = judges.len();
            let (index, judge) = judges.entry(r.spec.name.clone()).or_insert_with(|| {
                let log = format!("{}.csv", robot_log::file_stem(&r.spec.name));
                let log = if logs.join(&log).exists() { log } else { String::new() };
                (next, Judge::new(&r.spec.name, scenario.routes.get(&r.spec.name).map_or(&[], Vec::as_slice), log))
            });
            judge.observe(scenario, t, [r.pose.x, r.pose.y, r.pose.heading_deg()], r.collision_count);
            let s = &judge.s;
            seen.push(metrics::Seen {
                index: *index,
                body: metrics::Shape::new(r.corners().iter().map(|c| [c.x, c.y])),
                pos: [r.pose.x, r.pose.y],
                contacts: r.collision_count,
                routed: !s.route.is_empty(),
                arrived: s.finished_route(),
            });
        }
        traffic.observe(t, &seen);
    })?;
    let robots: Vec<RobotSummary> = judges
        .into_values()
        .map(|(index, judge)| {
            let mut r = judge.finish();
            traffic.fill(index, &mut r);
            r
        })
        .collect();
    Ok(Judged {
        traffic: traffic.summary(&robots),
        robots,
        ticks: replayed.outcome.ticks,
        state_hash: replayed.outcome.state_hash,
        truncated: replayed.truncated,
    })
}

/// Checks a run against the scenario's expectations.
fn check(scenario: &Scenario, robots: &[RobotSummary]) -> Vec<String> {
    let mut failures = Vec::new();
    if let Some(max) = scenario.expect.max_collisions {
        for r in robots.iter().filter(|r| r.collisions > max) {
            failures.push(format!("{}: {} contacts (at most {max} expected)", r.name, r.collisions));
        }
    }
    let within = |v: f64, [lo, hi]: [f64; 2]| (lo..=hi).contains(&v);
    for (name, e) in &scenario.expect.robots {
        let Some(r) = robots.iter().find(|r| &r.name == name) else {
            failures.push(format!("{name}: no log (did its agent start?)"));
            continue;
        };
        if e.route && r.checkpoints_reached < r.checkpoints_total {
            failures.push(format!("{name}: reached {} of {} checkpoints", r.checkpoints_reached, r.checkpoints_total));
        }
        for (what, value, range) in [
            ("top speed", r.top_speed_mps, e.top_speed_mps),
            ("rise time", r.rise_time_s, e.rise_time_s),
            ("final heading", r.final_pose[2], e.final_heading_deg),
            ("final x", r.final_pose[0], e.final_x_m),
        ] {
            if let Some(range) = range
                && !within(value, range)
            {
                failures.push(format!("{name}: {what} {value:.4} outside [{}, {}]", range[0], range[1]));
            }
        }
    }
    failures
}

fn iwsim() -> anyhow::Result<PathBuf> {
    std::env::current_exe().context("finding the iwsim executable")
}

/// How long the run's processes get to stop before they are killed: the hub gives its agents
/// 2 s to read the final tick and leave, then exits.
const STOP_BOUND: Duration = Duration::from_secs(5);
/// How long an agent's failure waits for a look at the hub's world that tells whether the run
/// had ended (when the hub is not serving yet, no look comes); after that the failure stands.
const LOOK_BOUND: Duration = Duration::from_secs(3);
/// How long the agents get to leave once the hub has ended the run.
const AGENTS_LEAVE_BOUND: Duration = Duration::from_secs(20);
/// How long the viewer gets to leave once the hub has ended the run.
const VIEWER_LEAVE_BOUND: Duration = Duration::from_secs(10);
/// How long the runner waits for the viewer's address before going on without it.
const VIEWER_START_BOUND: Duration = Duration::from_secs(20);
/// How long the runner waits for the hub to accept its lab and options before starting the
/// agents anyway.
const HUB_START_BOUND: Duration = Duration::from_secs(30);
/// The hub's first line on stderr, printed once its lab and options are accepted: the agents
/// start after it, so a faulty lab is reported at once with no agent to stop.
const HUB_BANNER: &str = "iwsim hub: session";
/// How long the chair emulator gets to open its port and say where it is.
const EMULATOR_START_BOUND: Duration = Duration::from_secs(15);
/// How long the chair's adapter gets to reach the hub, the chair's board, and register the
/// chair's robot.
const CHAIR_REGISTER_BOUND: Duration = Duration::from_secs(30);
/// How long a stopping run waits for the chair's adapter to leave (it stops the chair within
/// a second) before it tells the emulator to stop too.
const ADAPTER_STOP_BOUND: Duration = Duration::from_secs(3);
/// How often the runner looks at its children and its signals.
const POLL: Duration = Duration::from_millis(5);

/// A child process of the run, killed if the run is abandoned.
struct Kid {
    child: Child,
    what: String,
    status: Option<ExitStatus>,
    /// The CPU time (user + system, seconds) it used, known once it is reaped.
    cpu_s: Option<f64>,
    /// The threads copying its stderr (and the chair emulator's stdout).
    readers: Vec<JoinHandle<()>>,
}

impl Kid {
    /// Starts `iwsim ARGS`; only the hub's stdout (its JSON summary) is kept.
    fn spawn(args: &[String], what: &str, keep_stdout: bool) -> anyhow::Result<Self> {
        Self::spawn_in(None, args, what, keep_stdout)
    }

    /// [`Kid::spawn`], in network namespace `netns` when given (`ip netns exec NS iwsim …`,
    /// which execs iwsim in place: the child is iwsim itself, and signals reach it).
    fn spawn_in(netns: Option<&str>, args: &[String], what: &str, keep_stdout: bool) -> anyhow::Result<Self> {
        let mut command = match netns {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns]).arg(iwsim()?);
                c
            }
            None => Command::new(iwsim()?),
        };
        command.args(args).stdin(Stdio::null()).stderr(Stdio::piped()).stdout(if keep_stdout {
            Stdio::piped()
        } else {
            Stdio::null()
        });
        crate::signals::unblock_in_child(&mut command);
        crate::signals::die_with_parent(&mut command);
        let child = command.spawn().with_context(|| format!("starting the {what}"))?;
        Ok(Self { child, what: what.to_owned(), status: None, cpu_s: None, readers: Vec::new() })
    }

    /// Copies the child's stderr, line by line, to `sink` (prefixed, unless the line already
    /// starts with the prefix's word, as agents' lines do: `navigator chair1: …`), on a thread.
    /// The first line containing `marker`'s text is also sent to `marker`'s channel.
    fn forward_stderr(
        &mut self,
        prefix: String,
        echo: bool,
        sink: Sender<String>,
        marker: Option<(&'static str, Sender<String>)>,
    ) {
        if let Some(err) = self.child.stderr.take() {
            self.readers.push(forward(err, prefix, echo, sink, marker));
        }
    }

    /// Copies the child's stdout as [`Kid::forward_stderr`] copies its stderr (the chair
    /// emulator says on stdout where its port is, and how its run went).
    fn forward_stdout(
        &mut self,
        prefix: String,
        echo: bool,
        sink: Sender<String>,
        marker: Option<(&'static str, Sender<String>)>,
    ) {
        if let Some(out) = self.child.stdout.take() {
            self.readers.push(forward(out, prefix, echo, sink, marker));
        }
    }

    /// How the child exited, if it has.
    fn exited(&mut self) -> Option<ExitStatus> {
        self.reap(false)
    }

    /// Reaps the child if it has exited (with `block`, once it has), and keeps how it exited
    /// and the CPU time it used: the run's `summary.json` states each process's CPU exactly,
    /// where sampling `/proc` from outside misses what a short-lived process did last.
    fn reap(&mut self, block: bool) -> Option<ExitStatus> {
        if self.status.is_some() {
            return self.status;
        }
        match os::process::reap(&self.child, block) {
            Ok(Some(r)) => {
                self.status = Some(r.status);
                self.cpu_s = Some(r.cpu_s);
            }
            Ok(None) => {}
            // Not ours to wait for any more (reaped elsewhere): std says how it ended.
            Err(_) => self.status = self.child.try_wait().ok().flatten(),
        }
        self.status
    }

    /// Sends `signal` to the child if it still runs.
    fn signal(&mut self, signal: i32) {
        if self.exited().is_none() {
            crate::signals::send(&self.child, signal);
        }
    }

    /// Kills the child if it still runs, and reaps it.
    fn kill(&mut self) {
        if self.exited().is_none() {
            let _ = self.child.kill();
            self.reap(true);
        }
    }

    /// What the child printed on stdout (read once it has exited).
    fn stdout(&mut self) -> String {
        let mut out = String::new();
        if let Some(mut so) = self.child.stdout.take() {
            use std::io::Read as _;
            let _ = so.read_to_string(&mut out);
        }
        out
    }

    /// The child's failure, if it exited unsuccessfully.
    fn failure(&self) -> Option<String> {
        self.status.filter(|s| !s.success()).map(|s| format!("the {} exited with {s}", self.what))
    }

    /// Waits for the threads reading its pipes, which end once the child has exited and its
    /// pipes closed.
    fn join_stderr(&mut self) {
        for t in self.readers.drain(..) {
            let _ = t.join();
        }
    }

    /// Its failure before the run's end: any exit, since it was to run until the end (an
    /// agent that exits with success before then is only done).
    fn early_exit(&self) -> String {
        match (self.failure(), self.status) {
            (Some(f), _) => f,
            (None, Some(s)) => format!("the {} exited ({s})", self.what),
            (None, None) => format!("the {} is still running", self.what),
        }
    }
}

/// Copies `pipe`, line by line, to `sink` on a thread (see [`Kid::forward_stderr`]).
fn forward(
    pipe: impl std::io::Read + Send + 'static,
    prefix: String,
    echo: bool,
    sink: Sender<String>,
    mut marker: Option<(&'static str, Sender<String>)>,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let word = prefix.trim_end_matches(": ").to_owned();
        for line in std::io::BufReader::new(pipe).lines().map_while(Result::ok) {
            if let Some((text, tx)) = &marker
                && line.contains(text)
            {
                let _ = tx.send(line.clone());
                marker = None;
            }
            let line = if !word.is_empty() && line.starts_with(&word) { line } else { format!("{prefix}{line}") };
            if echo {
                ipc_services::report!("{line}");
            }
            let _ = sink.send(line);
        }
    })
}

impl Drop for Kid {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Every process of a run.
struct Procs {
    hub: Kid,
    /// The physical chair's adapter (`iwsim serial`), a hub client like an agent.
    adapter: Option<Kid>,
    /// The chair emulator, which plays the physical chair.
    emulator: Option<Kid>,
    agents: Vec<Kid>,
    viewer: Option<Kid>,
    /// The Zenoh bridge of the agents run as on other machines.
    bridge: Option<Kid>,
}

/// One of the run's processes that the run needs until its end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Who {
    /// The agent with this index.
    Agent(usize),
    /// The chair's adapter.
    Adapter,
    /// The chair emulator.
    Emulator,
    /// The Zenoh bridge.
    Bridge,
}

impl Procs {
    fn all(&mut self) -> impl Iterator<Item = &mut Kid> {
        std::iter::once(&mut self.hub)
            .chain(self.adapter.iter_mut())
            .chain(self.emulator.iter_mut())
            .chain(self.agents.iter_mut())
            .chain(self.bridge.iter_mut())
            .chain(self.viewer.iter_mut())
    }

    fn kid(&mut self, who: Who) -> Option<&mut Kid> {
        match who {
            Who::Agent(k) => self.agents.get_mut(k),
            Who::Adapter => self.adapter.as_mut(),
            Who::Emulator => self.emulator.as_mut(),
            Who::Bridge => self.bridge.as_mut(),
        }
    }

    /// The first process the run still needed that has gone: an agent or the adapter that
    /// failed, or the emulator however it exited.
    fn first_failed(&mut self) -> Option<Who> {
        if self.emulator.as_mut().is_some_and(|e| e.exited().is_some()) {
            return Some(Who::Emulator);
        }
        if self.adapter.as_mut().is_some_and(|a| a.exited().is_some_and(|s| !s.success())) {
            return Some(Who::Adapter);
        }
        if self.bridge.as_mut().is_some_and(|a| a.exited().is_some_and(|s| !s.success())) {
            return Some(Who::Bridge);
        }
        self.agents.iter_mut().position(|a| a.exited().is_some_and(|s| !s.success())).map(Who::Agent)
    }

    /// Sends `signal` to every process still running, waits up to [`STOP_BOUND`] for them to
    /// exit, then kills the rest; returns what had to be killed. The chair emulator is told
    /// last, once the adapter has gone (or [`ADAPTER_STOP_BOUND`] has passed): the adapter
    /// stops the chair on its way out, and the chair must be there to hear it.
    fn stop(&mut self, signal: i32) -> Vec<String> {
        let mut emulator = self.emulator.take();
        self.all().for_each(|k| k.signal(signal));
        let until = Instant::now() + ADAPTER_STOP_BOUND;
        while self.adapter.as_mut().is_some_and(|a| a.exited().is_none()) && Instant::now() < until {
            std::thread::sleep(POLL);
        }
        if let Some(e) = &mut emulator {
            e.signal(signal);
        }
        self.emulator = emulator;
        let until = Instant::now() + STOP_BOUND;
        while self.all().any(|k| k.exited().is_none()) && Instant::now() < until {
            std::thread::sleep(POLL);
        }
        let mut killed = Vec::new();
        for k in self.all().filter(|k| k.status.is_none()) {
            k.kill();
            killed.push(k.what.clone());
        }
        killed
    }
}

/// What the runner's observer learnt of the hub's world, for the supervising loop.
#[derive(Debug, Default)]
struct Watch {
    /// The hub published its run's last tick.
    finished: AtomicBool,
    /// The physical chair's robot (registered by its adapter) is in the hub's world.
    chair_seen: AtomicBool,
    /// Looks at the world begun, and the last one completed (looks are numbered from 1).
    begun: AtomicU64,
    completed: AtomicU64,
}

impl Watch {
    /// Whether the run had ended, from a look begun after look number `after`: `None` until
    /// such a look has completed.
    fn run_ended(&self, after: u64) -> Option<bool> {
        let completed = self.completed.load(Ordering::SeqCst);
        if self.finished.load(Ordering::SeqCst) {
            Some(true)
        } else if completed > after {
            Some(false)
        } else {
            None
        }
    }
}

/// Why the supervising loop stopped.
enum Stop {
    /// The hub exited (the run's end, or its failure).
    HubExited,
    /// The runner was told to stop.
    Signal(Signal),
    /// A process the run needed failed before the run ended.
    Failed(Who),
    /// The physical chair did not come up (what went wrong).
    ChairFailed(String),
}

/// The viewer, from its start until it has printed its address.
struct ViewerStart {
    lines: Receiver<String>,
    since: Instant,
    /// The last line before the banner: a library's log line to skip, or the viewer's error
    /// if it then exits.
    last: Option<String>,
}

/// Waits until the hub has accepted its lab and options, exited, or the runner is told to stop.
fn hub_started(procs: &mut Procs, banner: &Receiver<String>, signals: &Signals) -> Option<Stop> {
    let since = Instant::now();
    loop {
        if let Some(signal) = signals.wait(POLL) {
            return Some(Stop::Signal(signal));
        }
        if procs.hub.exited().is_some() {
            return Some(Stop::HubExited);
        }
        match banner.try_recv() {
            Ok(_) => return None,
            // The hub closed its stderr without the banner: it is exiting, though its exit
            // may not show yet (on a loaded machine the pipe's end comes first).
            Err(TryRecvError::Disconnected) => {
                let closed = Instant::now();
                while closed.elapsed() < STOP_BOUND {
                    if procs.hub.exited().is_some() {
                        return Some(Stop::HubExited);
                    }
                    if let Some(signal) = signals.wait(POLL) {
                        return Some(Stop::Signal(signal));
                    }
                }
                return None;
            }
            Err(TryRecvError::Empty) if since.elapsed() > HUB_START_BOUND => return None,
            Err(TryRecvError::Empty) => {}
        }
    }
}

/// Watches the run until the hub exits, an agent fails before the run's end, or a signal
/// comes. Starts the viewer's page on the way (or drops the viewer if it does not start).
fn supervise(procs: &mut Procs, viewer: &mut Option<ViewerStart>, watch: &Watch, signals: &Signals) -> Stop {
    // The first failed process, the looks begun when it was seen, and when.
    let mut failed: Option<(Who, u64, Instant)> = None;
    loop {
        if let Some(signal) = signals.wait(POLL) {
            return Stop::Signal(signal);
        }
        if procs.hub.exited().is_some() {
            return Stop::HubExited;
        }
        if let Some(start) = viewer {
            // Lines before the banner (a library's warning on a loaded machine) are not a
            // failure: the viewer failed only if it exits or stays silent past the bound.
            let said = match start.lines.try_recv() {
                Ok(line) if line.contains("open http") => Some(Some(line)),
                Ok(line) => {
                    start.last = Some(line);
                    None
                }
                Err(TryRecvError::Disconnected) => Some(start.last.take()),
                Err(TryRecvError::Empty) => (start.since.elapsed() > VIEWER_START_BOUND).then(|| start.last.take()),
            };
            match said {
                Some(Some(line)) if line.contains("open http") => {
                    ipc_services::report!("{line}");
                    *viewer = None;
                }
                Some(line) => {
                    match line {
                        Some(line) => {
                            ipc_services::report!("iwsim run: the viewer did not start ({line}); going on headless")
                        }
                        None => ipc_services::report!("iwsim run: the viewer did not start; going on headless"),
                    }
                    procs.viewer = None;
                    *viewer = None;
                }
                None => {}
            }
        }
        if failed.is_none()
            && let Some(who) = procs.first_failed()
        {
            failed = Some((who, watch.begun.load(Ordering::SeqCst), Instant::now()));
        }
        // An agent that fails after the run's last tick (a navigator that did not arrive)
        // fails the run's outcome, and the hub ends on its own; one that fails before it
        // (a bad option, a start pose off the map) would leave the hub waiting for it.
        if let Some((who, after, at)) = failed {
            match watch.run_ended(after) {
                Some(true) => {}
                Some(false) => return Stop::Failed(who),
                None if at.elapsed() > LOOK_BOUND => return Stop::Failed(who),
                None => {}
            }
        }
    }
}

/// The end of one run.
#[derive(Debug)]
pub struct RunEnd {
    /// What happened (partial if interrupted), as written to `summary.json`.
    pub summary: RunSummary,
    /// What happened to the physical chair, in a run with one (`"chair"` in `summary.json`).
    pub chair: Option<ChairSummary>,
    /// The signal that stopped the run before its end.
    pub interrupted: Option<Signal>,
}

/// How to run a scenario once.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Lock-step (as fast as the agents allow) instead of real time.
    pub lockstep: bool,
    /// The viewer (none when `headless`).
    pub viewer: crate::args::ViewerArgs,
    /// Print progress and the agents' messages.
    pub verbose: bool,
    /// The session (default: a unique `run-<pid>-<seed>-<n>`).
    pub session: Option<String>,
    /// More options for `iwsim hub` (e.g. `--threads 2`).
    pub hub_options: Vec<String>,
    /// Agents run as on other machines, through a Zenoh bridge.
    pub zenoh: Option<ZenohRun>,
}

/// Which of a scenario's agents join through Zenoh (`--zenoh-agents`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ZenohAgents {
    /// Every agent.
    All,
    /// These agents, numbered from 1 as the scenario lists them.
    Some(Vec<usize>),
}

impl ZenohAgents {
    /// Parses `all` or `1,3`.
    pub fn parse(text: &str) -> Result<Self, String> {
        if text.trim() == "all" {
            return Ok(Self::All);
        }
        let numbers = text
            .split(',')
            .map(|n| match n.trim().parse::<usize>() {
                Ok(k) if k >= 1 => Ok(k),
                _ => Err(format!("{n:?} is not an agent number (1, 2, …)")),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self::Some(numbers))
    }

    /// Whether agent `index` (from 0) is one of them.
    fn includes(&self, index: usize) -> bool {
        match self {
            Self::All => true,
            Self::Some(v) => v.contains(&(index + 1)),
        }
    }
}

/// Agents of a run through Zenoh: which, where the bridge listens, and which network
/// namespace they run in.
#[derive(Debug, Clone)]
pub struct ZenohRun {
    /// Which agents.
    pub agents: ZenohAgents,
    /// The bridge's listen endpoint (a free loopback port when `None`).
    pub listen: Option<String>,
    /// A network namespace for those agents.
    pub netns: Option<String>,
}

impl ZenohRun {
    /// The endpoint the bridge listens on, and the one its agents connect to.
    fn endpoints(&self) -> anyhow::Result<(String, String)> {
        let listen = match &self.listen {
            Some(e) => e.clone(),
            None => {
                // The kernel's free port of the moment: nothing holds it until the bridge binds
                // it a moment later, which is as good as a fixed port and never clashes with a
                // run beside this one.
                let l = std::net::TcpListener::bind("127.0.0.1:0").context("finding a free port for the bridge")?;
                format!("tcp/127.0.0.1:{}", l.local_addr()?.port())
            }
        };
        let connect = listen.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:");
        Ok((listen, connect))
    }
}

/// The physical chair of one run: the scenario's `[chair]` and where its files go.
struct ChairRun<'a> {
    spec: &'a ChairSpec,
    stepped: bool,
    lab: String,
    link: PathBuf,
    truth: PathBuf,
}

/// Starts the physical chair — the emulator, then (once its port is open) the adapter — and
/// waits until the adapter has registered the chair's robot in the hub's world, so that the
/// agent of that name attaches to it as its controller instead of adding a robot of its own.
/// `None` once it is there; otherwise why the run stops.
fn chair_started(
    procs: &mut Procs,
    chair: &ChairRun<'_>,
    session: &str,
    seed: u64,
    (tx, verbose): (&Sender<String>, bool),
    watch: &Watch,
    signals: &Signals,
) -> anyhow::Result<Option<Stop>> {
    let args = chair::emulator_args(chair.spec, &chair.lab, seed, chair.stepped, &chair.link, &chair.truth);
    let mut emulator = Kid::spawn(&args, "chair emulator", true)?;
    let prefix = chair::EMULATOR_BANNER.to_owned();
    let (port_tx, port) = std::sync::mpsc::channel();
    emulator.forward_stderr(prefix.clone(), verbose, tx.clone(), None);
    emulator.forward_stdout(prefix, verbose, tx.clone(), Some((chair::EMULATOR_BANNER, port_tx)));
    procs.emulator = Some(emulator);
    // Common to both waits: what ends the run before the chair is up.
    let gone = |procs: &mut Procs| -> Option<Stop> {
        if let Some(signal) = signals.wait(POLL) {
            Some(Stop::Signal(signal))
        } else if procs.hub.exited().is_some() {
            Some(Stop::HubExited)
        } else if procs.emulator.as_mut().is_some_and(|e| e.exited().is_some()) {
            Some(Stop::Failed(Who::Emulator))
        } else if procs.adapter.as_mut().is_some_and(|a| a.exited().is_some()) {
            Some(Stop::Failed(Who::Adapter))
        } else {
            None
        }
    };
    let since = Instant::now();
    let mut announced = false;
    // The banner comes once the port is open; the link is made beside it, in either order.
    while !(announced && chair.link.symlink_metadata().is_ok()) {
        if let Some(stop) = gone(procs) {
            return Ok(Some(stop));
        }
        announced |= port.try_recv().is_ok();
        if since.elapsed() > EMULATOR_START_BOUND {
            return Ok(Some(Stop::ChairFailed(format!(
                "the chair emulator did not {} within {EMULATOR_START_BOUND:?}",
                if announced {
                    format!("link its port at {}", chair.link.display())
                } else {
                    "say where its port is".into()
                }
            ))));
        }
    }
    let mode = chair.spec.mode;
    let mut adapter = Kid::spawn(
        &chair::adapter_args(chair.spec, mode, session, chair.stepped, &chair.link),
        "chair adapter",
        false,
    )?;
    adapter.forward_stderr("serial: ".into(), verbose, tx.clone(), None);
    procs.adapter = Some(adapter);
    let since = Instant::now();
    while !watch.chair_seen.load(Ordering::SeqCst) {
        if let Some(stop) = gone(procs) {
            return Ok(Some(stop));
        }
        if since.elapsed() > CHAIR_REGISTER_BOUND {
            return Ok(Some(Stop::ChairFailed(format!(
                "the chair adapter did not register robot {} in the hub within {CHAIR_REGISTER_BOUND:?}",
                chair.spec.robot
            ))));
        }
    }
    Ok(None)
}

/// `iwsim hub`'s command line for a run of `scenario` with `seed`, recording to `recording`.
fn hub_command(
    scenario: &Scenario,
    seed: u64,
    session: &str,
    recording: &Path,
    chair: Option<&ChairRun>,
    opts: &RunOptions,
) -> Vec<String> {
    let s = |x: &str| x.to_owned();
    let mut hub_args = vec![
        s("hub"),
        s("--session"),
        session.to_owned(),
        s("--lab"),
        scenario.lab_spec(),
        s("--cycle-ms"),
        scenario.cycle_ms.to_string(),
        s("--seed"),
        seed.to_string(),
        s("--ticks"),
        scenario.ticks().to_string(),
        s("--wait-agents"),
        // The chair's adapter is a hub client too.
        (scenario.agents.len() + chair.is_some() as usize).to_string(),
        s("--json"),
        s("--record"),
        recording.display().to_string(),
    ];
    if let Some(g) = scenario.grid_spec() {
        hub_args.extend([s("--grid"), g]);
    }
    if opts.lockstep {
        hub_args.extend([s("--lockstep"), s("--deadline-ms"), scenario.deadline_ms().to_string()]);
    }
    if !scenario.noise {
        hub_args.push(s("--no-noise"));
    }
    for o in &scenario.obstacles {
        hub_args.extend([s("--obstacle"), o.to_string()]);
    }
    for c in &scenario.checkpoints {
        hub_args.extend([s("--checkpoint"), c.to_string()]);
    }
    if let Some(c) = &chair {
        // The physical chair is the run's one Real robot: its adapter pushes its pose.
        hub_args.extend([s("--real"), c.spec.robot.clone()]);
    }
    hub_args.extend(opts.hub_options.iter().cloned());
    hub_args
}

/// Runs `scenario` once with `seed`, writing logs and `summary.json` into `out`. A signal
/// stops every process of the run and gives a partial summary; a process that fails before
/// the run's end stops the rest and gives an error.
pub fn run_once(
    scenario: &Scenario,
    seed: u64,
    out: &Path,
    opts: &RunOptions,
    signals: &Signals,
) -> anyhow::Result<RunEnd> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for e in std::fs::read_dir(out)?.flatten() {
        if e.path().extension().is_some_and(|x| x == "csv" || x == "mcap") {
            std::fs::remove_file(e.path())?;
        }
    }
    let chair = scenario.chair.as_ref().map(|spec| ChairRun {
        spec,
        stepped: chair::stepped(spec, opts.lockstep),
        lab: scenario.chair_lab_spec().unwrap_or_else(|| scenario.lab_spec()),
        link: out.join(chair::LINK),
        truth: out.join(chair::TRUTH),
    });
    if let Some(c) = &chair {
        // A previous run's: this run's emulator writes its own, and a stale link would lead
        // the adapter to a port that is gone.
        for f in [&c.link, &c.truth] {
            if f.symlink_metadata().is_ok() {
                std::fs::remove_file(f).with_context(|| format!("removing {}", f.display()))?;
            }
        }
    }
    let recording = out.join(RECORDING);
    let session =
        opts.session.clone().unwrap_or_else(|| format!("run-{}-{seed}-{}", std::process::id(), crate::run::unique()));
    let ticks = scenario.ticks();
    let hub_args = hub_command(scenario, seed, &session, &recording, chair.as_ref(), opts);
    let s = |x: &str| x.to_owned();
    let started = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let (banner_tx, banner) = std::sync::mpsc::channel();
    let mut procs = Procs {
        hub: Kid::spawn(&hub_args, "hub", true)?,
        adapter: None,
        emulator: None,
        agents: Vec::new(),
        viewer: None,
        bridge: None,
    };
    procs.hub.forward_stderr(s("hub: "), false, tx.clone(), Some((HUB_BANNER, banner_tx)));
    let watch = std::sync::Arc::new(Watch::default());
    let (stop_watch, stopped) = std::sync::mpsc::channel::<()>();
    let mut watcher = None;
    let stop = match hub_started(&mut procs, &banner, signals) {
        Some(stop) => stop,
        None => {
            // The observer: progress every few seconds on long runs, whether the chair's
            // robot is in, and whether the run had ended when an agent fails.
            watcher = Some({
                let (session, watch, verbose) = (session.clone(), watch.clone(), opts.verbose);
                let robot = chair.as_ref().map(|c| c.spec.robot.clone());
                std::thread::spawn(move || watch_loop(&session, ticks, verbose, robot.as_deref(), &watch, &stopped))
            });
            let chair_stop = match &chair {
                Some(c) => {
                    if opts.verbose {
                        ipc_services::report!(
                            "iwsim run: starting the chair emulator and its adapter ({} sensors{})",
                            c.spec.mode.as_str(),
                            if c.stepped { ", stepped clock" } else { "" }
                        );
                    }
                    chair_started(&mut procs, c, &session, seed, (&tx, opts.verbose), &watch, signals)?
                }
                None => None,
            };
            match chair_stop {
                Some(stop) => stop,
                None => {
                    if opts.verbose {
                        ipc_services::report!(
                            "iwsim run: the hub serves session {session}; starting {} agent(s)",
                            scenario.agents.len()
                        );
                    }
                    start_agents(&mut procs, scenario, &session, out, opts, &tx)?;
                    let mut viewer_start = start_viewer(&mut procs, &session, opts)?;
                    supervise(&mut procs, &mut viewer_start, &watch, signals)
                }
            }
        }
    };
    drop(tx);
    let (interrupted, agent_failures, failure) = wind_down(&mut procs, stop, signals);
    // Every process is gone: collect what they said, and leave nothing of the session behind
    // (a process killed above could not remove its files itself).
    drop(stop_watch);
    if let Some(w) = watcher {
        let _ = w.join();
    }
    procs.all().for_each(Kid::join_stderr);
    if let Ok(s) = ipc_services::Session::new(&session) {
        s.release_if_unused();
    }
    let messages: Vec<String> = rx.try_iter().collect();
    // A run that failed (a process it needed died, the hub failed or was killed) still gets
    // its summary, partial, saying what ended it: the record holds what happened up to there.
    if let Some(failure) = &failure {
        ipc_services::report!(
            "iwsim run: the run failed: {failure}; what the processes said:\n{}",
            messages.join("\n")
        );
    }
    let hub_out = procs.hub.stdout();
    let Verdict { ticks, state_hash, failures, robots, traffic, chair: chair_summary } =
        judge(scenario, out, &hub_out, chair.as_ref(), interrupted, failure, agent_failures)?;
    let cpu_s = procs.all().filter_map(|k| Some((k.what.clone(), k.cpu_s?))).collect();
    let summary = RunSummary {
        scenario: scenario.name.clone(),
        seed,
        ticks,
        state_hash,
        wall_s: started.elapsed().as_secs_f64(),
        passed: failures.is_empty(),
        failures,
        lab: scenario.lab_spec(),
        obstacles: scenario.obstacles.clone(),
        checkpoints: scenario.checkpoints.clone(),
        robots,
        traffic,
        cpu_s,
    };
    let text = chair::summary_json(&summary, chair_summary.as_ref()).context("writing summary.json")?;
    std::fs::write(out.join("summary.json"), text)?;
    Ok(RunEnd { summary, chair: chair_summary, interrupted })
}

/// Ends a run's processes as `stop` says: on a signal, forwarded to every child; on a failure,
/// the others stopped; at the run's end, each left to go in its order (agents and the chair's
/// adapter, then the emulator, then the viewer), killed past its bound. Returns the signal
/// that interrupted the run, what the runner saw go wrong with an agent, and what ended the
/// run early.
fn wind_down(procs: &mut Procs, stop: Stop, signals: &Signals) -> (Option<Signal>, Vec<String>, Option<String>) {
    let mut interrupted = None;
    let mut agent_failures = Vec::new();
    let failure = match stop {
        Stop::Signal(signal) => {
            ipc_services::report!(
                "iwsim run: {} received; stopping the hub, {} agent(s){}{}",
                signal.name(),
                procs.agents.len(),
                if procs.emulator.is_some() { ", the chair emulator and its adapter" } else { "" },
                if procs.viewer.is_some() { " and the viewer" } else { "" }
            );
            interrupted = Some(signal);
            for what in procs.stop(signal.forwarded()) {
                ipc_services::report!("iwsim run: the {what} did not stop within {STOP_BOUND:?}; killed it");
            }
            None
        }
        Stop::Failed(who) => {
            let failure = procs.kid(who).map(|k| k.early_exit()).unwrap_or_default();
            procs.stop(libc::SIGTERM);
            Some(format!("{failure} before the run ended; stopped the hub and the other processes"))
        }
        Stop::ChairFailed(why) => {
            procs.stop(libc::SIGTERM);
            Some(format!("{why}; stopped the hub and the other processes"))
        }
        Stop::HubExited => match procs.hub.failure() {
            Some(failure) => {
                procs.stop(libc::SIGTERM);
                Some(failure)
            }
            None => {
                // The run's end: the agents (and the chair's adapter, which stops the chair)
                // write their last rows and leave, then the chair emulator, then the viewer.
                let until = Instant::now() + AGENTS_LEAVE_BOUND;
                let mut signal = None;
                while signal.is_none()
                    && procs
                        .agents
                        .iter_mut()
                        .chain(procs.adapter.iter_mut())
                        .chain(procs.bridge.iter_mut())
                        .any(|a| a.exited().is_none())
                {
                    if Instant::now() > until {
                        break;
                    }
                    signal = signals.wait(POLL);
                }
                for a in procs.agents.iter_mut().chain(procs.adapter.iter_mut()).chain(procs.bridge.iter_mut()) {
                    if a.exited().is_none() && signal.is_none() {
                        a.kill();
                        agent_failures.push(format!(
                            "the {} did not exit within {AGENTS_LEAVE_BOUND:?} after the run ended; killed it",
                            a.what
                        ));
                    } else if let Some(f) = a.failure() {
                        agent_failures.push(f);
                    }
                }
                if signal.is_none()
                    && let Some(e) = &mut procs.emulator
                {
                    // It runs until told: the run has no more use for it.
                    e.signal(libc::SIGTERM);
                    let until = Instant::now() + STOP_BOUND;
                    while signal.is_none() && e.exited().is_none() && Instant::now() < until {
                        signal = signals.wait(POLL);
                    }
                    if e.exited().is_none() && signal.is_none() {
                        e.kill();
                        agent_failures.push(format!("the {} did not stop within {STOP_BOUND:?}; killed it", e.what));
                    } else if let Some(f) = e.failure() {
                        agent_failures.push(f);
                    }
                }
                let until = Instant::now() + VIEWER_LEAVE_BOUND;
                while signal.is_none()
                    && procs.viewer.as_mut().is_some_and(|v| v.exited().is_none())
                    && Instant::now() < until
                {
                    signal = signals.wait(POLL);
                }
                if let Some(signal) = signal {
                    ipc_services::report!("iwsim run: {} received; stopping what is left of the run", signal.name());
                    interrupted = Some(signal);
                    procs.stop(signal.forwarded());
                }
                procs.viewer.take();
                None
            }
        },
    };
    (interrupted, agent_failures, failure)
}

/// Starts the scenario's agents (and, for agents run as on other machines, the Zenoh bridge
/// they join through), each with its options, config file and log folder.
fn start_agents(
    procs: &mut Procs,
    scenario: &Scenario,
    session: &str,
    out: &Path,
    opts: &RunOptions,
    tx: &std::sync::mpsc::Sender<String>,
) -> anyhow::Result<()> {
    let s = |x: &str| x.to_owned();
    let zenoh = match &opts.zenoh {
        Some(z) => {
            let (listen, connect) = z.endpoints()?;
            let args = vec![
                s("zenoh"),
                s("--session"),
                session.to_owned(),
                s("--listen"),
                listen,
                s("--connect-timeout"),
                s("30"),
            ];
            let mut kid = Kid::spawn(&args, "Zenoh bridge", false)?;
            kid.forward_stderr(s("zenoh: "), opts.verbose, tx.clone(), None);
            procs.bridge = Some(kid);
            Some((z, connect))
        }
        None => None,
    };
    for (k, a) in scenario.agents.iter().enumerate() {
        let ros2 = a.kind == "ros2";
        let mut args = if ros2 {
            // The ROS 2 bridge: its chairs are driven from ROS 2 (no logs of its own).
            vec![s("ros2"), s("--session"), session.to_owned(), s("--connect-timeout"), s("30")]
        } else {
            vec![
                s("agent"),
                a.kind.clone(),
                s("--session"),
                session.to_owned(),
                s("--connect-timeout"),
                s("30"),
                s("--log"),
                out.display().to_string(),
            ]
        };
        if let Some(cfg) = &a.config {
            let path = out.join(format!("agent{}-{}.toml", k + 1, a.kind));
            std::fs::write(&path, toml::to_string(cfg).context("writing an agent's config")?)?;
            args.extend([s("--config"), path.display().to_string()]);
        }
        args.extend(option_flags(&a.options).map_err(|e| anyhow::anyhow!("agent {} ({}): {e}", k + 1, a.kind))?);
        let mut netns = None;
        if let Some((z, connect)) = &zenoh
            && z.agents.includes(k)
            && !ros2
        {
            // Agents retry for their --connect-timeout while the bridge comes up.
            args.extend([s("--zenoh"), connect.clone()]);
            netns = z.netns.as_deref();
        }
        let mut kid = Kid::spawn_in(netns, &args, &format!("agent {} ({})", k + 1, a.kind), false)?;
        kid.forward_stderr(format!("{}: ", a.kind), opts.verbose, tx.clone(), None);
        procs.agents.push(kid);
    }
    Ok(())
}

/// Starts the viewer unless the run is headless; what it says is watched for its address.
fn start_viewer(procs: &mut Procs, session: &str, opts: &RunOptions) -> anyhow::Result<Option<ViewerStart>> {
    let s = |x: &str| x.to_owned();
    let mut viewer_start = None;
    if !opts.viewer.headless {
        let mut args = vec![s("view"), s("--session"), session.to_owned(), s("--http"), opts.viewer.http.to_string()];
        if opts.viewer.allow_control {
            args.push(s("--allow-control"));
        }
        for h in &opts.viewer.allow_host {
            args.extend([s("--allow-host"), h.clone()]);
        }
        let mut v = Kid::spawn(&args, "viewer", false)?;
        let (vtx, lines) = std::sync::mpsc::channel();
        v.forward_stderr(String::new(), false, vtx, None);
        procs.viewer = Some(v);
        viewer_start = Some(ViewerStart { lines, since: Instant::now(), last: None });
    }
    Ok(viewer_start)
}

/// How a run went, judged from the hub's record (and the chair emulator's ground truth):
/// what [`run_once`] writes to `summary.json` besides the run's own figures.
struct Verdict {
    ticks: u64,
    state_hash: run_records::outcome::StateHash,
    failures: Vec<String>,
    robots: Vec<run_records::summary::RobotSummary>,
    traffic: Option<run_records::summary::TrafficSummary>,
    chair: Option<ChairSummary>,
}

/// Judges a run that has ended (every process gone) from its record in `out`: the hub's last
/// words `hub_out`, the signal that `interrupted` it or the `failure` that ended it early,
/// and the `agent_failures` the runner saw.
fn judge(
    scenario: &Scenario,
    out: &Path,
    hub_out: &str,
    chair: Option<&ChairRun>,
    interrupted: Option<Signal>,
    failure: Option<String>,
    agent_failures: Vec<String>,
) -> anyhow::Result<Verdict> {
    let recording = out.join(RECORDING);
    let ended_early = interrupted.is_some() || failure.is_some();
    let hub_said = HubOutcome::from_stdout(hub_out);
    let hub_outcome = match &hub_said {
        Ok(o) => o.clone(),
        // A hub interrupted or killed may have had no time to say how far it got.
        Err(_) if ended_early => HubOutcome::default(),
        Err(e) => return Err(anyhow::anyhow!("{e}")).context("reading how the hub's run ended"),
    };
    let mut recorded_end = None;
    // The record is the judge: the hub's truth, replayed; never what the agents wrote.
    let mut failures = Vec::new();
    let mut traffic = None;
    let robots = match judge_recording(&recording, scenario, out) {
        Ok(judged) => {
            traffic = judged.traffic;
            recorded_end = Some((judged.ticks, judged.state_hash));
            if let Some(lost) = &judged.truncated {
                failures.push(format!("{}: {lost}", recording.display()));
            } else if !ended_early && judged.state_hash != hub_outcome.state_hash {
                failures.push(format!(
                    "the record replays to state hash {} but the hub ended on {}",
                    judged.state_hash, hub_outcome.state_hash
                ));
            }
            judged.robots
        }
        // A recording cut short by the interruption still says what it can.
        Err(e) if ended_early => {
            failures.push(format!("{e:#}"));
            Vec::new()
        }
        Err(e) => return Err(e),
    };
    // The physical chair is judged in both worlds: the hub's record above (the pose its
    // adapter pushed), and the emulator's ground truth of the room.
    let chair_summary = chair.as_ref().map(|c| {
        let truth = chair::read_truth(&c.truth).unwrap_or_else(|e| {
            failures.push(format!("the chair's ground truth: {e}"));
            chair::RoomTruth::default()
        });
        let robot = robots.iter().find(|r| r.name == c.spec.robot);
        let sim = robot.map_or(0, |r| r.collisions);
        ChairSummary::new(scenario, c.spec, c.spec.mode, c.stepped, sim, robot.map(|r| r.final_pose), &truth)
    });
    // Where the hub said nothing, the record says how far the run got.
    let (ticks, state_hash) = match (&hub_said, recorded_end) {
        (Err(_), Some(end)) => end,
        _ => (hub_outcome.ticks, hub_outcome.state_hash),
    };
    if let Some(signal) = interrupted {
        failures.push(format!("interrupted by {} at tick {ticks}", signal.name()));
    } else if let Some(failure) = failure {
        failures.push(format!("ended at tick {ticks}: {failure}"));
    } else {
        failures.extend(check(scenario, &robots));
        failures.extend(chair_summary.as_ref().and_then(|c| c.room_failure(scenario.expect.max_collisions)));
    }
    // An agent that fails (a navigator that did not arrive exits 1) fails the run's outcome,
    // not the runner: the summary still says what happened.
    failures.extend(agent_failures);
    Ok(Verdict { ticks, state_hash, failures, robots, traffic, chair: chair_summary })
}

/// A number unique within this process, for session names.
pub fn unique() -> u32 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

/// Observes the session until the hub ends the run or `stop` is dropped: records in `watch`
/// what it sees (and whether the physical chair's robot `chair` is in), and (if `verbose`)
/// prints how far the run is every two seconds.
fn watch_loop(session: &str, ticks: u64, verbose: bool, chair: Option<&str>, watch: &Watch, stop: &Receiver<()>) {
    let stopped = || matches!(stop.recv_timeout(Duration::from_millis(20)), Err(RecvTimeoutError::Disconnected));
    // Short attempts, so that a run that ends before its hub serves does not wait for this.
    let mut obs = loop {
        match observer::Observer::connect_within(session, "iwsim-run-progress", Duration::from_millis(100)) {
            Ok(obs) => break obs,
            Err(_) if stopped() => return,
            Err(_) => {}
        }
    };
    let tty = std::io::stderr().is_terminal();
    let mut last_print = Instant::now();
    let mut last_tick = 0;
    loop {
        let look = watch.begun.fetch_add(1, Ordering::SeqCst) + 1;
        let seen = obs.try_world();
        if let Ok(Some((h, robots))) = &seen {
            last_tick = h.tick;
            if let Some(name) = chair
                && obs.refresh_robot_info().is_ok()
                && obs
                    .robot_infos()
                    .iter()
                    .any(|i| i.name.as_str() == Some(name) && robots.iter().any(|r| r.id == i.robot_id))
            {
                watch.chair_seen.store(true, Ordering::SeqCst);
            }
            if h.run_state == ipc_types::RunState::Finished as u32 {
                watch.finished.store(true, Ordering::SeqCst);
            }
        }
        watch.completed.store(look, Ordering::SeqCst);
        // A fast lock-step run may end before the observer sees its last snapshot.
        if seen.is_err() || watch.finished.load(Ordering::SeqCst) {
            break;
        }
        if verbose && last_print.elapsed() >= Duration::from_secs(2) {
            let pct = 100.0 * last_tick as f64 / ticks.max(1) as f64;
            if tty {
                eprint!("\r  tick {last_tick} / {ticks} ({pct:.0} %)   ");
            } else {
                ipc_services::report!("  tick {last_tick} / {ticks} ({pct:.0} %)");
            }
            last_print = Instant::now();
        }
        if stopped() {
            break;
        }
    }
    if verbose && tty {
        eprint!("\r{:40}\r", "");
    }
    obs.close();
}

/// Prints a run's summary table; with a physical chair, its contacts in both worlds (the
/// simulator's and the emulator's room) and its true final pose.
pub fn print_summary(s: &RunSummary, chair: Option<&ChairSummary>, out: &Path) {
    println!(
        "scenario {} seed {}: {} ticks, state hash {}, {:.1} s wall clock",
        s.scenario, s.seed, s.ticks, s.state_hash, s.wall_s
    );
    let (contacts, w, room) = match chair {
        Some(_) => ("contacts (sim)", 14, " contacts (room)"),
        None => ("contacts", 10, ""),
    };
    println!(
        "  {:<10} {:>11} {:>9} {:>w$} {:>9} {:>10} {:>9}{room}",
        "robot", "checkpoints", "time s", contacts, "driven m", "top m/s", "rise s"
    );
    for r in &s.robots {
        let room = match chair {
            Some(c) if c.robot == r.name => format!(" {:>15}", c.contacts_room),
            Some(_) => format!(" {:>15}", "-"),
            None => String::new(),
        };
        println!(
            "  {:<10} {:>11} {:>9} {:>w$} {:>9.2} {:>10.3} {:>9.1}{room}",
            r.name,
            format!("{}/{}", r.checkpoints_reached, r.checkpoints_total),
            r.reached_at_s.last().map_or("-".to_owned(), |t| format!("{t:.1}")),
            r.collisions,
            r.distance_m,
            r.top_speed_mps,
            r.rise_time_s
        );
    }
    if let Some(c) = chair {
        println!("  {}", c.line());
    }
    if let Some(t) = &s.traffic {
        print_traffic(s, t);
    }
    if s.passed {
        println!("  expected outcome: PASS");
    } else {
        for f in &s.failures {
            println!("  FAIL: {f}");
        }
    }
    println!("  logs, the recording (run.mcap) and summary.json in {}", out.display());
}

/// The traffic of a run of many chairs: per robot its clearances, contacts by kind and time
/// stood still short of its goal, then the run's measures.
fn print_traffic(s: &RunSummary, t: &run_records::summary::TrafficSummary) {
    let m = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.3}"));
    println!(
        "  {:<10} {:>8} {:>13} {:>13} {:>24} {:>8}",
        "robot", "arrived", "clear wall m", "clear chair m", "contacts chair/wall/obst", "still s"
    );
    for r in s.robots.iter().filter(|r| !r.route.is_empty()) {
        println!(
            "  {:<10} {:>8} {:>13} {:>13} {:>24} {:>8.1}",
            r.name,
            if r.arrived { "yes" } else { "NO" },
            m(r.min_clearance_wall_m),
            m(r.min_clearance_chair_m),
            format!("{}/{}/{}", r.contacts_chair, r.contacts_wall, r.contacts_obstacle),
            r.still_s
        );
    }
    println!(
        "  traffic: {}/{} arrived ({:.0} %), makespan {}, sum of times {:.1} s, {} deadlock(s), {:.2} arrivals/min, contacts {} chair-chair, {} wall, {} obstacle",
        t.arrived,
        t.chairs,
        t.success_rate * 100.0,
        t.makespan_s.map_or("- (not all arrived)".to_owned(), |v| format!("{v:.1} s")),
        t.sum_of_times_s,
        t.deadlocks,
        t.throughput_per_min,
        t.contacts_chair,
        t.contacts_wall,
        t.contacts_obstacle
    );
}

/// A run's exit code: 0 when the expected outcome holds, 1 when not, and 128 + the signal's
/// number when a signal stopped it (as a shell reports a process the signal killed).
pub fn exit_code(end: &RunEnd) -> ExitCode {
    match end.interrupted {
        Some(signal) => ExitCode::from(signal.exit_code()),
        None if end.summary.passed => ExitCode::SUCCESS,
        None => ExitCode::FAILURE,
    }
}

/// Parses `A..B` (inclusive).
pub fn parse_seeds(text: &str) -> Result<std::ops::RangeInclusive<u64>, String> {
    let (a, b) = text.split_once("..").ok_or_else(|| format!("--seeds {text}: expected A..B, e.g. 1..20"))?;
    let a: u64 = a.trim().parse().map_err(|_| format!("--seeds {text}: {a:?} is not a number"))?;
    let b: u64 =
        b.trim().trim_start_matches('=').parse().map_err(|_| format!("--seeds {text}: {b:?} is not a number"))?;
    if a > b {
        return Err(format!("--seeds {text}: the first seed is after the last"));
    }
    Ok(a..=b)
}

/// `iwsim run`.
pub fn run(args: &RunArgs) -> anyhow::Result<ExitCode> {
    // First, before any thread starts (see `signals`).
    let signals = Signals::install()?;
    let scenario = scenario_of(args)?;
    if args.describe {
        println!("{}", serde_json::to_string_pretty(&scenario.describe())?);
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(session) = &args.session {
        ipc_services::Session::new(session)?;
    }
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("runs/{}", scenario.name)));
    let opts = run_options(args);
    let Some(seeds) = &args.seeds else {
        let seed = args.seed.unwrap_or(scenario.seed);
        ipc_services::report!(
            "iwsim run: {} ({}), seed {seed}, {} s simulated in {}",
            scenario.name,
            scenario.description,
            scenario.seconds,
            if opts.lockstep { "lock-step" } else { "real time" }
        );
        let scenario = scenario.populated(seed).map_err(|e| anyhow::anyhow!("scenario {}: {e}", scenario.name))?;
        let end = run_once(&scenario, seed, &out, &opts, &signals)?;
        print_summary(&end.summary, end.chair.as_ref(), &out);
        return Ok(exit_code(&end));
    };
    let seeds = parse_seeds(seeds).map_err(anyhow::Error::msg)?;
    run_batch(&scenario, seeds, &out, &opts, &signals, args.quiet)
}

/// The scenario `iwsim run` names, with its command line's overrides applied.
fn scenario_of(args: &RunArgs) -> anyhow::Result<Scenario> {
    let mut scenario = Scenario::load(&args.scenario)?;
    if let Some(mode) = args.chair_mode {
        scenario.set_chair_mode(mode).map_err(|e| anyhow::anyhow!("--chair-mode {}: {e}", mode.as_str()))?;
    }
    if let Some(ms) = args.deadline_ms {
        scenario.deadline_ms = Some(ms);
    }
    if args.chair_odometry_only {
        let name = scenario.name.clone();
        let chair = scenario.chair.as_mut().ok_or_else(|| {
            anyhow::anyhow!("--chair-odometry-only: scenario {name} has no [chair] to run on odometry")
        })?;
        chair.localise = false;
    }
    if let Some(n) = args.chairs {
        let crowd = scenario.crowd.get_or_insert_with(|| crate::crowd::Crowd::of(n));
        crowd.chairs = n;
        crowd.check().map_err(|e| anyhow::anyhow!("--chairs {n}: {e}"))?;
    }
    Ok(scenario)
}

/// How `iwsim run`'s command line asks each run to go.
fn run_options(args: &RunArgs) -> RunOptions {
    RunOptions {
        lockstep: args.lockstep,
        // A batch has no viewer: runs follow one another too fast to watch.
        viewer: crate::args::ViewerArgs {
            headless: args.viewer.headless || args.seeds.is_some(),
            ..args.viewer.clone()
        },
        verbose: !args.quiet,
        session: args.session.clone(),
        hub_options: vec![
            "--threads".into(),
            args.threads.to_string(),
            "--parallel-min-robots".into(),
            args.parallel_min_robots.to_string(),
            "--answer-spin-us".into(),
            args.answer_spin_us.to_string(),
        ],
        zenoh: args.zenoh_agents.clone().map(|agents| ZenohRun {
            agents,
            listen: args.zenoh_listen.clone(),
            netns: args.zenoh_netns.clone(),
        }),
    }
}

/// One run per seed, each in `out/seed-N/`, a line of the table per run as it ends, then the
/// table and the batch's figures. Stops with a run that was interrupted.
fn run_batch(
    scenario: &Scenario,
    seeds: std::ops::RangeInclusive<u64>,
    out: &Path,
    opts: &RunOptions,
    signals: &Signals,
    quiet: bool,
) -> anyhow::Result<ExitCode> {
    let mut table = String::new();
    let mut all = Vec::new();
    // With a physical chair, contacts are counted in both worlds.
    let with_chair = scenario.chair.is_some();
    let w = if with_chair { 14 } else { 10 };
    let _ = writeln!(
        table,
        "  {:>6} {:>6} {:>11} {:>w$} {}{:>9}  state hash",
        "seed",
        "pass",
        "checkpoints",
        if with_chair { "contacts (sim)" } else { "contacts" },
        if with_chair { "contacts (room) pose off m " } else { "" },
        "time s"
    );
    let mut room_contacts = 0;
    let mut pose_errors: Vec<f64> = Vec::new();
    for seed in seeds {
        let dir = out.join(format!("seed-{seed}"));
        let placed =
            scenario.populated(seed).map_err(|e| anyhow::anyhow!("scenario {}, seed {seed}: {e}", scenario.name))?;
        let end = run_once(&placed, seed, &dir, &RunOptions { verbose: false, ..opts.clone() }, signals)?;
        if end.interrupted.is_some() {
            // The batch stops with the run it was in: that run's partial summary, and where
            // the finished ones are.
            print_summary(&end.summary, end.chair.as_ref(), &dir);
            println!("  {} earlier run(s) in {}/seed-*/", all.len(), out.display());
            return Ok(exit_code(&end));
        }
        let room = end.chair.as_ref().map(|c| c.contacts_room);
        room_contacts += room.unwrap_or(0);
        let pose_error = end.chair.as_ref().and_then(|c| c.pose_error_m);
        pose_errors.extend(pose_error);
        let s = end.summary;
        let reached: usize = s.robots.iter().map(|r| r.checkpoints_reached).sum();
        let total: usize = s.robots.iter().map(|r| r.checkpoints_total).sum();
        let contacts: u64 = s.robots.iter().map(|r| r.collisions).sum();
        let time = s.robots.iter().filter_map(|r| r.reached_at_s.last().copied()).fold(f64::NAN, f64::max);
        let line = format!(
            "  {:>6} {:>6} {:>11} {:>w$} {}{:>9}  {}",
            seed,
            if s.passed { "yes" } else { "NO" },
            format!("{reached}/{total}"),
            contacts,
            room.map_or(String::new(), |n| format!(
                "{n:>15} {:>10} ",
                pose_error.map_or("-".to_owned(), |e| format!("{e:.3}"))
            )),
            if time.is_nan() { "-".into() } else { format!("{time:.1}") },
            s.state_hash
        );
        if !quiet {
            ipc_services::report!("{line}");
        }
        table += &line;
        table.push('\n');
        all.push(s);
    }
    let passed = all.iter().filter(|s| s.passed).count();
    // A run's time is its last robot's arrival, as in the table's rows.
    let times: Vec<f64> = all
        .iter()
        .map(|s| s.robots.iter().filter_map(|r| r.reached_at_s.last().copied()).fold(f64::NAN, f64::max))
        .filter(|t| !t.is_nan())
        .collect();
    let contacts: u64 = all.iter().flat_map(|s| s.robots.iter().map(|r| r.collisions)).sum();
    println!(
        "scenario {}: {} runs, {}",
        scenario.name,
        all.len(),
        if opts.lockstep { "lock-step" } else { "real time" }
    );
    print!("{table}");
    println!(
        "  success rate {passed}/{} ({:.0} %), mean time {}, collisions {contacts} in all{}",
        all.len(),
        100.0 * passed as f64 / all.len().max(1) as f64,
        if times.is_empty() {
            "-".to_owned()
        } else {
            format!("{:.1} s", times.iter().sum::<f64>() / times.len() as f64)
        },
        if with_chair { format!(" in the simulator, {room_contacts} in the chair's room") } else { String::new() }
    );
    if !pose_errors.is_empty() {
        // How far the hub's frame (where virtual obstacles stand) ended from the room's.
        pose_errors.sort_by(f64::total_cmp);
        println!(
            "  the hub's final pose of the chair off its true pose: median {:.3} m, max {:.3} m",
            pose_errors[pose_errors.len() / 2],
            pose_errors[pose_errors.len() - 1]
        );
    }
    for s in all.iter().filter(|s| !s.passed) {
        for f in &s.failures {
            println!("  seed {}: {f}", s.seed);
        }
    }
    println!("  logs in {}/seed-*/", out.display());
    let _ = std::io::stdout().flush();
    Ok(if passed == all.len() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_agents_are_all_or_numbers_from_one() {
        assert_eq!(ZenohAgents::parse("all"), Ok(ZenohAgents::All));
        assert_eq!(ZenohAgents::parse("1, 3"), Ok(ZenohAgents::Some(vec![1, 3])));
        let some = ZenohAgents::parse("2").expect("one agent");
        assert!(!some.includes(0) && some.includes(1) && !some.includes(2));
        for bad in ["0", "x", "1,,2", ""] {
            let e = ZenohAgents::parse(bad).expect_err(bad);
            assert!(e.contains("is not an agent number"), "{bad}: {e}");
        }
    }

    #[test]
    fn agents_connect_where_the_bridge_listens_on_every_interface() {
        let run = |listen: &str| ZenohRun { agents: ZenohAgents::All, listen: Some(listen.into()), netns: None };
        let (listen, connect) = run("tcp/0.0.0.0:7447").endpoints().expect("endpoints");
        assert_eq!((listen.as_str(), connect.as_str()), ("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7447"));
        let (_, connect) = run("tcp/10.0.0.5:7000").endpoints().expect("endpoints");
        assert_eq!(connect, "tcp/10.0.0.5:7000");
        let free = ZenohRun { agents: ZenohAgents::All, listen: None, netns: None };
        let (listen, connect) = free.endpoints().expect("a free port");
        assert!(listen.starts_with("tcp/127.0.0.1:") && listen == connect, "{listen}");
    }
}
