//! Observers of a session: the world's truth, which agents never get.
//!
//! An [`Observer`] reads every robot's true state each tick, the observers' map (the lab with
//! the scenario's obstacles flagged), every robot's sensor geometry and the physical chairs'
//! states. Viewers, recorders, the runner and referees (the Python envs' judges) use it; an
//! agent learns only what its robots' sensors measure ([`agent_sdk::Agent`]), and the
//! architecture test forbids this crate to every agent and to every adapter that drives
//! robots.
#![warn(missing_docs)]

use std::time::{Duration, Instant};

use agent_sdk::{AgentError, map, ports};
use ipc_services::iceoryx2::node::Node;
use ipc_services::iceoryx2::port::subscriber::Subscriber;
use ipc_services::{Role, ServicesError, Session, Svc};
use ipc_types::{RobotInfo, RobotState, WorldHeader};

use ports::{ANSWER_TIMEOUT, ipc, receive_map, receive_newest};

/// A received world snapshot, held in shared memory.
type WorldSample = ipc_services::iceoryx2::sample::Sample<Svc, [RobotState], WorldHeader>;

/// The physical chairs' states, with the tick as header.
type ChairSubscriber = Subscriber<Svc, [ipc_types::ChairState], u64>;

/// A read-only view of a session: world snapshots and the map, with no hello and no robots,
/// so the hub does not count it as an agent (viewers, loggers).
pub struct Observer {
    session: Session,
    hub_pid: Option<u32>,
    _node: Node<Svc>,
    world: Subscriber<Svc, [RobotState], WorldHeader>,
    sensors: Subscriber<Svc, [RobotInfo], ()>,
    map_svc: ipc_services::MapService,
    /// The newest snapshot received, held in shared memory (not copied): what
    /// [`Observer::with_world`] lends and [`Observer::world`] copies.
    last_world: Option<WorldSample>,
    /// Every robot's info (name, sensor geometry) as last received.
    infos: Vec<RobotInfo>,
    /// The physical chairs' port, opened at the first look (a served replay has none).
    chairs: Option<(ChairSubscriber, ipc_services::ChairService)>,
    /// Last, so it runs after every port and the node are gone.
    _release: ipc_services::SessionRelease,
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Observer").field("session", &self.session.name()).finish()
    }
}

impl Observer {
    /// Attaches to the hub serving `session`, waiting up to `timeout` for it to come up.
    pub fn connect_within(session: &str, name: &str, timeout: Duration) -> Result<Self, AgentError> {
        let session = Session::new(session)?;
        // Declared before the node, so a failed attach (no hub) releases the session too.
        let release = session.release_on_drop();
        let node = session.node(name)?;
        let start = Instant::now();
        let (world_svc, map_svc, sensors_svc) = loop {
            let opened = (|| {
                Ok((
                    session.world(&node, Role::Client)?,
                    session.observer_map(&node, Role::Client)?,
                    session.robot_info(&node, Role::Client)?,
                ))
            })();
            match opened {
                Ok(services) => break services,
                Err(ServicesError::NotRunning { .. }) if start.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(e.into()),
            }
        };
        let world = world_svc.subscriber_builder().create().map_err(ipc("create a world subscriber"))?;
        let sensors = sensors_svc.subscriber_builder().create().map_err(ipc("create a robot-info subscriber"))?;
        // The hub creates its node before its services, so a hub whose services opened is
        // listed; one that died in between is found dead at the first check.
        let hub_pid = session.hub_pid();
        Ok(Self {
            session,
            hub_pid,
            _node: node,
            world,
            sensors,
            map_svc,
            last_world: None,
            infos: Vec::new(),
            chairs: None,
            _release: release,
        })
    }

    /// Fails with [`AgentError::HubGone`] once the hub's process has exited (however it ended:
    /// a SIGKILLed hub publishes no last tick), and with [`AgentError::Interrupted`] on SIGINT
    /// or SIGTERM.
    pub fn check_alive(&self) -> Result<(), AgentError> {
        if ipc_services::stop_requested(&self._node) {
            return Err(AgentError::Interrupted);
        }
        match self.hub_pid {
            Some(pid) if !ipc_services::process_alive(pid) => {
                Err(AgentError::HubGone { pid, session: self.session.name().to_owned() })
            }
            // No hub node was listed at attach: the hub died before the observer looked.
            None => Err(AgentError::HubGone { pid: 0, session: self.session.name().to_owned() }),
            Some(_) => Ok(()),
        }
    }

    /// The newest world snapshot if one arrived since the last call, copied out (see
    /// [`Observer::try_with_world`] to read it in place).
    pub fn try_world(&mut self) -> Result<Option<(WorldHeader, Vec<RobotState>)>, AgentError> {
        self.try_with_world(|h, robots| (*h, robots.to_vec()))
    }

    /// Runs `f` on the newest world snapshot, in the hub's shared memory (nothing is copied),
    /// if one arrived since the last call; `None` if none did.
    pub fn try_with_world<R>(
        &mut self,
        f: impl FnOnce(&WorldHeader, &[RobotState]) -> R,
    ) -> Result<Option<R>, AgentError> {
        if !receive_newest(&self.world, &mut self.last_world, "receive the world")? {
            return Ok(None);
        }
        Ok(self.with_last_world(f))
    }

    /// Runs `f` on the world snapshot the last call received (held in shared memory, nothing
    /// copied), without looking for a newer one; `None` before the first.
    pub fn with_last_world<R>(&self, f: impl FnOnce(&WorldHeader, &[RobotState]) -> R) -> Option<R> {
        self.last_world.as_ref().map(|s| f(s.user_header(), s.payload()))
    }

    /// The latest world snapshot: every robot's true state, copied out (see
    /// [`Observer::with_world`] to read it in place). The first call gets the snapshot the hub
    /// keeps for late subscribers (waiting up to 15 s for it); later calls return the newest one.
    pub fn world(&mut self) -> Result<(WorldHeader, Vec<RobotState>), AgentError> {
        self.with_world(|h, robots| (*h, robots.to_vec()))
    }

    /// Runs `f` on the latest world snapshot (as [`Observer::world`] finds it) where it lies in
    /// the hub's shared memory: the header and every robot's true state, with nothing copied.
    ///
    /// ```no_run
    /// let mut observer = observer::Observer::connect_within("demo", "counter", std::time::Duration::from_secs(5))?;
    /// let frozen = observer.with_world(|_, robots| robots.iter().filter(|r| r.flags & ipc_types::ROBOT_FROZEN != 0).count())?;
    /// # let _ = frozen;
    /// # Ok::<(), agent_sdk::AgentError>(())
    /// ```
    pub fn with_world<R>(&mut self, f: impl FnOnce(&WorldHeader, &[RobotState]) -> R) -> Result<R, AgentError> {
        let start = Instant::now();
        loop {
            receive_newest(&self.world, &mut self.last_world, "receive the world")?;
            if let Some(s) = &self.last_world {
                return Ok(f(s.user_header(), s.payload()));
            }
            self.check_alive()?;
            if start.elapsed() > ANSWER_TIMEOUT {
                return Err(AgentError::NoAnswer(self.session.name().to_owned(), ANSWER_TIMEOUT));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Takes every robot's info (name, proximity-sensor geometry) if the hub republished it
    /// since the last look (it does when the set of robots changes); true if it did.
    pub fn refresh_robot_info(&mut self) -> Result<bool, AgentError> {
        let mut changed = false;
        while let Some(s) = self.sensors.receive().map_err(ipc("receive robot info"))? {
            // The newest, in the hub's robot order; then those of robots that have left, so a
            // snapshot read before they left still finds their names.
            let mut ids: Vec<u32> = s.payload().iter().map(|i| i.robot_id).collect();
            ids.sort_unstable();
            let left: Vec<RobotInfo> =
                self.infos.iter().filter(|i| ids.binary_search(&i.robot_id).is_err()).copied().collect();
            self.infos.clear();
            self.infos.extend_from_slice(s.payload());
            self.infos.extend(left);
            changed = true;
        }
        Ok(changed)
    }

    /// Every robot's info (name, proximity-sensor geometry) as the last
    /// [`Observer::refresh_robot_info`] took it (empty before): the robots in the hub's order,
    /// then those that have left. Names live here, not in the per-tick snapshot: match a
    /// snapshot's robot to its info with [`RobotInfo::find`]. The hub publishes a new robot's
    /// info before the first snapshot that shows it, so a refresh after reading a snapshot
    /// finds all of its robots.
    pub fn robot_infos(&self) -> &[RobotInfo] {
        &self.infos
    }

    /// Every robot's info once it covers each robot of `robots` (a snapshot this observer
    /// read), waiting up to 15 s: a fresh observer gets the kept world and the kept info from
    /// two publishers, not necessarily together.
    pub fn robot_infos_covering(&mut self, robots: &[RobotState]) -> Result<&[RobotInfo], AgentError> {
        let start = Instant::now();
        loop {
            self.refresh_robot_info()?;
            if robots.iter().enumerate().all(|(k, r)| RobotInfo::find(&self.infos, k, r.id).is_some()) {
                return Ok(&self.infos);
            }
            self.check_alive()?;
            if start.elapsed() > ANSWER_TIMEOUT {
                return Err(AgentError::NoAnswer(self.session.name().to_owned(), ANSWER_TIMEOUT));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The physical chairs' states (sensor mode, real and virtual readings, the test bench's
    /// true pose) with their tick, if the hub published them since the last call. `None` too
    /// when the session has no chair service (a served replay).
    pub fn try_chairs(&mut self) -> Result<Option<(u64, Vec<ipc_types::ChairState>)>, AgentError> {
        if self.chairs.is_none() {
            match self.session.observer_chairs(&self._node, Role::Client) {
                Ok(svc) => {
                    let sub = svc.subscriber_builder().create().map_err(ipc("create a chairs subscriber"))?;
                    self.chairs = Some((sub, svc));
                }
                Err(ServicesError::NotRunning { .. }) => return Ok(None),
                Err(e) => return Err(e.into()),
            }
        }
        let Some((sub, _)) = &self.chairs else { return Ok(None) };
        let mut newest = None;
        while let Some(s) = sub.receive().map_err(ipc("receive chair states"))? {
            newest = Some((*s.user_header(), s.payload().to_vec()));
        }
        Ok(newest)
    }

    /// The observers' map, decoded: the lab with the scenario's obstacles flagged (waits up to
    /// 5 s for the hub's kept sample).
    pub fn map(&self) -> Result<map::Map, AgentError> {
        receive_map(&self.map_svc, &self.session, || Ok(()))
    }

    /// The session.
    pub fn session(&self) -> &str {
        self.session.name()
    }

    /// Detaches, and removes the session's last file if this was the last process in it
    /// (dropping the observer does the same).
    pub fn close(self) {
        drop(self);
    }
}
