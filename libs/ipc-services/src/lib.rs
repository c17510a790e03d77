//! iwsim's iceoryx2 services, created by the hub and opened by every client with the same
//! settings from this one module (iceoryx2 refuses an open whose settings or types differ).
//!
//! All services of a run live under `iwsim/<session>/`, so two sessions on one machine never
//! see each other. Limits are explicit: iceoryx2's defaults (2 publishers, 8 subscribers,
//! 20 nodes per service) would refuse the 21st agent.
//!
//! ```no_run
//! use ipc_services::{Role, Session};
//!
//! let session = Session::new("demo").expect("a valid session name");
//! let node = session.node("agent-1").expect("iceoryx2 node");
//! // Fails with ServicesError::NotRunning when no hub serves "demo".
//! let world = session.world(&node, Role::Client).expect("a hub serves the session");
//! let subscriber = world.subscriber_builder().create().expect("a free subscriber slot");
//! # drop(subscriber);
//! ```
#![warn(missing_docs)]

use iceoryx2::config::Config;
use iceoryx2::node::{Node, NodeBuilder};
use iceoryx2::prelude::{AllocationStrategy, NodeName, SemanticString, ServiceName, SignalHandlingMode};
use iceoryx2::service::ipc;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};
use ipc_types::{
    ActionBlock, ActionHeader, ChairState, ControlRequest, ControlResponse, MAX_AGENTS, MapHeader, MapItem, Ping,
    RegisterRequest, RegisterResponse, RobotInfo, RobotState, SensorBlock, TickHeader, WorldHeader, service,
};

pub use iceoryx2;

/// The iceoryx2 service flavour every iwsim process uses (inter-process, ports not `Send`).
pub type Svc = ipc::Service;
/// World snapshots.
pub type WorldService = publish_subscribe::PortFactory<Svc, [RobotState], WorldHeader>;
/// The map.
pub type MapService = publish_subscribe::PortFactory<Svc, [MapItem], MapHeader>;
/// Every robot's sensor geometry.
pub type RobotInfoService = publish_subscribe::PortFactory<Svc, [RobotInfo], ()>;
/// Physical chairs, for observers.
pub type ChairService = publish_subscribe::PortFactory<Svc, [ChairState], u64>;
/// Actions from the agents.
pub type ActionService = publish_subscribe::PortFactory<Svc, [ActionBlock], ActionHeader>;
/// One agent's sensor blocks.
pub type SensorService = publish_subscribe::PortFactory<Svc, [SensorBlock], TickHeader>;
/// Hello and registration.
pub type RegisterService = request_response::PortFactory<Svc, RegisterRequest, (), RegisterResponse, ()>;
/// Run control.
pub type ControlService = request_response::PortFactory<Svc, ControlRequest, (), ControlResponse, ()>;
/// A doorbell.
pub type EventService = event::PortFactory<Svc>;
/// The latency benchmark's pings, driver to peer.
pub type PingService = publish_subscribe::PortFactory<Svc, Ping, ()>;
/// The latency benchmark's pongs (the ping's `seq`), peer to driver.
pub type PongService = publish_subscribe::PortFactory<Svc, u64, ()>;

/// The four services of `iwsim bench latency`'s raw iceoryx2 ping-pong, the baseline the
/// hub's latency is compared with: what a bare publish + notify costs, with no hub between.
#[derive(Debug)]
pub struct RawPingPong {
    /// Pings, driver to peer.
    pub ping: PingService,
    /// The peer's doorbell.
    pub ping_event: EventService,
    /// Pongs, peer to driver.
    pub pong: PongService,
    /// The driver's doorbell.
    pub pong_event: EventService,
}

/// Extra processes, beyond agents, that may attach to a session (viewers, bridges, CLI).
pub const MAX_OBSERVERS: usize = 16;
/// The name of the hub's iceoryx2 node: clients that never say hello (viewers) find the hub's
/// process by it.
pub const HUB_NODE_NAME: &str = "iwsim-hub";

/// Writes a line to stderr like `eprintln!`, but a closed or broken stderr (the reader of a
/// pipe went away) is ignored instead of panicking: what a process reports about itself is
/// never a reason for it to fail.
///
/// ```
/// ipc_services::report!("agent {}: ready", 7);
/// ```
#[macro_export]
macro_rules! report {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::writeln!(::std::io::stderr().lock(), $($arg)*);
    }};
}

/// Makes `command`'s child get SIGTERM when its parent (a runner, an episode host) dies,
/// however it dies (SIGKILL, a crash): the hub, the agents and the viewer then stop and clean
/// up as on Ctrl-C, rather than run on as orphans. The signal comes when the thread that
/// spawned the child ends, so children are spawned from a thread that lives as long as they
/// should (the main one). A parent that died between the fork and the child's `prctl` is
/// caught by comparing the parent's pid: the child then fails to start.
pub fn die_with_parent(command: &mut std::process::Command) {
    os::process::die_with_parent(command);
}

/// Whether process `pid` still runs: one of its threads has not exited yet. A killed process
/// whose parent has not reaped it yet has exited all the same (a zombie).
///
/// Every thread counts, not only the first: after a SIGKILL the main thread turns zombie while
/// the others are still exiting, and until the last of them has, the process keeps its files,
/// so iceoryx2 still sees its node alive (its monitor lock is held). A viewer that took the
/// zombie main thread for the end of a killed three-thread hub cleaned up too early, found the
/// hub's node "alive", and left the dead hub's shared memory in /dev/shm.
pub fn process_alive(pid: u32) -> bool {
    // One read while the main thread runs (the bridges ask on every turn of their loops); the
    // other threads are looked at only once it has exited.
    match thread_alive(&format!("/proc/{pid}/stat")) {
        Some(true) => true,
        None => false,
        Some(false) => std::fs::read_dir(format!("/proc/{pid}/task")).is_ok_and(|tasks| {
            tasks.flatten().any(|t| thread_alive(&t.path().join("stat").to_string_lossy()) == Some(true))
        }),
    }
}

/// Whether the thread whose `stat` file is at `path` has not exited; `None` when it is gone.
fn thread_alive(path: &str) -> Option<bool> {
    let stat = std::fs::read_to_string(path).ok()?;
    // The state follows the command name, which is in parentheses and may hold anything.
    Some(
        stat.rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_none_or(|state| state != "Z" && state != "X"),
    )
}

/// Nodes one service admits: every agent, every observer, the hub.
pub const MAX_NODES: usize = MAX_AGENTS + MAX_OBSERVERS + 1;

/// Creates (hub) or opens (client) a built service, with one error type for both.
macro_rules! finish {
    ($session:expr, $builder:expr, $role:expr, $part:expr) => {
        match $role {
            Role::Hub => $builder.create().map_err(|e| $session.fail($role, $part, e)),
            Role::Client => $builder.open().map_err(|e| $session.fail($role, $part, e)),
        }
    };
}

/// Which side of a service a process is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The hub creates the service (and fails if it exists).
    Hub,
    /// Everyone else opens it (and fails if no hub serves the session).
    Client,
}

/// Why a service could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum ServicesError {
    /// The session name is unusable.
    #[error("session name {0:?} is invalid: use 1 to 64 letters, digits, '-' or '_'")]
    BadSession(String),
    /// No hub serves this session (the service does not exist).
    #[error(
        "no hub is serving session {session:?} (service {service} does not exist); start `iwsim hub --session {session}` first"
    )]
    NotRunning {
        /// Session.
        session: String,
        /// Service that was missing.
        service: String,
    },
    /// The service exists already: another hub serves this session.
    #[error("another hub already serves session {session:?} (service {service} exists)")]
    AlreadyServed {
        /// Session.
        session: String,
        /// Service that exists.
        service: String,
    },
    /// iceoryx2 refused for another reason.
    #[error("iceoryx2 could not {action} {service}: {reason}")]
    Iceoryx {
        /// What was tried.
        action: &'static str,
        /// Which service or port.
        service: String,
        /// iceoryx2's error.
        reason: String,
    },
}

/// A session: the name space of one run's services, and the iceoryx2 configuration every
/// process of it uses (built in code, so no config file in the working directory can change
/// behaviour).
#[derive(Debug, Clone)]
pub struct Session {
    name: String,
    config: Config,
}

impl Session {
    /// A session by name: 1 to 64 of `[A-Za-z0-9_-]`.
    pub fn new(name: &str) -> Result<Self, ServicesError> {
        let ok = !name.is_empty()
            && name.len() <= 64
            && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if !ok {
            return Err(ServicesError::BadSession(name.to_owned()));
        }
        // The session is also an iceoryx2 domain: its files are named iwsim_<session>_…, so
        // sessions cannot see each other even by accident, and leftovers can be found.
        let mut config = Config::default();
        config.global.prefix = iceoryx2::prelude::FileName::new(Self::prefix_of(name).as_bytes())
            .map_err(|_| ServicesError::BadSession(name.to_owned()))?;
        Ok(Self { name: name.to_owned(), config })
    }

    /// The file name prefix of the session's shared memory and lock files.
    pub fn prefix_of(name: &str) -> String {
        format!("iwsim_{name}_")
    }

    /// The session's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The full service name of a part.
    pub fn service_name(&self, part: &str) -> String {
        format!("iwsim/{}/{}", self.name, part)
    }

    /// An iceoryx2 node for this process. SIGINT, SIGTERM and SIGHUP (a closed terminal or
    /// ssh session) are caught: [`stop_requested`] then says so, so every process stops
    /// cleanly and removes what it created.
    pub fn node(&self, name: &str) -> Result<Node<Svc>, ServicesError> {
        let node_name = NodeName::new(name).map_err(|e| ServicesError::Iceoryx {
            action: "name the node",
            service: name.to_owned(),
            reason: format!("{e:?}"),
        })?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&self.config)
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Svc>()
            .map_err(|e| ServicesError::Iceoryx {
                action: "create node",
                service: name.to_owned(),
                reason: format!("{e:?}"),
            })?;
        // iceoryx2 installs its handlers (for SIGHUP too, which it then only records) the
        // first time its signal handler is used, which may be any later call: use it now
        // (`wait` asks it whether to stop), so that ours, installed next, stay.
        let _ = node.wait(std::time::Duration::ZERO);
        install_stop_handlers();
        Ok(node)
    }

    fn iox_name(&self, part: &str) -> Result<ServiceName, ServicesError> {
        let full = self.service_name(part);
        ServiceName::new(&full).map_err(|e| ServicesError::Iceoryx {
            action: "name",
            service: full.clone(),
            reason: format!("{e:?}"),
        })
    }

    fn fail<E: std::fmt::Debug>(&self, role: Role, part: &str, e: E) -> ServicesError {
        let text = format!("{e:?}");
        let service = self.service_name(part);
        let session = self.name.clone();
        match role {
            Role::Client if text.contains("DoesNotExist") => ServicesError::NotRunning { session, service },
            Role::Hub if text.contains("AlreadyExists") => ServicesError::AlreadyServed { session, service },
            Role::Hub => ServicesError::Iceoryx { action: "create", service, reason: text },
            Role::Client => ServicesError::Iceoryx { action: "open", service, reason: text },
        }
    }

    /// World snapshots: one publisher (the hub), a subscriber per agent or observer, the
    /// latest snapshot kept for late subscribers, and a full queue dropping its oldest so a
    /// stalled reader can never block the hub.
    pub fn world(&self, node: &Node<Svc>, role: Role) -> Result<WorldService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::WORLD)?)
            .publish_subscribe::<[RobotState]>()
            .user_header::<WorldHeader>()
            .max_publishers(1)
            .max_subscribers(MAX_AGENTS + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::WORLD)
    }

    /// The agents' map (no scenario obstacles): published once with history, so every later
    /// subscriber gets it.
    pub fn map(&self, node: &Node<Svc>, role: Role) -> Result<MapService, ServicesError> {
        self.map_named(node, role, service::MAP)
    }

    /// The observers' map (with the scenario's obstacles), like [`Session::map`].
    pub fn observer_map(&self, node: &Node<Svc>, role: Role) -> Result<MapService, ServicesError> {
        self.map_named(node, role, service::OBSERVER_MAP)
    }

    fn map_named(&self, node: &Node<Svc>, role: Role, part: &'static str) -> Result<MapService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(part)?)
            .publish_subscribe::<[MapItem]>()
            .user_header::<MapHeader>()
            .max_publishers(1)
            .max_subscribers(MAX_AGENTS + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, part)
    }

    /// Sensor geometry of every robot: republished with history when the robots change, so
    /// viewers can draw cones without the world snapshot carrying them every tick.
    pub fn robot_info(&self, node: &Node<Svc>, role: Role) -> Result<RobotInfoService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::ROBOT_INFO)?)
            .publish_subscribe::<[RobotInfo]>()
            .max_publishers(1)
            .max_subscribers(MAX_AGENTS + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::ROBOT_INFO)
    }

    /// Physical chairs for observers: the hub publishes every tick while there are chairs
    /// (the tick in the header), the viewer subscribes; the last sample is kept for late
    /// subscribers.
    pub fn observer_chairs(&self, node: &Node<Svc>, role: Role) -> Result<ChairService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::OBSERVER_CHAIRS)?)
            .publish_subscribe::<[ChairState]>()
            .user_header::<u64>()
            .max_publishers(1)
            .max_subscribers(MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::OBSERVER_CHAIRS)
    }

    /// Actions: a publisher per agent (and bridge), one subscriber (the hub). Agents send one
    /// sample per tick holding all their robots; a buffer of 16 lets a fast agent in real-time
    /// mode send several per tick before the oldest are dropped.
    pub fn actions(&self, node: &Node<Svc>, role: Role) -> Result<ActionService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::ACTIONS)?)
            .publish_subscribe::<[ActionBlock]>()
            .user_header::<ActionHeader>()
            .max_publishers(MAX_AGENTS + MAX_OBSERVERS)
            .max_subscribers(1)
            .max_nodes(MAX_NODES)
            .history_size(0)
            .subscriber_max_buffer_size(16)
            .subscriber_max_borrowed_samples(2)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::ACTIONS)
    }

    /// One agent's sensor blocks: the hub publishes, the agent subscribes.
    pub fn agent_sensors(&self, node: &Node<Svc>, agent_id: u32, role: Role) -> Result<SensorService, ServicesError> {
        let part = format!("{}/{agent_id}/sensors", service::AGENT_SENSORS_PREFIX);
        let b = node
            .service_builder(&self.iox_name(&part)?)
            .publish_subscribe::<[SensorBlock]>()
            .user_header::<TickHeader>()
            .max_publishers(1)
            .max_subscribers(2)
            .max_nodes(4)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, &part)
    }

    /// Hello and registration: a client per process, the hub serves.
    pub fn register(&self, node: &Node<Svc>, role: Role) -> Result<RegisterService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::REGISTER)?)
            .request_response::<RegisterRequest, RegisterResponse>()
            .max_clients(MAX_AGENTS + MAX_OBSERVERS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(4)
            .max_response_buffer_size(2);
        finish!(self, b, role, service::REGISTER)
    }

    /// Run control: start, pause, step, stop, remove a robot.
    pub fn control(&self, node: &Node<Svc>, role: Role) -> Result<ControlService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::CONTROL)?)
            .request_response::<ControlRequest, ControlResponse>()
            .max_clients(MAX_AGENTS + MAX_OBSERVERS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(4)
            .max_response_buffer_size(2);
        finish!(self, b, role, service::CONTROL)
    }

    /// The tick doorbell: the hub rings it once per published tick; agents wait on it.
    pub fn tick_event(&self, node: &Node<Svc>, role: Role) -> Result<EventService, ServicesError> {
        self.event(node, role, service::WORLD, 1, MAX_AGENTS + MAX_OBSERVERS)
    }

    /// The hub's doorbell: clients ring it after sending actions, a registration or a
    /// command, so the hub sleeps until there is something to read.
    pub fn hub_event(&self, node: &Node<Svc>, role: Role) -> Result<EventService, ServicesError> {
        self.event(node, role, service::ACTIONS, MAX_AGENTS + MAX_OBSERVERS, 1)
    }

    /// The raw ping-pong of `iwsim bench latency`: the driver creates it (`Role::Hub`), the
    /// peer opens it (`Role::Client`). One-deep queues that drop their oldest, and otherwise
    /// iceoryx2's default limits: it is the plain baseline, not tuned for iwsim.
    pub fn raw_ping_pong(&self, node: &Node<Svc>, role: Role) -> Result<RawPingPong, ServicesError> {
        let ping = node
            .service_builder(&self.iox_name(service::BENCH_PING)?)
            .publish_subscribe::<Ping>()
            .subscriber_max_buffer_size(1)
            .enable_safe_overflow(true);
        let ping_event = node.service_builder(&self.iox_name(service::BENCH_PING)?).event();
        let pong = node
            .service_builder(&self.iox_name(service::BENCH_PONG)?)
            .publish_subscribe::<u64>()
            .subscriber_max_buffer_size(1)
            .enable_safe_overflow(true);
        let pong_event = node.service_builder(&self.iox_name(service::BENCH_PONG)?).event();
        Ok(RawPingPong {
            ping: finish!(self, ping, role, service::BENCH_PING)?,
            ping_event: finish!(self, ping_event, role, service::BENCH_PING)?,
            pong: finish!(self, pong, role, service::BENCH_PONG)?,
            pong_event: finish!(self, pong_event, role, service::BENCH_PONG)?,
        })
    }

    fn event(
        &self,
        node: &Node<Svc>,
        role: Role,
        part: &str,
        notifiers: usize,
        listeners: usize,
    ) -> Result<EventService, ServicesError> {
        // Every notification is event id 0. A listener drains its event ids with one atomic
        // swap each, and with iceoryx2's default of 256 ids that was ~2 µs per wait, twice a
        // tick in every agent: a sixth of the CPU time of 100 one-robot agents.
        let b = node
            .service_builder(&self.iox_name(part)?)
            .event()
            .event_id_max_value(0)
            .max_notifiers(notifiers)
            .max_listeners(listeners)
            .max_nodes(MAX_NODES);
        finish!(self, b, role, part)
    }
}

/// Removes the session's last file when dropped, if no live node of the session remains
/// ([`Session::release_if_unused`]). Held as the last field of a client (or the first local of a
/// function), it runs after every port and node of its owner is gone, on every way out: a
/// return, an error, a panic's unwinding.
#[derive(Debug)]
pub struct SessionRelease(Session);

impl Drop for SessionRelease {
    fn drop(&mut self) {
        self.0.release_if_unused();
    }
}

impl Session {
    /// A guard that releases the session when dropped; see [`SessionRelease`].
    pub fn release_on_drop(&self) -> SessionRelease {
        SessionRelease(self.clone())
    }

    /// The process id of the hub serving this session, found by its node's name; `None` when
    /// no live hub node is listed.
    pub fn hub_pid(&self) -> Option<u32> {
        use iceoryx2::node::{NodeState, NodeView as _};
        let mut pid = None;
        let _ = Node::<Svc>::list(&self.config, |state| {
            if let NodeState::Alive(view) = state
                && let Some(details) = view.details()
                && details.name().as_str() == HUB_NODE_NAME
            {
                pid = u32::try_from(details.process_id().value()).ok();
                return iceoryx2::prelude::CallbackProgression::Stop;
            }
            iceoryx2::prelude::CallbackProgression::Continue
        });
        pid
    }

    /// Called by each process after it dropped its node: when no live node of the session
    /// remains, removes the session's last file (iceoryx2's per-domain node counter), so a
    /// finished run leaves nothing in /dev/shm. Returns whether it was removed.
    ///
    /// A process of the session may start between the check and the removal; see
    /// `remove_node_counter` (private) for why that costs nothing.
    pub fn release_if_unused(&self) -> bool {
        use iceoryx2::node::NodeState;
        let mut live = 0;
        let _ = Node::<Svc>::list(&self.config, |state| {
            match state {
                NodeState::Dead(view) => {
                    let _ = view.try_remove_stale_resources();
                }
                _ => live += 1,
            }
            iceoryx2::prelude::CallbackProgression::Continue
        });
        if live > 0 {
            return false;
        }
        remove_node_counter(&self.config)
    }
}

/// Removes the domain's node counter: the one shared-memory file iceoryx2 0.10 keeps per domain
/// (`<prefix>…_node.0_10_0.global_mgmt` in /dev/shm, here one domain per session) and never
/// removes. It holds only a counter that node creation opens, increments into the new node's
/// id, and closes again. iceoryx2 0.10 (and its main branch) offers no way to remove it other
/// than `iceoryx2::testing::remove_global_mgmt_segment`, so this function is the only place
/// that names iceoryx2's `testing` API.
///
/// The race: iceoryx2 asks that no other process use the domain while it is removed, and the
/// caller can check only that no node was alive a moment ago. Another process of the session
/// (an agent joining as the last one leaves, a hub restarted at once) may start in between.
/// That loses nothing: no node, port or service holds the counter, and the services' own files
/// are not touched, so a live session keeps working. A node being created at that instant
/// either has the counter mapped already (it increments the unlinked copy) or finds it gone and
/// creates a fresh one; iceoryx2's open-or-create retries either way. A counter that restarts
/// at zero cannot repeat a node id, which also holds the process id and the creation time. The
/// worst outcome is a fresh counter file left until that process leaves and cleans up in turn.
/// `tests::a_live_session_survives_the_counter_removal_of_a_leaving_process` and
/// `tests::nodes_created_while_the_counter_is_removed_all_start_with_distinct_ids` check this.
///
/// Returns whether a counter was there and is now gone; a failed removal is logged and leaves
/// the file, which costs a few bytes of /dev/shm and nothing else.
fn remove_node_counter(config: &Config) -> bool {
    #[allow(unsafe_code)]
    // SAFETY: iceoryx2's contract is that no other process uses the domain. Callers check that
    // no node of the session is alive; one that starts after the check can only have opened the
    // counter, which stays valid for it after the unlink (see the race above).
    let removed = unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Svc>(config) };
    removed.unwrap_or_else(|e| {
        tracing::warn!("could not remove the session's iceoryx2 node counter: {e:?}");
        false
    })
}

/// CLOCK_MONOTONIC in nanoseconds: one clock for every process on the machine, so a
/// timestamp written by one process (`TickHeader::t_pub_ns`) can be compared by another.
#[cfg(target_os = "linux")]
pub fn monotonic_ns() -> u64 {
    // std's Instant is this clock but opaque; only a raw reading crosses processes.
    os::clock::monotonic_ns()
}

/// Allocation for slice publishers: start small and grow by powers of two, so a hub with ten
/// robots does not reserve shared memory for ten thousand.
pub const SLICE_ALLOCATION: AllocationStrategy = AllocationStrategy::PowerOfTwo;

/// Removes what crashed iwsim processes left behind (nodes whose process is gone, and the
/// services only they held), so a restarted hub can create its services again.
pub fn clean_dead_nodes(session: &Session) -> usize {
    use iceoryx2::node::NodeState;
    let mut removed = 0;
    let _ = Node::<Svc>::list(&session.config, |state| {
        if let NodeState::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            removed += 1;
        }
        iceoryx2::prelude::CallbackProgression::Continue
    });
    removed
}

/// Set by SIGINT, SIGTERM or SIGHUP once a node exists (see [`stop_requested`]).
static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether this process was asked to stop: SIGINT, SIGTERM, or SIGHUP (a closed terminal or
/// ssh session), or iceoryx2's own view of `node`.
///
/// iceoryx2 keeps only the *last* signal in one slot, which its own calls reset (a signal
/// that lands just before one is lost: under load a hub ran on after its SIGTERM), and it does
/// not take SIGHUP as a request to stop. So every node's process keeps its own flag: the
/// handlers below only store to it.
pub fn stop_requested(node: &Node<Svc>) -> bool {
    STOP.load(std::sync::atomic::Ordering::SeqCst) || node.wait(std::time::Duration::ZERO).is_err()
}

/// Whether a termination signal arrived (the handlers stay after every node is closed: a
/// process that lingers after its session can still be stopped).
pub fn stop_signalled() -> bool {
    STOP.load(std::sync::atomic::Ordering::SeqCst)
}

/// Installs the handlers that set [`STOP`], after iceoryx2's (which a node's creation may
/// install): SIGINT, SIGTERM, and SIGHUP unless it was ignored (as under `nohup`). Creating
/// a node calls it; a process with no node (an agent on another machine, joined over Zenoh)
/// calls it itself, so that it too stops cleanly on those signals.
pub fn install_stop_handlers() {
    extern "C" fn on_stop(_: libc::c_int) {
        // Only an atomic store: the one thing this handler may safely do.
        STOP.store(true, std::sync::atomic::Ordering::SeqCst);
    }
    // SIGHUP stays ignored where it was (as under `nohup`).
    let hup = !os::signals::is_ignored(libc::SIGHUP);
    let signals: &[i32] =
        if hup { &[libc::SIGINT, libc::SIGTERM, libc::SIGHUP] } else { &[libc::SIGINT, libc::SIGTERM] };
    if let Err(e) = os::signals::on_signals(signals, on_stop, true) {
        tracing::debug!("termination handlers not installed: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    /// A session no other test (or run of this test binary) shares.
    fn unique_session(tag: &str) -> Session {
        Session::new(&format!("ipc-services-test-{tag}-{}", std::process::id())).expect("a valid session name")
    }

    /// Releases the session when dropped, last of a test's locals, so a failing test leaves
    /// nothing behind either.
    struct ReleaseOnDrop(Session);

    impl Drop for ReleaseOnDrop {
        fn drop(&mut self) {
            self.0.release_if_unused();
        }
    }

    /// The session's files in /dev/shm.
    fn shm_files_of(session: &Session) -> Vec<String> {
        let prefix = Session::prefix_of(session.name());
        std::fs::read_dir("/dev/shm")
            .expect("/dev/shm is readable")
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|name| name.starts_with(&prefix))
            .collect()
    }

    /// The hub's side of a session: its node, world and tick services, publisher and notifier.
    struct TestHub {
        publisher: iceoryx2::port::publisher::Publisher<Svc, [RobotState], WorldHeader>,
        notifier: iceoryx2::port::notifier::Notifier<Svc>,
        _world: WorldService,
        _tick: EventService,
        node: Node<Svc>,
    }

    impl TestHub {
        fn start(session: &Session) -> Self {
            let node = session.node("hub").expect("a hub node");
            let world = session.world(&node, Role::Hub).expect("the hub creates the world");
            let tick = session.tick_event(&node, Role::Hub).expect("the hub creates the doorbell");
            let publisher = world
                .publisher_builder()
                .initial_max_slice_len(1)
                .allocation_strategy(SLICE_ALLOCATION)
                .create()
                .expect("a publisher");
            let notifier = tick.notifier_builder().create().expect("a notifier");
            Self { publisher, notifier, _world: world, _tick: tick, node }
        }

        /// Publishes the world snapshot of tick `n` and rings the tick doorbell.
        fn publish_tick(&self, n: u64) {
            let sample = self.publisher.loan_slice_uninit(1).expect("a sample");
            let mut sample = sample.write_from_fn(|_| <RobotState as bytemuck::Zeroable>::zeroed());
            *sample.user_header_mut() = WorldHeader { tick: n, ..WorldHeader::default() };
            sample.send().expect("sent");
            self.notifier.notify().expect("rung");
        }
    }

    /// In a thread of its own (as another process would be): a client node opens the world and
    /// tick services, says it is ready, and waits for the snapshot of tick `n`. Returns its
    /// node's id.
    fn client_waiting_for_tick(
        session: Session,
        n: u64,
        ready: std::sync::mpsc::Sender<()>,
    ) -> std::thread::JoinHandle<iceoryx2::identifiers::UniqueNodeId> {
        std::thread::spawn(move || {
            let node = session.node("client").expect("a client node after the removal");
            let world = session.world(&node, Role::Client).expect("the hub's world service still opens");
            let tick = session.tick_event(&node, Role::Client).expect("the hub's tick event still opens");
            let subscriber = world.subscriber_builder().create().expect("a subscriber");
            let listener = tick.listener_builder().create().expect("a listener");
            ready.send(()).expect("the test waits");
            let deadline = Instant::now() + Duration::from_secs(10);
            loop {
                if let Some(sample) = subscriber.receive().expect("receive")
                    && sample.user_header().tick == n
                {
                    return *node.id();
                }
                assert!(Instant::now() < deadline, "the snapshot of tick {n} never arrived");
                listener.timed_wait(|_| {}, Duration::from_millis(100)).expect("wait");
            }
        })
    }

    #[test]
    fn a_live_session_survives_the_counter_removal_of_a_leaving_process() {
        let session = unique_session("survives");
        let _release = ReleaseOnDrop(session.clone());
        let hub = TestHub::start(&session);

        // The usual path: a leaving process sees the hub alive and keeps the counter.
        assert!(!session.release_if_unused());
        // The race: a leaving process saw no live node just before the hub started, and its
        // removal runs now, with the hub's services in use.
        let before = shm_files_of(&session);
        assert!(remove_node_counter(&session.config), "the counter existed, so the removal ran");
        let after = shm_files_of(&session);
        let gone: Vec<_> = before.iter().filter(|f| !after.contains(f)).collect();
        assert!(
            gone.len() == 1 && gone[0].contains("global_mgmt") && after.iter().all(|f| before.contains(f)),
            "the removal takes the counter and nothing else: {before:?} -> {after:?}"
        );

        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let client = client_waiting_for_tick(session.clone(), 7, ready_tx);
        ready_rx.recv_timeout(Duration::from_secs(10)).expect("the client connected");
        hub.publish_tick(7);
        let client_id = client.join().expect("the client received the hub's snapshot");
        assert_ne!(client_id, *hub.node.id(), "a fresh counter must not repeat a node id");

        drop(hub);
        assert!(session.release_if_unused(), "the last process removes the counter the client recreated");
        assert_eq!(shm_files_of(&session), Vec::<String>::new());
    }

    #[test]
    fn nodes_created_while_the_counter_is_removed_all_start_with_distinct_ids() {
        let session = unique_session("churn");
        let _release = ReleaseOnDrop(session.clone());
        let hub = TestHub::start(&session);

        let creators_done = AtomicBool::new(false);
        let (ids, removals) = std::thread::scope(|scope| {
            // Removes the counter over and over while nodes are created, and at least once
            // (after the creators, the counter they made is there to remove).
            let remover = scope.spawn(|| {
                let mut removals = 0;
                while !(creators_done.load(Ordering::Acquire) && removals > 0) {
                    if remove_node_counter(&session.config) {
                        removals += 1;
                    }
                    std::thread::yield_now();
                }
                removals
            });
            let creators: Vec<_> = (0..4)
                .map(|t| {
                    let session = &session;
                    scope.spawn(move || {
                        (0..20)
                            .map(|i| session.node(&format!("churn-{t}-{i}")).map(|node| *node.id()))
                            .collect::<Result<Vec<_>, _>>()
                    })
                })
                .collect();
            let ids: Vec<_> = creators
                .into_iter()
                .flat_map(|c| c.join().expect("no panic").expect("every node is created"))
                .collect();
            creators_done.store(true, Ordering::Release);
            (ids, remover.join().expect("no panic"))
        });
        assert!(removals > 0);
        assert_eq!(ids.iter().collect::<HashSet<_>>().len(), 80, "node ids repeat: {ids:?}");

        // The hub's services outlived it all.
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let client = client_waiting_for_tick(session.clone(), 3, ready_tx);
        ready_rx.recv_timeout(Duration::from_secs(10)).expect("the client connected");
        hub.publish_tick(3);
        client.join().expect("the client received the hub's snapshot");

        drop(hub);
        session.release_if_unused();
        assert_eq!(shm_files_of(&session), Vec::<String>::new());
    }

    #[test]
    fn a_zombie_or_reaped_process_is_not_alive() {
        assert!(process_alive(std::process::id()));
        let mut child = std::process::Command::new("true").spawn().expect("true runs");
        // Exited but not reaped: a zombie, which /proc still lists.
        let pid = child.id();
        let until = Instant::now() + Duration::from_secs(10);
        while process_alive(pid) {
            assert!(Instant::now() < until, "`true` never exited");
            std::thread::yield_now();
        }
        assert!(std::path::Path::new(&format!("/proc/{pid}")).exists(), "a zombie is still listed");
        child.wait().expect("reaped");
        assert!(!process_alive(pid));
    }

    #[test]
    fn every_event_service_carries_one_event_id_and_a_ring_drains_as_one() {
        // A listener's drain visits every event id the service allows; iwsim rings only id 0.
        use iceoryx2::prelude::PortFactory;
        let session = unique_session("event-ids");
        let _release = ReleaseOnDrop(session.clone());
        let node = session.node("hub").expect("a node");
        for svc in [
            session.tick_event(&node, Role::Hub).expect("the tick event"),
            session.hub_event(&node, Role::Hub).expect("the hub's doorbell"),
        ] {
            assert_eq!(svc.static_config().event_id_max_value(), 0);
            let listener = svc.listener_builder().create().expect("a listener");
            let notifier = svc.notifier_builder().create().expect("a notifier");
            notifier.notify().expect("rung");
            notifier.notify().expect("rung again");
            let mut ids = Vec::new();
            listener.try_wait(|e| ids.push((e.id.as_value(), e.count))).expect("drained");
            assert_eq!(ids, [(0, 2)], "two rings of id 0, drained as one activation that counts both");
        }
    }

    #[test]
    fn the_hub_is_found_by_its_node_name() {
        let session = unique_session("hub-pid");
        let _release = ReleaseOnDrop(session.clone());
        assert_eq!(session.hub_pid(), None);
        let other = session.node("viewer").expect("a node");
        assert_eq!(session.hub_pid(), None, "only the hub's node counts");
        let hub = session.node(HUB_NODE_NAME).expect("the hub's node");
        assert_eq!(session.hub_pid(), Some(std::process::id()));
        drop((hub, other));
        assert_eq!(session.hub_pid(), None);
    }

    #[test]
    fn a_release_guard_removes_the_session_file_of_a_failed_client() {
        let session = unique_session("guard");
        {
            let _release = session.release_on_drop();
            let node = session.node("client").expect("a node");
            assert!(matches!(session.world(&node, Role::Client), Err(ServicesError::NotRunning { .. })));
            assert!(!shm_files_of(&session).is_empty(), "the node made the session's counter");
        }
        assert_eq!(shm_files_of(&session), Vec::<String>::new());
    }

    #[test]
    fn report_survives_any_arguments() {
        report!("{} {:?}", 1, "two");
    }

    #[test]
    fn session_names_are_checked() {
        assert!(Session::new("run-1_a").is_ok());
        for bad in ["", "a/b", "a b", "ü", &"x".repeat(65)] {
            assert!(matches!(Session::new(bad), Err(ServicesError::BadSession(_))), "{bad:?}");
        }
        assert_eq!(Session::new("s").expect("valid").service_name("world"), "iwsim/s/world");
    }
}
