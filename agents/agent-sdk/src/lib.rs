//! The agent SDK: connect to a hub's session, register robots, then loop "wait for a tick →
//! read my sensor blocks → send my actions".
//!
//! ```no_run
//! use agent_sdk::{Agent, Wait};
//! use ipc_types::{ActionBlock, RobotRegistration};
//!
//! let mut agent = Agent::connect("demo", "my-agent").expect("a hub serves session demo");
//! let id = agent.register(&RobotRegistration::new("chair")).expect("accepted");
//! agent.ready().expect("hub still there");
//! while let Some(tick) = agent.wait_tick(Wait::Blocking).expect("hub alive") {
//!     let front = agent.sensors()[0].proximity_m[0];
//!     let power = if front < 0.8 { 0.0 } else { 0.8 };
//!     agent.send(tick.tick, &[ActionBlock::motors(id, power, power)]).expect("sent");
//! }
//! ```
//!
//! Agents depend on `ipc-types` and `ipc-services` only, never on the hub.
//!
//! # What an agent may know
//!
//! An [`Agent`] gets its own robots' sensor blocks (what their sensors measure, with their
//! noise: proximity, compass, GPS when the run has it, beacons, ground, encoders, the collision
//! flag, messages heard) and the agents' map (walls, beacons, targets, grid, route — not the
//! scenario's obstacles, which its sensors must find). Where it truly is, where the other
//! robots are and where the obstacles stand are for observers (the `observer` crate: viewers,
//! recorders, referees), and an agent has no call that returns them:
//!
//! ```compile_fail,E0599
//! fn cheat(agent: &mut agent_sdk::Agent) {
//!     let _every_true_pose = agent.world(); // no such call: the world snapshot is for observers
//! }
//! ```
//!
//! ```compile_fail,E0609
//! fn cheat(block: &ipc_types::SensorBlock) -> sim_model::Pose {
//!     block.pose // no such field: a sensor block carries what the sensors measure
//! }
//! ```
//!
//! To know where it is, an agent estimates it: [`odometry::Odometry`] on its encoders and
//! compass, or its GPS.
#![warn(missing_docs)]

pub use ipc_services::{report, stop_signalled};
pub use places::{args, files};
pub use robot_log as log;

pub mod cli;
pub mod inbox;
pub mod logs;
pub mod map;
pub mod odometry;
pub mod pending;
pub mod remote;

/// Building blocks for other clients of a hub (the observer crate): newest-sample receiving,
/// the kept map sample, error mapping. None of them opens a service: what a client may read
/// is decided by the services it can open.
pub mod ports {
    pub use super::{ANSWER_TIMEOUT, ipc, receive_map, receive_map_items, receive_newest};
}

use std::time::{Duration, Instant};

use ipc_services::iceoryx2::node::Node;
use ipc_services::iceoryx2::port::ReceiveError;
use ipc_services::iceoryx2::port::client::Client;
use ipc_services::iceoryx2::port::listener::{Listener, ListenerWaitError};
use ipc_services::iceoryx2::port::notifier::Notifier;
use ipc_services::iceoryx2::port::publisher::Publisher;
use ipc_services::iceoryx2::port::subscriber::Subscriber;
use ipc_services::iceoryx2::prelude::{PortFactory as _, ZeroCopySend};
use ipc_services::iceoryx2::sample::Sample;
use ipc_services::{Role, SLICE_ALLOCATION, ServicesError, Session, Svc};
use ipc_types::{
    ActionBlock, ActionHeader, MapHeader, MapItem, Refusal, RegisterKind, RegisterRequest, RegisterResponse,
    RobotRegistration, RunState, SensorBlock, TickHeader,
};

/// How long an agent waits for a tick before it checks the hub is still alive.
const LIVENESS_SLICE: Duration = Duration::from_millis(100);
/// How often a request still unanswered makes the hub's server look at its clients again
/// (see [`Nudge`]).
const NUDGE_EVERY: Duration = Duration::from_secs(1);

/// When to nudge the hub about an unanswered request: once [`NUDGE_EVERY`] has passed since
/// the request was sent or since the last nudge.
#[derive(Debug)]
pub(crate) struct Nudge(Instant);

impl Nudge {
    pub(crate) fn new() -> Self {
        Self(Instant::now())
    }

    /// If it is time, [`nudge`]s the hub through `svc` and rings its doorbell.
    pub(crate) fn if_due<Req, Resp>(
        &mut self,
        svc: &ipc_services::iceoryx2::service::port_factory::request_response::PortFactory<Svc, Req, (), Resp, ()>,
        doorbell: &Notifier<Svc>,
    ) where
        Req: std::fmt::Debug + ZeroCopySend + Copy,
        Resp: std::fmt::Debug + ZeroCopySend + Copy,
    {
        if self.0.elapsed() > NUDGE_EVERY {
            self.0 = Instant::now();
            nudge(svc);
            let _ = doorbell.notify();
        }
    }
}

/// Makes the hub's server set up its connections to clients again. An iceoryx2 (0.10) server
/// does that only when the service's client list changes, and a connection it failed to set
/// up (one a client was still creating when the server's wait for it, `creation_timeout`,
/// 1 s, ran out on a loaded machine: a warning only) is not tried again until then, so that
/// client's requests are never read. A client port created and dropped here changes the
/// list: the server's next look retries. (A longer `creation_timeout` was tried instead: the
/// hub's loop then blocked for as long, and an operator's resume went unanswered for 20 s.)
fn nudge<Req, Resp>(
    svc: &ipc_services::iceoryx2::service::port_factory::request_response::PortFactory<Svc, Req, (), Resp, ()>,
) where
    Req: std::fmt::Debug + ZeroCopySend + Copy,
    Resp: std::fmt::Debug + ZeroCopySend + Copy,
{
    let _ = svc.client_builder().create();
}

/// How long an answer to a registration (or a command, or the map) may take: on a loaded
/// 2-core machine a hub's loop was seen to answer after more than 5 s. A hub that is gone is
/// noticed at once all the same (the waits check it is alive).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(15);

/// How `wait_tick` waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// Sleep until the hub rings the tick (the default: costs no CPU while waiting). When the
    /// hub's last tick header allows it (`spin_us`: lock-step, fewer agents than cores, a
    /// one-thread step), spin that long first, on a core no other process needs.
    Blocking,
    /// Spin on shared memory: lowest latency, one core busy. Only sensible when processes ≤
    /// cores.
    BusyPoll,
}

/// Why an agent call failed.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// The session's services could not be opened (no hub, or a bad session name).
    #[error(transparent)]
    Services(#[from] ServicesError),
    /// The hub refused a request.
    #[error("the hub refused: {reason:?}: {detail}")]
    Refused {
        /// Why.
        reason: Refusal,
        /// The hub's explanation.
        detail: String,
    },
    /// The hub's process is gone.
    #[error("the hub (pid {pid}) of session {session:?} has exited")]
    HubGone {
        /// The hub's pid.
        pid: u32,
        /// The session.
        session: String,
    },
    /// The hub did not answer in time: the session and how long it was given.
    #[error("the hub of session {0:?} did not answer within {secs} s", secs = .1.as_secs_f64())]
    NoAnswer(String, Duration),
    /// SIGINT or SIGTERM arrived.
    #[error("interrupted by a termination signal")]
    Interrupted,
    /// iceoryx2 failed.
    #[error("iceoryx2 failed to {0}")]
    Ipc(String),
    /// The hub's map did not decode.
    #[error("the hub's map is malformed: {0}")]
    Map(#[from] map::MapDecodeError),
    /// No Zenoh bridge serves the session where the agent looked.
    #[error("no Zenoh bridge answered for session {0:?} (is `iwsim zenoh` running there, and reachable?)")]
    NoBridge(String),
    /// The Zenoh bridge the agent reached its hub through is gone (it, its hub or the link).
    #[error("the Zenoh bridge of session {0:?} is gone")]
    BridgeGone(String),
    /// Zenoh failed.
    #[error("zenoh failed to {0}")]
    Zenoh(String),
    /// The other end sent bytes that are not the payload they should be.
    #[error("a malformed {what} came over the network: {error}")]
    Frame {
        /// Which payload.
        what: &'static str,
        /// What was wrong with it.
        error: ipc_types::remote::FrameError,
    },
}

/// Turns an iceoryx2 error met while trying to `what` into [`AgentError::Ipc`].
pub fn ipc<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> AgentError + '_ {
    move |e| AgentError::Ipc(format!("{what}: {e:?}"))
}

/// One tick as an agent sees it; the sensor blocks are in [`Agent::sensors`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// The tick number; answer it with [`Agent::send`].
    pub tick: u64,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// The run state.
    pub run_state: RunState,
    /// Nanoseconds from the hub sending these sensor blocks to this agent having them
    /// (CLOCK_MONOTONIC, shared by every process on the machine).
    pub latency_ns: u64,
    /// Whether the hub waits for this agent's answer before it steps (lock-step). When not, a
    /// tick comes every cycle regardless, and an agent that thinks longer than a cycle leaves
    /// its robot on its last command meanwhile.
    pub lockstep: bool,
}

/// Sends a run-control command to the hub of `session` (start, pause, step, stop, remove a
/// robot) and returns its answer.
pub fn control(
    session: &str,
    command: ipc_types::Command,
    robot_id: u32,
) -> Result<ipc_types::ControlResponse, AgentError> {
    control_within(session, command, robot_id, ANSWER_TIMEOUT)
}

/// [`control`], waiting up to `timeout` for the hub to serve and then to answer: an operator's
/// command on a loaded machine (`iwsim resume --connect-timeout S`) may wait longer than an
/// agent's registration.
pub fn control_within(
    session: &str,
    command: ipc_types::Command,
    robot_id: u32,
    timeout: Duration,
) -> Result<ipc_types::ControlResponse, AgentError> {
    let session = Session::new(session)?;
    // Declared first, dropped last: whatever happens below, the node is gone before it runs.
    let _release = session.release_on_drop();
    let node = session.node(&format!("iwsim-control-{}", std::process::id()))?;
    let svc = session.control(&node, Role::Client)?;
    let start = Instant::now();
    while svc.dynamic_config().number_of_servers() == 0 {
        if start.elapsed() > timeout {
            return Err(AgentError::NoAnswer(session.name().to_owned(), timeout));
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let doorbell =
        session.hub_event(&node, Role::Client)?.notifier_builder().create().map_err(ipc("create the hub doorbell"))?;
    let client = svc.client_builder().create().map_err(ipc("create a control client"))?;
    let pending = client
        .send_copy(ipc_types::ControlRequest { command: command as u32, robot_id })
        .map_err(ipc("send a command"))?;
    let _ = doorbell.notify();
    let start = Instant::now();
    let mut nudge = Nudge::new();
    loop {
        if let Some(r) = pending.receive().map_err(ipc("receive an answer"))? {
            return Ok(*r.payload());
        }
        if start.elapsed() > timeout {
            return Err(AgentError::NoAnswer(session.name().to_owned(), timeout));
        }
        nudge.if_due(&svc, &doorbell);
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// Whether a sensor sample carries the robots `ids`, in that order.
fn same_robots(ids: &[u32], blocks: &[SensorBlock]) -> bool {
    ids.iter().copied().eq(blocks.iter().map(|b| b.robot_id))
}

/// A received sample of an agent's sensor blocks, held in shared memory.
type SensorSample = Sample<Svc, [SensorBlock], TickHeader>;

/// Receives the newest sample of `sub` into `held`, replacing the one held; true if one came.
/// A subscriber may borrow one sample at a time, so the held one is let go only when a newer
/// one is waiting (receiving then fails with `ExceedsMaxBorrows` without taking it).
pub fn receive_newest<T: std::fmt::Debug + ZeroCopySend, H: std::fmt::Debug + ZeroCopySend>(
    sub: &Subscriber<Svc, [T], H>,
    held: &mut Option<Sample<Svc, [T], H>>,
    what: &str,
) -> Result<bool, AgentError> {
    let mut fresh = false;
    loop {
        match sub.receive() {
            Ok(Some(sample)) => {
                *held = Some(sample);
                fresh = true;
            }
            Ok(None) => return Ok(fresh),
            Err(ReceiveError::ExceedsMaxBorrows) if held.is_some() => *held = None,
            Err(e) => return Err(AgentError::Ipc(format!("{what}: {e:?}"))),
        }
    }
}

/// A run-control client kept for a process's lifetime: commands are sent without waiting,
/// so a process serving other inputs (the UDP bridge) never stalls on them.
pub struct ControlClient {
    client: Client<Svc, ipc_types::ControlRequest, (), ipc_types::ControlResponse, ()>,
    /// The control service, kept to [`nudge`] the hub with.
    svc: ipc_services::ControlService,
    doorbell: Notifier<Svc>,
    _node: Node<Svc>,
    /// The session's name, for errors.
    session: String,
    pending: Vec<
        ipc_services::iceoryx2::pending_response::PendingResponse<
            Svc,
            ipc_types::ControlRequest,
            (),
            ipc_types::ControlResponse,
            (),
        >,
    >,
    /// Last, so it runs after every port and the node are gone.
    _release: ipc_services::SessionRelease,
}

impl std::fmt::Debug for ControlClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlClient").field("pending", &self.pending.len()).finish()
    }
}

impl ControlClient {
    /// Opens the control service of the hub serving `session`.
    pub fn connect(session: &str) -> Result<Self, AgentError> {
        let session = Session::new(session)?;
        let release = session.release_on_drop();
        let node = session.node(&format!("iwsim-control-{}", std::process::id()))?;
        let svc = session.control(&node, Role::Client)?;
        let doorbell = session
            .hub_event(&node, Role::Client)?
            .notifier_builder()
            .create()
            .map_err(ipc("create the hub doorbell"))?;
        let client = svc.client_builder().create().map_err(ipc("create a control client"))?;
        let session = session.name().to_owned();
        Ok(Self { client, svc, doorbell, _node: node, session, pending: Vec::new(), _release: release })
    }

    /// Sends a command and returns at once; answers are collected and dropped later.
    pub fn send(&mut self, command: ipc_types::Command, robot_id: u32) -> Result<(), AgentError> {
        // Forget answered requests; keep at most a few outstanding (the service allows 4).
        self.pending.retain(|p| p.receive().ok().flatten().is_none() && p.is_connected());
        if self.pending.len() >= 3 {
            self.pending.remove(0);
        }
        let p = self
            .client
            .send_copy(ipc_types::ControlRequest { command: command as u32, robot_id })
            .map_err(ipc("send a command"))?;
        self.pending.push(p);
        let _ = self.doorbell.notify();
        Ok(())
    }

    /// Sends a command as [`ControlClient::send`] does on the client in `slot`, opening it
    /// first if the slot is empty: for a process (a bridge) that sends commands rarely and
    /// keeps no control node until it does.
    pub fn send_lazily(
        slot: &mut Option<Self>,
        session: &str,
        command: ipc_types::Command,
        robot_id: u32,
    ) -> Result<(), AgentError> {
        let client = match slot {
            Some(c) => c,
            None => slot.insert(Self::connect(session)?),
        };
        client.send(command, robot_id)
    }

    /// Sends a command and waits up to 15 s for the hub's answer, on this one client: a
    /// process that sends many commands (the web viewer) keeps one node instead of one per
    /// command.
    pub fn ask(
        &mut self,
        command: ipc_types::Command,
        robot_id: u32,
    ) -> Result<ipc_types::ControlResponse, AgentError> {
        let p = self
            .client
            .send_copy(ipc_types::ControlRequest { command: command as u32, robot_id })
            .map_err(ipc("send a command"))?;
        let _ = self.doorbell.notify();
        let start = Instant::now();
        let mut nudge = Nudge::new();
        loop {
            if let Some(r) = p.receive().map_err(ipc("receive an answer"))? {
                return Ok(*r.payload());
            }
            if start.elapsed() > ANSWER_TIMEOUT {
                return Err(AgentError::NoAnswer(self.session.clone(), ANSWER_TIMEOUT));
            }
            nudge.if_due(&self.svc, &self.doorbell);
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

/// Waits up to 15 s for the map sample the hub keeps for late subscribers and decodes it;
/// `alive` is asked between polls so a caller can give up early when the hub is gone.
pub fn receive_map(
    svc: &ipc_services::MapService,
    session: &Session,
    alive: impl FnMut() -> Result<(), AgentError>,
) -> Result<map::Map, AgentError> {
    let (header, items) = receive_map_items(svc, session, alive)?;
    Ok(map::Map::decode(&header, &items)?)
}

/// [`receive_map`] without the decoding: the map sample's header and items, copied out.
pub fn receive_map_items(
    svc: &ipc_services::MapService,
    session: &Session,
    mut alive: impl FnMut() -> Result<(), AgentError>,
) -> Result<(MapHeader, Vec<MapItem>), AgentError> {
    let sub: Subscriber<Svc, [MapItem], MapHeader> =
        svc.subscriber_builder().create().map_err(ipc("create a map subscriber"))?;
    let start = Instant::now();
    loop {
        if let Some(s) = sub.receive().map_err(ipc("receive the map"))? {
            return Ok((*s.user_header(), s.payload().to_vec()));
        }
        alive()?;
        if start.elapsed() > ANSWER_TIMEOUT {
            return Err(AgentError::NoAnswer(session.name().to_owned(), ANSWER_TIMEOUT));
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// The link an [`Agent`] reaches its hub by.
enum Link {
    /// Shared memory, on the hub's machine.
    Shm(Box<ShmLink>),
    /// Zenoh, through the bridge (`iwsim zenoh`), from any machine.
    Zenoh(Box<remote::ZenohLink>),
}

/// The ports of an agent on the hub's machine.
struct ShmLink {
    session: Session,
    node: Node<Svc>,
    register: Client<Svc, RegisterRequest, (), RegisterResponse, ()>,
    /// The register service, kept to [`nudge`] the hub with.
    register_svc: ipc_services::RegisterService,
    /// When this agent next nudges the hub about an unanswered request.
    nudge: Nudge,
    sensors: Option<Subscriber<Svc, [SensorBlock], TickHeader>>,
    actions: Publisher<Svc, [ActionBlock], ActionHeader>,
    tick_listener: Listener<Svc>,
    doorbell: Notifier<Svc>,
    /// The sensor sample of the last tick, held in shared memory: [`Agent::sensors`] lends it,
    /// nothing copies it.
    held: Option<SensorSample>,
    /// Last, so it runs after every port and the node are gone: an agent that ends any way
    /// (an error, a signal, the end of the run) leaves nothing in /dev/shm if it was the
    /// session's last process.
    _release: ipc_services::SessionRelease,
}

/// Which tick an agent has in hand, whichever link brought it.
#[derive(Debug, Default)]
struct TickState {
    last_tick: Option<u64>,
    last_header: TickHeader,
    received_ns: u64,
    /// The robot ids of the held sample, in its order (kept to tell a republished tick's
    /// newcomers, since the sample must be let go before the next can be received).
    held_ids: Vec<u32>,
}

impl TickState {
    /// Takes note of a sample with header `h` and `blocks` that arrived at `received_ns`;
    /// whether it is fresh: a tick not seen yet, the tick in hand with another set of robots
    /// (the hub re-publishes the tick when this agent's robot joins or leaves, and while a run
    /// waits for its Start that is the only way a robot registered after the first gets its
    /// readings), or the run's end.
    fn note(&mut self, h: &TickHeader, blocks: &[SensorBlock], received_ns: u64) -> bool {
        let finished = RunState::from_u32(h.run_state) == Some(RunState::Finished);
        let same = same_robots(&self.held_ids, blocks);
        let seen = match self.last_tick {
            Some(t) if h.tick < t => true,
            Some(t) if h.tick == t => same,
            _ => false,
        };
        if !same {
            self.held_ids.clear();
            self.held_ids.extend(blocks.iter().map(|b| b.robot_id));
        }
        // A tick seen already brings nothing new, so the tick in hand and its header stay.
        if seen && !finished {
            return false;
        }
        self.last_tick = Some(h.tick);
        self.last_header = *h;
        self.received_ns = received_ns;
        true
    }
}

/// A connection to a hub: on its machine through shared memory ([`Agent::connect`]), or from
/// any machine through its Zenoh bridge ([`Agent::connect_zenoh`]). Both serve the same calls
/// with the same payloads.
pub struct Agent {
    link: Link,
    /// The session's name.
    session: String,
    agent_id: u32,
    hub_pid: u32,
    robots: Vec<u32>,
    ticks: TickState,
    finished: bool,
}

impl Drop for Agent {
    fn drop(&mut self) {
        self.goodbye();
    }
}

/// Waits until `fd` is readable or `timeout` passes (a signal also ends the wait); whether it
/// became readable.
fn wait_readable(fd: i32, timeout: Duration) -> bool {
    poll_readable(&[fd], timeout)
}

/// Waits until one of `fds` (at most 4) is readable or `timeout` passes (a signal also ends
/// the wait); whether one became readable.
pub(crate) fn poll_readable(fds: &[i32], timeout: Duration) -> bool {
    os::poll::any_readable(fds, Some(timeout)).unwrap_or(false)
}

impl std::fmt::Debug for Agent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Agent")
            .field("session", &self.session)
            .field(
                "link",
                &match self.link {
                    Link::Shm(_) => "shared memory",
                    Link::Zenoh(_) => "zenoh",
                },
            )
            .field("agent_id", &self.agent_id)
            .field("robots", &self.robots)
            .finish()
    }
}

impl Agent {
    fn with_link(link: Link, session: &str) -> Self {
        Self {
            link,
            session: session.to_owned(),
            agent_id: 0,
            hub_pid: 0,
            robots: Vec::new(),
            ticks: TickState::default(),
            finished: false,
        }
    }

    /// Connects to the hub serving `session` and says hello.
    pub fn connect(session: &str, name: &str) -> Result<Self, AgentError> {
        let session = Session::new(session)?;
        // Declared before the node, so a failed connect (no hub yet) releases the session too.
        let release = session.release_on_drop();
        let node = session.node(name)?;
        let register_svc = session.register(&node, Role::Client)?;
        let actions_svc = session.actions(&node, Role::Client)?;
        let tick_svc = session.tick_event(&node, Role::Client)?;
        let doorbell_svc = session.hub_event(&node, Role::Client)?;
        // The hub creates its services first and its ports right after: a request sent in
        // between would reach no server and be lost, so wait until the hub's ports exist.
        let start = Instant::now();
        while register_svc.dynamic_config().number_of_servers() == 0
            || doorbell_svc.dynamic_config().number_of_listeners() == 0
            || actions_svc.dynamic_config().number_of_subscribers() == 0
        {
            if start.elapsed() > ANSWER_TIMEOUT {
                return Err(AgentError::NoAnswer(session.name().to_owned(), ANSWER_TIMEOUT));
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        let register = register_svc.client_builder().create().map_err(ipc("create a register client"))?;
        let actions = actions_svc
            .publisher_builder()
            .initial_max_slice_len(4)
            .allocation_strategy(SLICE_ALLOCATION)
            .create()
            .map_err(ipc("create the actions publisher"))?;
        let tick_listener = tick_svc.listener_builder().create().map_err(ipc("create the tick listener"))?;
        let doorbell = doorbell_svc.notifier_builder().create().map_err(ipc("create the hub doorbell"))?;
        let name = session.name().to_owned();
        let link = ShmLink {
            session,
            node,
            register,
            register_svc,
            nudge: Nudge::new(),
            sensors: None,
            actions,
            tick_listener,
            doorbell,
            held: None,
            _release: release,
        };
        let mut agent = Self::with_link(Link::Shm(Box::new(link)), &name);
        let resp = agent.request(RegisterKind::Hello, None)?;
        agent.agent_id = resp.agent_id;
        agent.hub_pid = resp.hub_pid;
        let Link::Shm(link) = &mut agent.link else { unreachable!("built above") };
        let sensors_svc = link.session.agent_sensors(&link.node, agent.agent_id, Role::Client)?;
        link.sensors = Some(sensors_svc.subscriber_builder().create().map_err(ipc("create the sensor subscriber"))?);
        Ok(agent)
    }

    /// Like [`Agent::connect`], but waits up to `timeout` for a hub to start serving the
    /// session, so an agent may be started before its hub.
    pub fn connect_within(session: &str, name: &str, timeout: Duration) -> Result<Self, AgentError> {
        let start = Instant::now();
        loop {
            match Self::connect(session, name) {
                Err(AgentError::Services(ServicesError::NotRunning { .. })) if start.elapsed() < timeout => {
                    // Polling for the hub's services to appear; nothing to wait on before they exist.
                    std::thread::sleep(Duration::from_millis(10));
                }
                other => return other,
            }
        }
    }

    /// Connects to the hub serving `session` on another machine, through its Zenoh bridge
    /// (`iwsim zenoh`) at `remote.endpoint` (e.g. `tcp/10.0.0.5:7447`, the bridge's or a Zenoh
    /// router's), and says hello; waits up to `timeout` for the bridge to answer. Every call
    /// after this works as on the hub's machine.
    pub fn connect_zenoh(remote: &remote::Remote, session: &str, timeout: Duration) -> Result<Self, AgentError> {
        // No iceoryx2 node installs them here: a signal must end the agent cleanly all the same
        // (its goodbye said, its logs whole).
        ipc_services::install_stop_handlers();
        let link = remote::ZenohLink::open(remote, session, timeout)?;
        let mut agent = Self::with_link(Link::Zenoh(Box::new(link)), session);
        let start = Instant::now();
        let resp = loop {
            match agent.request(RegisterKind::Hello, None) {
                // No bridge answered yet: it may still be starting.
                Err(AgentError::NoBridge(_)) if start.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(50));
                }
                other => break other?,
            }
        };
        agent.agent_id = resp.agent_id;
        agent.hub_pid = 0;
        let Link::Zenoh(link) = &mut agent.link else { unreachable!("built above") };
        link.joined(resp.agent_id)?;
        Ok(agent)
    }

    /// The id the hub gave this agent.
    pub fn id(&self) -> u32 {
        self.agent_id
    }

    /// The hub's process id (0 through a Zenoh bridge: the hub is on another machine).
    pub fn hub_pid(&self) -> u32 {
        self.hub_pid
    }

    /// This agent's robots, in registration order.
    pub fn robots(&self) -> &[u32] {
        &self.robots
    }

    fn hub_alive(&self) -> bool {
        match &self.link {
            Link::Shm(_) => self.hub_pid == 0 || ipc_services::process_alive(self.hub_pid),
            Link::Zenoh(z) => z.bridge_alive(),
        }
    }

    fn check(&self) -> Result<(), AgentError> {
        match &self.link {
            Link::Shm(l) => {
                if ipc_services::stop_requested(&l.node) {
                    return Err(AgentError::Interrupted);
                }
            }
            Link::Zenoh(_) => {
                if ipc_services::stop_signalled() {
                    return Err(AgentError::Interrupted);
                }
            }
        }
        if !self.hub_alive() {
            return Err(match &self.link {
                Link::Shm(_) => AgentError::HubGone { pid: self.hub_pid, session: self.session.clone() },
                Link::Zenoh(_) => AgentError::BridgeGone(self.session.clone()),
            });
        }
        Ok(())
    }

    /// Sends a request and waits for the hub's answer (at most [`ANSWER_TIMEOUT`]).
    fn request(
        &mut self,
        kind: RegisterKind,
        robot: Option<&RobotRegistration>,
    ) -> Result<RegisterResponse, AgentError> {
        let pending = self.start_request(kind, robot)?;
        loop {
            if let Some(r) = self.poll_response(&pending)? {
                return Ok(r);
            }
            // The hub answers within its loop; a short nap keeps the wait cheap.
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Registers a robot; its id, or the hub's typed refusal.
    pub fn register(&mut self, robot: &RobotRegistration) -> Result<u32, AgentError> {
        let resp = self.request(RegisterKind::Robot, Some(robot))?;
        self.accepted(resp.robot_id, Some(robot));
        Ok(resp.robot_id)
    }

    /// A robot the hub accepted joins this agent's; through Zenoh its registration is kept,
    /// for a restarted bridge.
    fn accepted(&mut self, robot_id: u32, registration: Option<&RobotRegistration>) {
        self.robots.push(robot_id);
        if let (Link::Zenoh(z), Some(reg)) = (&mut self.link, registration) {
            z.registrations.push((robot_id, *reg));
        }
    }

    /// Tells the hub every robot is registered: the agent joins the lock-step barrier.
    pub fn ready(&mut self) -> Result<(), AgentError> {
        self.request(RegisterKind::Ready, None).map(|_| ())
    }

    /// Waits for the next tick and returns this agent's sensor blocks; `None` once the run
    /// has finished. The tick in hand comes again when this agent's robots changed within it
    /// (one registered or removed): its sensor blocks then include the newcomer. Fails when the
    /// hub exits or a termination signal arrives.
    pub fn wait_tick(&mut self, wait: Wait) -> Result<Option<Tick>, AgentError> {
        if self.finished {
            return Ok(None);
        }
        loop {
            if self.take_sensors()? {
                return self.tick_from_last();
            }
            // Wait for the next sample; check the hub's liveness only when a wait slice
            // ends with nothing, so the check's syscalls never sit between a sample's arrival
            // and its reading.
            let arrived = match (&mut self.link, wait) {
                // Frames from the network arrive on the link's own threads, which ring the
                // link's socket: sleep on it (a busy poll would gain nothing on a network).
                (Link::Zenoh(z), _) => wait_readable(z.wake_fd(), LIVENESS_SLICE),
                (Link::Shm(_), Wait::Blocking) => {
                    // The hub says when spinning takes no core another process needs (lock-step,
                    // fewer agents than cores): then look for the sample for a while first, with
                    // no syscall, so a tick that comes within the spin costs no wake-up.
                    let spin = Duration::from_micros(u64::from(self.ticks.last_header.spin_us));
                    if !spin.is_zero() && self.sample_within(spin) {
                        continue;
                    }
                    let Link::Shm(link) = &mut self.link else { unreachable!("matched above") };
                    // Drain the rings already read, look once more (a sample whose ring was
                    // just drained is found here), then sleep in poll(2) until the next ring.
                    // The socket stays non-blocking throughout: iceoryx2's own timed wait
                    // switches it to blocking and sets a receive timeout (three syscalls),
                    // and its drain switches it back (two more), on every tick.
                    match link.tick_listener.try_wait(|_| {}) {
                        Ok(_) => {}
                        // Any signal cuts the wait short (SIGSTOP/SIGCONT, a debugger); a
                        // termination request is caught by the check below, anything else is
                        // a spurious wake-up.
                        Err(ListenerWaitError::InterruptSignal) => {}
                        Err(e) => return Err(AgentError::Ipc(format!("wait for a tick: {e:?}"))),
                    }
                    if self.take_sensors()? {
                        return self.tick_from_last();
                    }
                    wait_readable(self.tick_fd(), LIVENESS_SLICE)
                }
                (Link::Shm(_), Wait::BusyPoll) => {
                    // Spin on receive itself, as a bare subscriber would: the sample is read
                    // the moment it lands.
                    let spin_until = Instant::now() + LIVENESS_SLICE;
                    let mut spins = 0u32;
                    loop {
                        if self.take_sensors()? {
                            return self.tick_from_last();
                        }
                        spins = spins.wrapping_add(1);
                        if spins.is_multiple_of(1024) && Instant::now() >= spin_until {
                            break false;
                        }
                        std::hint::spin_loop();
                    }
                }
            };
            if !arrived {
                self.rejoin_if_replaced()?;
            }
            if !arrived && let Err(e) = self.check() {
                // The hub may have published its last tick just before going: read it first.
                if self.take_sensors()? {
                    return self.tick_from_last();
                }
                return Err(e);
            }
        }
    }

    /// The next tick if it has arrived, without waiting; `None` when there is none yet. The
    /// last tick of a run comes once with `run_state` Finished (its sensor blocks are the final
    /// readings); after it, [`Agent::finished`] is true. For processes that multiplex the hub
    /// with other inputs, together with [`Agent::tick_fd`].
    pub fn try_tick(&mut self) -> Result<Option<Tick>, AgentError> {
        if self.finished {
            return Ok(None);
        }
        if let Link::Shm(link) = &self.link {
            let _ = link.tick_listener.try_wait(|_| {});
        }
        if self.take_sensors()? {
            let h = self.ticks.last_header;
            if RunState::from_u32(h.run_state) == Some(RunState::Finished) {
                self.finished = true;
                return Ok(Some(Tick {
                    tick: h.tick,
                    sim_time_s: h.sim_time_s,
                    run_state: RunState::Finished,
                    latency_ns: self.ticks.received_ns.saturating_sub(h.t_pub_ns),
                    lockstep: h.flags & ipc_types::TICK_LOCKSTEP != 0,
                }));
            }
            return self.tick_from_last();
        }
        Ok(None)
    }

    /// Through Zenoh, when the bridge was restarted (another run of it came up, which has
    /// forgotten this agent): says hello to the new one and registers this agent's robots
    /// again, each by its name and id, which takes them back from the hub as a local agent
    /// restarted takes its robots back. The agent's id changes; its robots' ids do not (a
    /// robot the hub gives another id fails the rejoin). Nothing to do on shared memory, or
    /// when the bridge is the one this agent knows. [`Agent::wait_tick`] calls it when a
    /// wait brings nothing.
    pub fn rejoin_if_replaced(&mut self) -> Result<(), AgentError> {
        let Link::Zenoh(z) = &mut self.link else { return Ok(()) };
        if !z.replaced() || self.finished {
            return Ok(());
        }
        z.leave();
        let registrations = std::mem::take(&mut z.registrations);
        let hello = self.request(RegisterKind::Hello, None)?;
        self.agent_id = hello.agent_id;
        let Link::Zenoh(z) = &mut self.link else { unreachable!("matched above") };
        z.joined(hello.agent_id)?;
        let before = std::mem::take(&mut self.robots);
        for (id, reg) in registrations {
            let again = RobotRegistration { requested_id: id, ..reg };
            let got = self.register(&again)?;
            if got != id {
                return Err(AgentError::Zenoh(format!(
                    "the restarted bridge gave robot {id} ({:?}) id {got}: this agent's robots are not its own any more",
                    reg.name.as_str().unwrap_or("")
                )));
            }
        }
        debug_assert_eq!(before, self.robots, "the same robots, in the same order");
        self.request(RegisterKind::Ready, None)?;
        Ok(())
    }

    /// The header of the last tick returned (for a bridge that passes the tick on).
    pub fn tick_header(&self) -> &TickHeader {
        &self.ticks.last_header
    }

    /// Whether the hub has said the run is over.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The session's name.
    pub fn session(&self) -> &str {
        &self.session
    }

    /// Checks the hub is alive and no termination signal arrived.
    pub fn check_alive(&self) -> Result<(), AgentError> {
        self.check()
    }

    /// A file descriptor that becomes readable when a tick arrives, for `poll(2)`.
    pub fn tick_fd(&self) -> i32 {
        match &self.link {
            Link::Shm(link) => {
                use ipc_services::iceoryx2::prelude::FileDescriptorBased;
                #[allow(unsafe_code)]
                // SAFETY: reads the fd number of a listener this agent owns for as long as it lives.
                unsafe {
                    link.tick_listener.file_descriptor().native_handle()
                }
            }
            Link::Zenoh(z) => z.wake_fd(),
        }
    }

    /// This agent's robots' sensor blocks of the last tick returned by [`Agent::wait_tick`],
    /// in registration order: on the hub's machine a view of the sample where the hub wrote
    /// it in shared memory, nothing copied (copy the blocks out, e.g. with `to_vec()`, to keep
    /// them past the next tick).
    pub fn sensors(&self) -> &[SensorBlock] {
        match &self.link {
            Link::Shm(link) => link.held.as_ref().map_or(&[], |s| s.payload()),
            Link::Zenoh(z) => &z.held,
        }
    }

    fn tick_from_last(&mut self) -> Result<Option<Tick>, AgentError> {
        let h = self.ticks.last_header;
        if RunState::from_u32(h.run_state) == Some(RunState::Finished) {
            self.finished = true;
            return Ok(None);
        }
        Ok(Some(Tick {
            tick: h.tick,
            sim_time_s: h.sim_time_s,
            run_state: RunState::from_u32(h.run_state).unwrap_or(RunState::Running),
            latency_ns: self.ticks.received_ns.saturating_sub(h.t_pub_ns),
            lockstep: h.flags & ipc_types::TICK_LOCKSTEP != 0,
        }))
    }

    /// Spins for at most `spin` until a sensor sample waits to be taken; whether one does.
    fn sample_within(&self, spin: Duration) -> bool {
        let Link::Shm(link) = &self.link else { return false };
        let Some(sub) = &link.sensors else { return false };
        let until = Instant::now() + spin;
        loop {
            // An error is left for `take_sensors` to report.
            if sub.has_samples().unwrap_or(true) {
                return true;
            }
            if Instant::now() >= until {
                return false;
            }
            std::hint::spin_loop();
        }
    }

    /// Reads the newest sensor sample if it is fresh (see [`TickState::note`]); whether one was.
    fn take_sensors(&mut self) -> Result<bool, AgentError> {
        match &mut self.link {
            Link::Shm(link) => {
                let Some(sub) = &link.sensors else { return Ok(false) };
                let mut fresh = false;
                loop {
                    let sample = match sub.receive() {
                        Ok(Some(sample)) => sample,
                        Ok(None) => return Ok(fresh),
                        // A newer sample waits, and the subscriber may borrow one at a time.
                        Err(ReceiveError::ExceedsMaxBorrows) if link.held.is_some() => {
                            link.held = None;
                            continue;
                        }
                        Err(e) => return Err(AgentError::Ipc(format!("receive sensor blocks: {e:?}"))),
                    };
                    let received_ns = ipc_services::monotonic_ns();
                    fresh |= self.ticks.note(sample.user_header(), sample.payload(), received_ns);
                    // Held in any case (the one before had to go to receive it).
                    link.held = Some(sample);
                }
            }
            Link::Zenoh(z) => {
                let mut fresh = false;
                while let Some((h, blocks)) = z.take()? {
                    if self.ticks.note(&h, &blocks, ipc_services::monotonic_ns()) {
                        z.held = blocks;
                        fresh = true;
                    }
                }
                Ok(fresh)
            }
        }
    }

    /// Sends this agent's actions answering `tick` and rings the hub.
    pub fn send(&mut self, tick: u64, actions: &[ActionBlock]) -> Result<(), AgentError> {
        let header = ActionHeader { tick, agent_id: self.agent_id, count: actions.len() as u32 };
        match &mut self.link {
            Link::Shm(link) => {
                let mut sample = link.actions.loan_slice_uninit(actions.len()).map_err(ipc("loan actions"))?;
                *sample.user_header_mut() = header;
                sample.write_from_slice(actions).send().map_err(ipc("send actions"))?;
                link.doorbell.notify().map_err(ipc("ring the hub"))?;
            }
            Link::Zenoh(z) => z.send(&header, actions)?,
        }
        Ok(())
    }

    /// Leaves the session: says goodbye (the hub removes this agent's robots) unless the run
    /// has finished, closes every port, and removes the session's last file if this was the
    /// last process in it.
    pub fn close(mut self) {
        self.goodbye();
        drop(self);
    }

    /// A register request of this agent. On the hub's machine every one names the publisher
    /// its actions come from: the hub ties this agent's id to it (and to the client the hello
    /// came from), so no other process's port can act in its name.
    pub(crate) fn request_of(&self, kind: RegisterKind, robot: Option<&RobotRegistration>) -> RegisterRequest {
        let publisher = match &self.link {
            Link::Shm(link) => link.actions.id().value(),
            Link::Zenoh(_) => 0,
        };
        RegisterRequest {
            kind: kind as u32,
            pid: std::process::id(),
            agent_id: self.agent_id,
            _reserved: 0,
            actions_publisher: [publisher as u64, (publisher >> 64) as u64],
            robot: robot.copied().unwrap_or_else(bytemuck::Zeroable::zeroed),
        }
    }

    fn goodbye(&mut self) {
        if !self.finished && self.agent_id != 0 && self.hub_alive() {
            let req = self.request_of(RegisterKind::Bye, None);
            match &self.link {
                Link::Shm(link) => {
                    if link.register.send_copy(req).is_ok() {
                        let _ = link.doorbell.notify();
                    }
                }
                Link::Zenoh(z) => z.say_goodbye(&req),
            }
            // Said once: the hub needs no answer, and a second goodbye would name a stranger.
            self.finished = true;
        }
    }

    /// The map as this agent's robots may know it, decoded: walls, beacons, targets, grid and
    /// route, without the scenario's obstacles (its sensors must find those). Waits up to 15 s
    /// for the hub's kept sample.
    pub fn map(&self) -> Result<map::Map, AgentError> {
        let (header, items) = self.map_items()?;
        Ok(map::Map::decode(&header, &items)?)
    }

    /// The map as [`Agent::map`] gives it, as it came over the wire: its header and items (for
    /// a bridge that passes it on).
    pub fn map_items(&self) -> Result<(MapHeader, Vec<MapItem>), AgentError> {
        match &self.link {
            Link::Shm(link) => {
                let svc = link.session.map(&link.node, Role::Client)?;
                receive_map_items(&svc, &link.session, || self.check())
            }
            Link::Zenoh(z) => z.map(&self.session),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(robot_id: u32) -> SensorBlock {
        SensorBlock { robot_id, ..bytemuck::Zeroable::zeroed() }
    }

    #[test]
    fn a_republished_tick_is_fresh_only_when_its_robots_changed() {
        let two = [block(1), block(2)];
        assert!(same_robots(&[1], &[block(1)]), "the same tick again: nothing new");
        assert!(!same_robots(&[1], &two), "a robot joined: its readings are new");
        assert!(!same_robots(&[1, 2], &[block(2)]), "a robot left");
        assert!(!same_robots(&[1, 2], &[block(2), block(1)]));
    }
}
