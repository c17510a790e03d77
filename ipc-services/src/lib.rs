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
    ActionBlock, ActionHeader, ControlRequest, ControlResponse, MAX_AGENTS, MapHeader, MapItem, RegisterRequest,
    RegisterResponse, RobotSensors, RobotState, SensorBlock, TickHeader, WorldHeader, service,
};

pub use iceoryx2;

/// The iceoryx2 service flavour every iwsim process uses (inter-process, ports not `Send`).
pub type Svc = ipc::Service;
/// World snapshots.
pub type WorldService = publish_subscribe::PortFactory<Svc, [RobotState], WorldHeader>;
/// The map.
pub type MapService = publish_subscribe::PortFactory<Svc, [MapItem], MapHeader>;
/// Every robot's sensor geometry.
pub type RobotSensorsService = publish_subscribe::PortFactory<Svc, [RobotSensors], ()>;
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

/// Extra processes, beyond agents, that may attach to a session (viewers, bridges, CLI).
pub const MAX_OBSERVERS: usize = 16;
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

    /// An iceoryx2 node for this process. SIGINT and SIGTERM are caught: `node.wait(0)`
    /// then reports a termination request, so every process stops cleanly and removes what
    /// it created.
    pub fn node(&self, name: &str) -> Result<Node<Svc>, ServicesError> {
        let node_name = NodeName::new(name).map_err(|e| ServicesError::Iceoryx {
            action: "name the node",
            service: name.to_owned(),
            reason: format!("{e:?}"),
        })?;
        NodeBuilder::new()
            .name(&node_name)
            .config(&self.config)
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Svc>()
            .map_err(|e| ServicesError::Iceoryx {
                action: "create node",
                service: name.to_owned(),
                reason: format!("{e:?}"),
            })
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

    /// The map: published once with history, so every later subscriber gets it.
    pub fn map(&self, node: &Node<Svc>, role: Role) -> Result<MapService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::MAP)?)
            .publish_subscribe::<[MapItem]>()
            .user_header::<MapHeader>()
            .max_publishers(1)
            .max_subscribers(MAX_AGENTS + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::MAP)
    }

    /// Sensor geometry of every robot: republished with history when the robots change, so
    /// viewers can draw cones without the world snapshot carrying them every tick.
    pub fn robot_sensors(&self, node: &Node<Svc>, role: Role) -> Result<RobotSensorsService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(service::ROBOT_SENSORS)?)
            .publish_subscribe::<[RobotSensors]>()
            .max_publishers(1)
            .max_subscribers(MAX_AGENTS + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true);
        finish!(self, b, role, service::ROBOT_SENSORS)
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

    fn event(
        &self,
        node: &Node<Svc>,
        role: Role,
        part: &str,
        notifiers: usize,
        listeners: usize,
    ) -> Result<EventService, ServicesError> {
        let b = node
            .service_builder(&self.iox_name(part)?)
            .event()
            .max_notifiers(notifiers)
            .max_listeners(listeners)
            .max_nodes(MAX_NODES);
        finish!(self, b, role, part)
    }
}

impl Session {
    /// Called by each process after it dropped its node: when no live node of the session
    /// remains, removes the session's last file (iceoryx2's per-domain node counter), so a
    /// finished run leaves nothing in /dev/shm. Returns whether it was removed.
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
        #[allow(unsafe_code)]
        // SAFETY: iceoryx2 requires that no other process uses the domain. The domain is this
        // session's own prefix and no node of it is alive; a process starting this very
        // instant would recreate the counter on open_or_create.
        let removed = unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Svc>(&self.config) };
        removed.unwrap_or(false)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_names_are_checked() {
        assert!(Session::new("run-1_a").is_ok());
        for bad in ["", "a/b", "a b", "ü", &"x".repeat(65)] {
            assert!(matches!(Session::new(bad), Err(ServicesError::BadSession(_))), "{bad:?}");
        }
        assert_eq!(Session::new("s").expect("valid").service_name("world"), "iwsim/s/world");
    }
}
