//! The serving side of a session, one method per phase: what the live hub ([`crate::run`]) and
//! a served replay ([`crate::serve`]) both do, written once.
//!
//! A serving loop turns through the phases in this order:
//!
//! - **publish** ([`Server::publish_world`], [`Server::publish_blocks`], [`Server::ring`]): the
//!   tick's world snapshot (the robots' sensor geometry first when the set of robots changed),
//!   every agent's sensor blocks, then the tick doorbell;
//! - **accept** ([`Server::accept`]): sleep in `poll(2)` on the doorbell (rung by every client
//!   after it sends something) and one pidfd per agent process, so a crashed agent wakes the
//!   loop within a millisecond; let the publishers meet new subscribers; tell the [`Host`]
//!   which agents exited;
//! - **admit** ([`Server::admit`]): answer hellos, robot registrations, readies and byes, each
//!   checked against the port that said hello;
//! - **control** ([`Server::control`]): run-control commands;
//! - **collect** ([`Server::collect`]): the agents' actions, each from the publisher its hello
//!   named;
//! - **step** and **record** belong to the host (the world, or the recording, moves on);
//! - **linger** ([`Server::linger`]): at the end, give agents (and observers) time to read
//!   the last tick from this process's shared memory before it goes.
//!
//! What differs between a live world and a recorded one is behind [`Host`].

use std::collections::BTreeMap;
use std::os::fd::{AsRawFd as _, OwnedFd};
use std::time::{Duration, Instant};

use ipc_services::iceoryx2::node::Node;
use ipc_services::iceoryx2::prelude::PortFactory as _;
use ipc_services::{HUB_NODE_NAME, Session, SessionRelease, Svc, clean_dead_nodes};
use ipc_types::{
    ActionBlock, ChairState, Command, ControlResponse, MapHeader, MapItem, Refusal, RegisterKind, RegisterRequest,
    RegisterResponse, RobotInfo, RobotRegistration, RobotState, RunState, SensorBlock, TickHeader, WorldHeader,
};

use crate::core::Refused;
use crate::ports::{self, HubPorts, SensorPublisher, agent_sensor_port};
use crate::{HubError, ipc};

/// The longest the loop sleeps: how often it looks for a termination signal and for
/// subscribers that joined without ringing.
pub(crate) const IDLE_POLL: Duration = Duration::from_millis(50);

/// The longest the end waits for agents (and, for a replay, observers) to read the last tick
/// and leave: what a client reads lives in this process's shared memory, which goes with it.
pub(crate) const LINGER: Duration = Duration::from_secs(2);

/// What a served world answers: the live hub's core, or a replay's player.
pub(crate) trait Host {
    /// The tick being served.
    fn tick(&self) -> u64;
    /// The run state.
    fn run_state(&self) -> RunState;
    /// A new agent process: its id, or why not.
    fn hello(&mut self, pid: u32) -> Result<u32, Refused>;
    /// A robot for an agent: its id and sensor count, or why not.
    fn register(&mut self, agent: u32, robot: &RobotRegistration) -> Result<(u32, u32), Refused>;
    /// An agent has registered all its robots.
    fn ready(&mut self, agent: u32) -> Result<(), Refused>;
    /// An agent said goodbye.
    fn bye(&mut self, agent: u32);
    /// An agent's process exited without a goodbye: whether it was alive (its robots changed,
    /// so observers must hear of it now).
    fn exited(&mut self, agent: u32) -> bool;
    /// A run-control command; its status (0: done).
    fn command(&mut self, command: Command, robot: u32) -> u32;
    /// An agent's actions for `tick`; how many were for robots it does not own.
    fn actions(&mut self, agent: u32, tick: u64, blocks: &[ActionBlock]) -> usize;
}

/// A Linux pidfd: readable once the process has exited.
#[derive(Debug)]
struct PidFd(OwnedFd);

/// An attached agent: the port its sensor blocks go out on, and who may speak for it.
struct AgentPorts {
    publisher: SensorPublisher,
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

/// What an [`Server::admit`] phase changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Admitted {
    /// A robot was registered: its agent wants its readings soon.
    pub(crate) robot: bool,
    /// An agent said it is ready: it wants the current tick now.
    pub(crate) ready: bool,
}

/// What the server counted, for the run's outcome.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Counts {
    /// Agents that said hello.
    pub(crate) agents_seen: usize,
    /// Requests and actions in an agent's name from a port that is not its own.
    pub(crate) foreign_dropped: u64,
    /// Robot registrations refused.
    pub(crate) robots_refused: u64,
    /// Live agents whose process exited without a goodbye.
    pub(crate) agents_died: usize,
}

/// A session's services, served. Fields drop in order: the agents' ports, the session's, the
/// node, and last the session's files.
pub(crate) struct Server {
    agents: BTreeMap<u32, AgentPorts>,
    ports: HubPorts,
    node: Node<Svc>,
    session: Session,
    _release: SessionRelease,
    doorbell_fd: i32,
    pid: u32,
    poller: os::poll::Poller,
    fds: Vec<i32>,
    fd_agents: Vec<u32>,
    ready: Vec<usize>,
    counts: Counts,
}

impl Server {
    /// Opens session `name` (removing the nodes of dead processes an earlier run left in it),
    /// creates its services as the hub's node (failing if another process serves the
    /// session), and publishes both maps, kept for late subscribers: the agents' (no scenario
    /// obstacles: their sensors must find those) and the observers' (the truth).
    pub(crate) fn open(
        name: &str,
        agents_map: (MapHeader, Vec<MapItem>),
        observers_map: (MapHeader, Vec<MapItem>),
    ) -> Result<Self, HubError> {
        let session = Session::new(name)?;
        // Dropped last, on every way out (a failed port, the end of the run): the last process
        // of a session leaves nothing in /dev/shm.
        let release = session.release_on_drop();
        let cleaned = clean_dead_nodes(&session);
        if cleaned > 0 {
            tracing::info!("removed {cleaned} dead iceoryx2 nodes left by an earlier run of session {name}");
        }
        // The hub's node name: observers find the process serving the session by it.
        let node = session.node(HUB_NODE_NAME)?;
        let ports = HubPorts::open(&session, &node, agents_map, observers_map)?;
        Ok(Self {
            agents: BTreeMap::new(),
            doorbell_fd: ports.doorbell_fd(),
            ports,
            node,
            session,
            _release: release,
            pid: std::process::id(),
            poller: os::poll::Poller::default(),
            fds: Vec::new(),
            fd_agents: Vec::new(),
            ready: Vec::new(),
            counts: Counts::default(),
        })
    }

    /// Whether a Stop was asked for from outside (SIGINT or SIGTERM).
    pub(crate) fn stop_requested(&self) -> bool {
        ipc_services::stop_requested(&self.node)
    }

    /// Attached agents.
    pub(crate) fn agent_count(&self) -> usize {
        self.agents.len()
    }

    /// What the server counted so far.
    pub(crate) fn counts(&self) -> Counts {
        self.counts
    }

    /// Whether actions wait to be collected (no syscall: a lock-step hub spins on it).
    pub(crate) fn actions_waiting(&self) -> bool {
        self.ports.actions_sub.has_samples().unwrap_or(true)
    }

    /// **Publish**, 1 of 3: the world snapshot with `header`, its `count` robots written
    /// straight into the loaned sample; the robots' sensor geometry (`info`) goes first when
    /// the set of robots changed, so an observer that reads a snapshot finds every robot's
    /// name already there. `recorded` gets a copy of the snapshot.
    pub(crate) fn publish_world<I: Iterator<Item = RobotInfo>>(
        &mut self,
        header: WorldHeader,
        count: usize,
        states: impl Iterator<Item = RobotState>,
        info: impl FnOnce() -> I,
        recorded: Option<&mut Vec<RobotState>>,
    ) -> Result<(), HubError> {
        let mut sample = self.ports.world_pub.loan_slice_uninit(count).map_err(ipc("loan a world snapshot"))?;
        *sample.user_header_mut() = header;
        let sample = ports::fill(sample, states);
        self.ports.roster.note(sample.payload().iter().map(|s| s.id));
        if let Some(states) = recorded {
            states.clear();
            states.extend_from_slice(sample.payload());
        }
        self.ports.roster.publish_if_changed(info)?;
        sample.send().map_err(ipc("send a world snapshot"))?;
        Ok(())
    }

    /// The robots' sensor geometry as last published (the recorder keeps it with each frame).
    pub(crate) fn robot_info(&self) -> &[RobotInfo] {
        &self.ports.roster.scratch
    }

    /// **Publish**, 2 of 3: every agent's sensor blocks for the tick of `header`, each written
    /// straight into its loaned sample. An agent with no blocks gets nothing per tick, but
    /// every agent hears the end of the run.
    pub(crate) fn publish_blocks<B>(
        &self,
        header: &WorldHeader,
        spin_us: u32,
        lockstep: bool,
        blocks: impl Fn(u32) -> B,
    ) -> Result<(), HubError>
    where
        B: Iterator<Item = SensorBlock> + Clone,
    {
        let finished = header.run_state == RunState::Finished as u32;
        for (&id, agent) in &self.agents {
            let of_agent = blocks(id);
            let count = of_agent.clone().count();
            if count == 0 && !finished {
                continue;
            }
            let mut sample = agent.publisher.loan_slice_uninit(count).map_err(ipc("loan sensor blocks"))?;
            *sample.user_header_mut() = TickHeader {
                tick: header.tick,
                sim_time_s: header.sim_time_s,
                run_state: header.run_state,
                count: count as u32,
                t_pub_ns: 0,
                spin_us,
                flags: if lockstep { ipc_types::TICK_LOCKSTEP } else { 0 },
            };
            let mut sample = ports::fill(sample, of_agent);
            // Stamped last, so the latency figure starts at the send itself.
            sample.user_header_mut().t_pub_ns = ipc_services::monotonic_ns();
            sample.send().map_err(ipc("send sensor blocks"))?;
        }
        Ok(())
    }

    /// Publishes the physical chairs' states for observers (nothing when there are none).
    pub(crate) fn publish_chairs(
        &self,
        tick: u64,
        count: usize,
        states: impl Iterator<Item = ChairState>,
    ) -> Result<(), HubError> {
        ports::publish_chairs(&self.ports.chairs_pub, tick, count, states)
    }

    /// **Publish**, 3 of 3: rings the tick doorbell.
    pub(crate) fn ring(&self) -> Result<(), HubError> {
        self.ports.tick_notifier.notify().map_err(ipc("ring the tick"))?;
        Ok(())
    }

    /// **Accept**: sleeps until a client rings, an agent's process exits, or `timeout`
    /// passes; lets the publishers meet subscribers that came (a new subscriber gets the kept
    /// sample only when its publisher next looks: the maps are sent once, the world not while
    /// paused); tells `host` of every agent that exited. Returns whether observers must hear
    /// of an exit now.
    pub(crate) fn accept(&mut self, timeout: Duration, host: &mut impl Host) -> bool {
        self.fds.clear();
        self.fd_agents.clear();
        self.fds.push(self.doorbell_fd);
        for (&id, a) in &self.agents {
            if let Some(p) = &a.pidfd {
                self.fds.push(p.0.as_raw_fd());
                self.fd_agents.push(id);
            }
        }
        readable(&mut self.poller, &self.fds, timeout, &mut self.ready);
        let _ = self.ports.doorbell.try_wait(|_| {});
        self.ports.update_connections();
        let mut tell = false;
        for &i in self.ready.iter().filter(|&&i| i > 0) {
            let id = self.fd_agents[i - 1];
            let died = host.exited(id);
            self.counts.agents_died += died as usize;
            tell |= died;
            self.agents.remove(&id);
            let _ = self.node.try_cleanup_dead_nodes();
        }
        tell
    }

    /// **Admit**: answers every registration request waiting. A request in an agent's name
    /// from a port other than the one that said hello for it (another process, or a stale
    /// client) is refused and changes nothing.
    pub(crate) fn admit(&mut self, host: &mut impl Host) -> Result<Admitted, HubError> {
        let mut admitted = Admitted::default();
        while let Some(req) = self.ports.register_server.receive().map_err(ipc("receive a registration"))? {
            let r = *req.payload();
            let origin = req.origin().value();
            tracing::debug!("registration request kind {} from pid {} agent {}", r.kind, r.pid, r.agent_id);
            let mut resp =
                RegisterResponse { hub_pid: self.pid, tick: host.tick() as u32, ..bytemuck::Zeroable::zeroed() };
            let kind = RegisterKind::from_u32(r.kind);
            let foreign = kind.is_some_and(|k| k != RegisterKind::Hello)
                && self.agents.get(&r.agent_id).is_some_and(|a| a.client != origin);
            let answer = if foreign {
                self.counts.foreign_dropped += 1;
                tracing::warn!("a {kind:?} request in agent {}'s name came from another port; refused", r.agent_id);
                Err(Refused::new(Refusal::NotYours, "this agent id belongs to another process's port"))
            } else {
                match kind {
                    Some(RegisterKind::Hello) => self.hello(host, &r, origin).map(|id| resp.agent_id = id),
                    Some(RegisterKind::Robot) => {
                        resp.agent_id = r.agent_id;
                        let registered = host.register(r.agent_id, &r.robot);
                        self.counts.robots_refused += registered.is_err() as u64;
                        registered.map(|(robot_id, sensors)| {
                            resp.robot_id = robot_id;
                            resp.sensor_count = sensors;
                            admitted.robot = true;
                        })
                    }
                    Some(RegisterKind::Ready) => {
                        resp.agent_id = r.agent_id;
                        // The new agent's first sensor blocks: the current tick.
                        admitted.ready = true;
                        host.ready(r.agent_id)
                    }
                    Some(RegisterKind::Bye) => {
                        host.bye(r.agent_id);
                        self.agents.remove(&r.agent_id);
                        Ok(())
                    }
                    None => Err(Refused::new(Refusal::Malformed, "unknown request kind")),
                }
            };
            if let Err(refused) = answer {
                resp.status = refused.reason as u32;
                resp.set_detail(&refused.detail);
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
        Ok(admitted)
    }

    /// A hello: the host gives the agent an id, the server its sensor port.
    fn hello(&mut self, host: &mut impl Host, r: &RegisterRequest, origin: u128) -> Result<u32, Refused> {
        if named_publisher(r) == 0 {
            return Err(Refused::new(Refusal::Malformed, "a hello must name its actions publisher"));
        }
        let id = host.hello(r.pid)?;
        match agent_sensor_port(&self.session, &self.node, id) {
            Ok((service, publisher)) => {
                let pidfd = os::process::pidfd_open(r.pid).map(PidFd);
                if pidfd.is_none() {
                    tracing::warn!("agent {id}: pid {} cannot be watched; only the deadline guards it", r.pid);
                }
                let ports =
                    AgentPorts { publisher, _service: service, pidfd, client: origin, actions: named_publisher(r) };
                self.agents.insert(id, ports);
                self.counts.agents_seen += 1;
                Ok(id)
            }
            Err(e) => {
                // Out of shared memory or file descriptors: refuse this agent, serve the rest.
                tracing::warn!("agent {id}: cannot create its sensor service: {e}");
                host.bye(id);
                Err(Refused::new(Refusal::Capacity, "this agent's sensor service cannot be created"))
            }
        }
    }

    /// **Control**: answers every run-control command waiting. Returns whether any came (the
    /// world then republishes, so observers see the new run state).
    pub(crate) fn control(&mut self, host: &mut impl Host) -> Result<bool, HubError> {
        let mut any = false;
        while let Some(req) = self.ports.control_server.receive().map_err(ipc("receive a command"))? {
            let c = *req.payload();
            let status = Command::from_u32(c.command).map_or(1, |cmd| host.command(cmd, c.robot_id));
            let resp = ControlResponse { status, run_state: host.run_state() as u32, tick: host.tick() };
            req.send_copy(resp).map_err(ipc("answer a command"))?;
            any = true;
        }
        Ok(any)
    }

    /// **Collect**: hands every waiting action sample to `host`, each only if it came from
    /// the publisher its agent's hello named (otherwise another process acts in its name, or
    /// a port of an agent that has left: its robots keep their inputs).
    pub(crate) fn collect(&mut self, host: &mut impl Host) -> Result<(), HubError> {
        while let Some(sample) = self.ports.actions_sub.receive().map_err(ipc("receive actions"))? {
            let h = *sample.user_header();
            if self.agents.get(&h.agent_id).is_none_or(|a| a.actions != sample.origin().value()) {
                self.counts.foreign_dropped += 1;
                if self.counts.foreign_dropped.is_power_of_two() {
                    tracing::warn!(
                        "actions in agent {}'s name from a port that is not its own dropped ({} so far)",
                        h.agent_id,
                        self.counts.foreign_dropped
                    );
                }
                continue;
            }
            let ignored = host.actions(h.agent_id, h.tick, sample.payload());
            if ignored > 0 {
                tracing::debug!("agent {}: {ignored} actions for robots it does not own were ignored", h.agent_id);
            }
        }
        Ok(())
    }

    /// **Linger**: gives every agent process up to [`LINGER`] to read the last tick and exit;
    /// with `observers`, also waits for the world's subscribers to leave (they leave no fd to
    /// wait on, so it looks again every 10 ms).
    pub(crate) fn linger(&mut self, observers: bool) {
        let until = Instant::now() + LINGER;
        loop {
            self.fds.clear();
            self.fds.extend(self.agents.values().filter_map(|a| a.pidfd.as_ref().map(|p| p.0.as_raw_fd())));
            let watched = observers && self.ports.world_svc.dynamic_config().number_of_subscribers() > 0;
            let left = until.saturating_duration_since(Instant::now());
            if (self.fds.is_empty() && !watched) || left.is_zero() {
                return;
            }
            let timeout = if watched { left.min(Duration::from_millis(10)) } else { left };
            readable(&mut self.poller, &self.fds, timeout, &mut self.ready);
            if self.ready.is_empty() && !watched {
                return;
            }
            for &i in &self.ready {
                let fd = self.fds[i];
                self.agents.retain(|_, a| a.pidfd.as_ref().is_none_or(|p| p.0.as_raw_fd() != fd));
            }
        }
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
