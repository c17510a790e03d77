//! Observers of a session: the world's truth, which agents never get.
//!
//! An [`Observer`] reads every robot's true state each tick, the observers' map (the lab with
//! the scenario's obstacles flagged), every robot's sensor geometry and the physical chairs'
//! states. Viewers, recorders, the runner and referees (the Python envs' judges) use it; an
//! agent learns only what its robots' sensors measure ([`agent_sdk::Agent`]), and the
//! architecture test forbids this crate to every agent and to every adapter that drives
//! robots.
//!
//! On another machine, [`Observer::connect_zenoh`] reads the same truth through the hub's Zenoh
//! bridge, when the bridge serves it (`iwsim zenoh --observers world`).
#![warn(missing_docs)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use agent_sdk::remote::{BridgeWatch, Remote};
use agent_sdk::{AgentError, map, ports};
use ipc_services::iceoryx2::node::Node;
use ipc_services::iceoryx2::port::subscriber::Subscriber;
use ipc_services::{Role, ServicesError, Session, Svc};
use ipc_types::remote as wire;
use ipc_types::{MapHeader, MapItem, RobotInfo, RobotState, WorldHeader};
use zenoh::Wait as _;

use ports::{ANSWER_TIMEOUT, ipc, receive_map, receive_newest};

/// A received world snapshot, held in shared memory.
type WorldSample = ipc_services::iceoryx2::sample::Sample<Svc, [RobotState], WorldHeader>;

/// The physical chairs' states, with the tick as header.
type ChairSubscriber = Subscriber<Svc, [ipc_types::ChairState], u64>;

/// A read-only view of a session: world snapshots and the map, with no hello and no robots,
/// so the hub does not count it as an agent (viewers, loggers).
pub struct Observer {
    /// Every robot's info (name, sensor geometry) as last received.
    infos: Vec<RobotInfo>,
    link: Link,
}

/// How an observer reaches its hub.
enum Link {
    /// Shared memory, on the hub's machine.
    Shm(Box<ShmLink>),
    /// Zenoh, through the hub's bridge, from any machine.
    Zenoh(Box<ZenohLink>),
}

/// An observer's shared-memory ports.
struct ShmLink {
    session: Session,
    hub_pid: Option<u32>,
    node: Node<Svc>,
    world: Subscriber<Svc, [RobotState], WorldHeader>,
    sensors: Subscriber<Svc, [RobotInfo], ()>,
    map_svc: ipc_services::MapService,
    /// The newest snapshot received, held in shared memory (not copied): what
    /// [`Observer::with_world`] lends and [`Observer::world`] copies.
    last_world: Option<WorldSample>,
    /// The physical chairs' port, opened at the first look (a served replay has none).
    chairs: Option<(ChairSubscriber, ipc_services::ChairService)>,
    /// Last, so it runs after every port and the node are gone.
    _release: ipc_services::SessionRelease,
}

/// The newest payload a subscriber received, not read yet.
type Newest = Arc<Mutex<Option<Vec<u8>>>>;

/// World snapshots received and not read yet, oldest first: a viewer takes the newest, a
/// recorder every one in order ([`Observer::next_world`]).
type Backlog = Arc<Mutex<std::collections::VecDeque<Vec<u8>>>>;

/// World snapshots kept for a reader that falls behind; older ones are dropped (a recorder
/// sees the gap in the ticks).
const WORLD_BACKLOG: usize = 1024;

/// An observer's Zenoh session with the hub's bridge.
struct ZenohLink {
    session: String,
    z: zenoh::Session,
    watch: BridgeWatch,
    world_in: Backlog,
    infos_in: Newest,
    _subscribers: [zenoh::pubsub::Subscriber<()>; 2],
    /// The newest snapshot received, copied out of the network buffer.
    last_world: Option<(WorldHeader, Vec<RobotState>)>,
    map: (MapHeader, Vec<MapItem>),
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Observer").field("session", &self.session()).finish()
    }
}

/// How long an observer waits for a kept world or robot info (the hub republishes both).
const KEPT_TIMEOUT: Duration = ANSWER_TIMEOUT;

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
            infos: Vec::new(),
            link: Link::Shm(Box::new(ShmLink {
                session,
                hub_pid,
                node,
                world,
                sensors,
                map_svc,
                last_world: None,
                chairs: None,
                _release: release,
            })),
        })
    }

    /// Attaches to the hub serving `session` on another machine, through its Zenoh bridge at
    /// `remote` (which must serve observers: `iwsim zenoh --observers world`), waiting up to
    /// `timeout` for the bridge to answer. What it reads is what a local observer reads, but
    /// for the physical chairs ([`Observer::try_chairs`] has none).
    pub fn connect_zenoh(remote: &Remote, session: &str, timeout: Duration) -> Result<Self, AgentError> {
        // No node here to install them: SIGINT and SIGTERM must still end the observer's loop.
        agent_sdk::remote::install_stop_handlers();
        let z = agent_sdk::remote::open_session(remote, timeout)?;
        let prefix = remote.prefix.clone().unwrap_or_else(|| wire::prefix(session));
        let watch = BridgeWatch::new(&z, &prefix)?;
        let (world_in, infos_in): (Backlog, Newest) = Default::default();
        let subscribe = |key: String, what: &str, keep: Box<dyn Fn(Vec<u8>) + Send + Sync>| {
            let news = watch.news.clone();
            z.declare_subscriber(key)
                .callback(move |s: zenoh::sample::Sample| {
                    keep(s.payload().to_bytes().into_owned());
                    *news.lock().unwrap_or_else(|p| p.into_inner()) = Some(Instant::now());
                })
                .wait()
                .map_err(|e| AgentError::Zenoh(format!("subscribe to {what}: {e}")))
        };
        let (worlds, infos) = (world_in.clone(), infos_in.clone());
        let subscribers = [
            subscribe(
                wire::observe_world_key(&prefix),
                "the world",
                Box::new(move |bytes| {
                    let mut q = worlds.lock().unwrap_or_else(|p| p.into_inner());
                    if q.len() >= WORLD_BACKLOG {
                        q.pop_front();
                    }
                    q.push_back(bytes);
                }),
            )?,
            subscribe(
                wire::observe_robots_key(&prefix),
                "the robots' info",
                Box::new(move |bytes| *infos.lock().unwrap_or_else(|p| p.into_inner()) = Some(bytes)),
            )?,
        ];
        // The observers' map, asked with the layouts' names (a bridge built with others
        // refuses, as one that serves no observers does), tried until `timeout`: the bridge
        // may be coming up.
        let start = Instant::now();
        let map = loop {
            match agent_sdk::remote::ask(
                &z,
                &wire::observe_map_key(&prefix),
                Some(wire::observer_schema()),
                "get the observers' map",
                session,
            ) {
                Ok(bytes) => break bytes,
                Err(AgentError::NoBridge(_)) if start.elapsed() < timeout && !ipc_services::stop_signalled() => {
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(AgentError::NoBridge(s)) => {
                    return Err(AgentError::Zenoh(format!(
                        "no bridge at {} serves observers of session {s:?} (is it started with --observers world?)",
                        remote.endpoint
                    )));
                }
                Err(e) => return Err(e),
            }
        };
        let frame = |error| AgentError::Frame { what: "observers' map", error };
        let (h, items): (MapHeader, Vec<MapItem>) = wire::unframe(&map).map_err(frame)?;
        wire::check_count(h.item_count, items.len()).map_err(frame)?;
        let infos =
            agent_sdk::remote::ask(&z, &wire::observe_robots_key(&prefix), None, "get the robots' info", session)?;
        let mut o = Self {
            infos: Vec::new(),
            link: Link::Zenoh(Box::new(ZenohLink {
                session: session.to_owned(),
                z,
                watch,
                world_in,
                infos_in,
                _subscribers: subscribers,
                last_world: None,
                map: (h, items),
            })),
        };
        // What the bridge answered stands until it puts newer news.
        if let Link::Zenoh(l) = &o.link {
            l.infos_in.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(infos);
        }
        o.refresh_robot_info()?;
        Ok(o)
    }

    /// Fails with [`AgentError::HubGone`] once the hub's process has exited (however it ended:
    /// a SIGKILLed hub publishes no last tick), and with [`AgentError::Interrupted`] on SIGINT
    /// or SIGTERM.
    /// Through Zenoh: [`AgentError::BridgeGone`] once the bridge has been out of reach for
    /// [`agent_sdk::remote::BRIDGE_GRACE`].
    pub fn check_alive(&self) -> Result<(), AgentError> {
        let l = match &self.link {
            Link::Shm(l) => l,
            Link::Zenoh(l) => {
                if ipc_services::stop_signalled() {
                    return Err(AgentError::Interrupted);
                }
                return if l.watch.alive(&l.z) { Ok(()) } else { Err(AgentError::BridgeGone(l.session.clone())) };
            }
        };
        if ipc_services::stop_requested(&l.node) {
            return Err(AgentError::Interrupted);
        }
        match l.hub_pid {
            Some(pid) if !ipc_services::process_alive(pid) => {
                Err(AgentError::HubGone { pid, session: l.session.name().to_owned() })
            }
            // No hub node was listed at attach: the hub died before the observer looked.
            None => Err(AgentError::HubGone { pid: 0, session: l.session.name().to_owned() }),
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
        if !self.receive_world()? {
            return Ok(None);
        }
        Ok(self.with_last_world(f))
    }

    /// The world snapshot after the last one read, copied out, if one came: through Zenoh
    /// every snapshot in the order the bridge put it (up to 1024 wait; a reader further behind
    /// loses the oldest), so a recorder misses none the network delivered; over shared memory
    /// the newest, as [`Observer::try_world`].
    pub fn next_world(&mut self) -> Result<Option<(WorldHeader, Vec<RobotState>)>, AgentError> {
        if !self.receive_world_from(true)? {
            return Ok(None);
        }
        Ok(self.with_last_world(|h, robots| (*h, robots.to_vec())))
    }

    /// Takes the newest world snapshot if one came since the last look; true if one did.
    fn receive_world(&mut self) -> Result<bool, AgentError> {
        self.receive_world_from(false)
    }

    /// Takes a world snapshot that came since the last look (through Zenoh, the oldest one
    /// waiting if `oldest`, else the newest, the rest dropped); true if one did.
    fn receive_world_from(&mut self, oldest: bool) -> Result<bool, AgentError> {
        match &mut self.link {
            Link::Shm(l) => receive_newest(&l.world, &mut l.last_world, "receive the world"),
            Link::Zenoh(l) => {
                let taken = {
                    let mut q = l.world_in.lock().unwrap_or_else(|p| p.into_inner());
                    if oldest {
                        q.pop_front()
                    } else {
                        let newest = q.pop_back();
                        q.clear();
                        newest
                    }
                };
                let Some(bytes) = taken else { return Ok(false) };
                let frame = |error| AgentError::Frame { what: "world snapshot", error };
                let (h, robots): (WorldHeader, Vec<RobotState>) = wire::unframe(&bytes).map_err(frame)?;
                wire::check_count(h.robot_count, robots.len()).map_err(frame)?;
                l.last_world = Some((h, robots));
                Ok(true)
            }
        }
    }

    /// Runs `f` on the world snapshot the last call received (held in shared memory, nothing
    /// copied), without looking for a newer one; `None` before the first.
    pub fn with_last_world<R>(&self, f: impl FnOnce(&WorldHeader, &[RobotState]) -> R) -> Option<R> {
        match &self.link {
            Link::Shm(l) => l.last_world.as_ref().map(|s| f(s.user_header(), s.payload())),
            Link::Zenoh(l) => l.last_world.as_ref().map(|(h, robots)| f(h, robots)),
        }
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
        let mut f = Some(f);
        loop {
            self.receive_world()?;
            if let Some(r) = self.with_last_world(|h, robots| f.take().map(|f| f(h, robots))).flatten() {
                return Ok(r);
            }
            self.check_alive()?;
            if start.elapsed() > KEPT_TIMEOUT {
                return Err(AgentError::NoAnswer(self.session().to_owned(), KEPT_TIMEOUT));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Takes every robot's info (name, proximity-sensor geometry) if the hub republished it
    /// since the last look (it does when the set of robots changes); true if it did.
    pub fn refresh_robot_info(&mut self) -> Result<bool, AgentError> {
        let mut changed = false;
        match &mut self.link {
            Link::Shm(l) => {
                while let Some(s) = l.sensors.receive().map_err(ipc("receive robot info"))? {
                    merge_infos(&mut self.infos, s.payload());
                    changed = true;
                }
            }
            Link::Zenoh(l) => {
                if let Some(bytes) = l.infos_in.lock().unwrap_or_else(|p| p.into_inner()).take() {
                    let frame = |error| AgentError::Frame { what: "robots' info", error };
                    let (count, infos): (u64, Vec<RobotInfo>) = wire::unframe(&bytes).map_err(frame)?;
                    wire::check_count(u32::try_from(count).unwrap_or(u32::MAX), infos.len()).map_err(frame)?;
                    merge_infos(&mut self.infos, &infos);
                    changed = true;
                }
            }
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
            if start.elapsed() > KEPT_TIMEOUT {
                return Err(AgentError::NoAnswer(self.session().to_owned(), KEPT_TIMEOUT));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The physical chairs' states (sensor mode, real and virtual readings, the test bench's
    /// true pose) with their tick, if the hub published them since the last call. `None` too
    /// when the session has no chair service (a served replay), and through Zenoh (the bridge
    /// does not carry them).
    pub fn try_chairs(&mut self) -> Result<Option<(u64, Vec<ipc_types::ChairState>)>, AgentError> {
        let Link::Shm(l) = &mut self.link else { return Ok(None) };
        if l.chairs.is_none() {
            match l.session.observer_chairs(&l.node, Role::Client) {
                Ok(svc) => {
                    let sub = svc.subscriber_builder().create().map_err(ipc("create a chairs subscriber"))?;
                    l.chairs = Some((sub, svc));
                }
                Err(ServicesError::NotRunning { .. }) => return Ok(None),
                Err(e) => return Err(e.into()),
            }
        }
        let Some((sub, _)) = &l.chairs else { return Ok(None) };
        let mut newest = None;
        while let Some(s) = sub.receive().map_err(ipc("receive chair states"))? {
            newest = Some((*s.user_header(), s.payload().to_vec()));
        }
        Ok(newest)
    }

    /// The observers' map, decoded: the lab with the scenario's obstacles flagged (waits up to
    /// 5 s for the hub's kept sample).
    pub fn map(&self) -> Result<map::Map, AgentError> {
        match &self.link {
            Link::Shm(l) => receive_map(&l.map_svc, &l.session, || Ok(())),
            Link::Zenoh(l) => Ok(map::Map::decode(&l.map.0, &l.map.1)?),
        }
    }

    /// [`Observer::map`] without the decoding: the map's header and items, copied out.
    pub fn map_items(&self) -> Result<(MapHeader, Vec<MapItem>), AgentError> {
        match &self.link {
            Link::Shm(l) => agent_sdk::receive_map_items(&l.map_svc, &l.session, || Ok(())),
            Link::Zenoh(l) => Ok(l.map.clone()),
        }
    }

    /// The session.
    pub fn session(&self) -> &str {
        match &self.link {
            Link::Shm(l) => l.session.name(),
            Link::Zenoh(l) => &l.session,
        }
    }

    /// Whether this observer reads the session through Zenoh (from another machine).
    pub fn is_remote(&self) -> bool {
        matches!(self.link, Link::Zenoh(_))
    }

    /// Detaches, and removes the session's last file if this was the last process in it
    /// (dropping the observer does the same).
    pub fn close(self) {
        drop(self);
    }
}

/// Takes a new set of robot infos: the newest, in the hub's robot order; then those of robots
/// that have left, so a snapshot read before they left still finds their names.
fn merge_infos(infos: &mut Vec<RobotInfo>, newest: &[RobotInfo]) {
    let mut ids: Vec<u32> = newest.iter().map(|i| i.robot_id).collect();
    ids.sort_unstable();
    let left: Vec<RobotInfo> = infos.iter().filter(|i| ids.binary_search(&i.robot_id).is_err()).copied().collect();
    infos.clear();
    infos.extend_from_slice(newest);
    infos.extend(left);
}
