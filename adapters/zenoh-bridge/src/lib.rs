//! The Zenoh bridge (`iwsim zenoh`): serves one hub session to agents on other machines.
//!
//! To the hub it is one agent, as the UDP bridge is: it registers the remote agents' robots,
//! stands in the lock-step barrier for them, and answers each tick when every remote agent
//! that got the tick's sensor blocks has answered, or a little before the hub's deadline. It
//! never links the hub or the world. To the remote agents it is their hub: the same payloads
//! as in shared memory (`ipc_types::remote`), each agent getting its own robots' sensor blocks
//! only, never the truth.
//!
//! A remote agent that goes (its process, its host or its link) takes its liveliness token
//! with it: its robots then stand with their motors at rest, answered for at once, until an
//! agent registers a robot of the same name (and id, or id 0) and so takes it back, as the hub
//! does for a local agent that died.

pub mod cli;
pub mod episodes;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::Read as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use agent_sdk::inbox::{Doorbell, Inbox, inbox};
use agent_sdk::pending::PendingRequest;
use agent_sdk::{Agent, AgentError};
use ipc_types::remote as wire;
use ipc_types::{
    ActionBlock, ActionHeader, Command, MapHeader, MapItem, Refusal, RegisterKind, RegisterRequest, RegisterResponse,
    RunState, SensorBlock, TickHeader,
};
use zenoh::Wait as _;

/// Why the bridge stopped.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// The hub side failed (or the hub went away).
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// Zenoh failed.
    #[error("zenoh failed to {0}")]
    Zenoh(String),
}

pub(crate) fn zerr<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> BridgeError + '_ {
    move |e| BridgeError::Zenoh(format!("{what}: {e}"))
}

/// A random number naming this run of the bridge (its token's key): agents that see another
/// one come know the bridge was restarted.
fn instance() -> Result<u64, BridgeError> {
    let mut b = [0u8; 8];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut b))
        .map_err(|e| BridgeError::Zenoh(format!("draw the bridge's instance: {e}")))?;
    Ok(u64::from_le_bytes(b))
}

/// A fresh agent secret, from the kernel's random source.
fn new_secret() -> std::io::Result<[u8; wire::SECRET_LEN]> {
    let mut s = [0u8; wire::SECRET_LEN];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut s)?;
    Ok(s)
}

/// How the bridge is set up.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    /// The hub's session.
    pub session: String,
    /// How long to wait for the hub.
    pub connect_timeout: Duration,
    /// Zenoh endpoints to listen on (`tcp/0.0.0.0:7447`).
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (a router).
    pub connect: Vec<String>,
    /// A Zenoh configuration file to start from.
    pub config: Option<PathBuf>,
    /// The key prefix; `iwsim/<session>` when `None`.
    pub prefix: Option<String>,
    /// What remote observers may read.
    pub observers: Observers,
    /// Remote agents that must say they are ready before the bridge tells the hub it is: a
    /// lock-step run then starts with every one of them in, as `iwsim hub --wait-agents` does
    /// for local agents. At least 1.
    pub wait_agents: usize,
}

/// What a bridge serves to observers on other machines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Observers {
    /// Nothing: the truth stays on the hub's machine.
    #[default]
    Off,
    /// Every robot's true state each tick, the robots' info and the observers' map.
    World,
}

/// The truth, served to remote observers (`--observers world`).
struct Observing {
    observer: observer::Observer,
    /// The observers' map, framed, for every query.
    map: Vec<u8>,
    world: zenoh::pubsub::Publisher<'static>,
    robots: zenoh::pubsub::Publisher<'static>,
    /// The robots' info, framed, as last put.
    infos: Vec<u8>,
}

impl Observing {
    fn start(
        cfg: &BridgeConfig,
        z: &zenoh::Session,
        prefix: &str,
        congestion: zenoh::qos::CongestionControl,
    ) -> Result<Self, BridgeError> {
        let observer = observer::Observer::connect_within(
            &cfg.session,
            &format!("zenoh-bridge-observer-{}", std::process::id()),
            cfg.connect_timeout,
        )?;
        let (h, items) = observer.map_items()?;
        let declare = |key: String| {
            z.declare_publisher(key)
                .express(true)
                .congestion_control(congestion)
                .wait()
                .map_err(zerr("declare a publisher"))
        };
        let mut o = Self {
            map: wire::frame(&h, &items),
            world: declare(wire::observe_world_key(prefix))?,
            robots: declare(wire::observe_robots_key(prefix))?,
            infos: wire::frame(&0u64, &[] as &[ipc_types::RobotInfo]),
            observer,
        };
        o.poll()?;
        Ok(o)
    }

    /// Puts what changed since the last look: the robots' info first (as the hub does, so a
    /// snapshot's robots are named by the time it arrives), then the newest world.
    fn poll(&mut self) -> Result<(), BridgeError> {
        if self.observer.refresh_robot_info()? {
            let infos = self.observer.robot_infos();
            self.infos = wire::frame(&(infos.len() as u64), infos);
            if let Err(e) = self.robots.put(self.infos.clone()).wait() {
                tracing::warn!("robots' info for observers: {e}");
            }
        }
        if let Some(bytes) = self.observer.try_with_world(wire::frame)?
            && let Err(e) = self.world.put(bytes).wait()
        {
            tracing::warn!("a world snapshot for observers: {e}");
        }
        Ok(())
    }

    fn answer(&self, q: &zenoh::query::Query, prefix: &str) {
        let key = q.key_expr().as_str();
        if key == wire::observe_robots_key(prefix) {
            let _ = q.reply(q.key_expr().clone(), self.infos.clone()).wait();
            return;
        }
        let schema = q.attachment().map(|a| a.to_bytes().into_owned()).unwrap_or_default();
        if schema != wire::observer_schema().as_bytes() {
            let _ = q
                .reply_err(format!(
                    "this bridge speaks {:?}, the observer {:?}: build both from the same iwsim",
                    wire::observer_schema(),
                    String::from_utf8_lossy(&schema)
                ))
                .wait();
            return;
        }
        let _ = q.reply(q.key_expr().clone(), self.map.clone()).wait();
    }
}

/// How the bridge's puts meet a full queue to a peer. In lock-step every tick's sensor blocks
/// and world must arrive (a dropped frame would change the run, or leave a hole in a remote
/// recording), and the run waits for its agents anyway: Block. In real time the newest frame
/// is what matters and one slow peer must not hold the others back: Drop, Zenoh's default.
fn congestion_control(lockstep: bool) -> zenoh::qos::CongestionControl {
    if lockstep { zenoh::qos::CongestionControl::Block } else { zenoh::qos::CongestionControl::Drop }
}

/// Where the bridge stands with the hub's ready (`--wait-agents`).
enum Readiness {
    /// The remote agents that said they are ready (`counted`), until there are enough; the
    /// ready queries that came once there were (`waiting`) wait for the hub's answer to the
    /// bridge's own request (`asked`, once sent).
    Counting { counted: BTreeSet<u32>, waiting: Vec<zenoh::query::Query>, asked: Option<Box<PendingRequest>> },
    /// The hub counts the bridge ready: a remote agent's ready is answered at once.
    Ready,
}

/// Input the bridge refused, by kind.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    /// Payloads of the wrong size or count.
    pub malformed: u64,
    /// Actions for a robot the sending agent does not own, or in another agent's name.
    pub foreign: u64,
    /// Hellos refused (other layouts, too many agents).
    pub refused: u64,
    /// Remote agents that went without saying goodbye.
    pub lost: u64,
    /// Of those, the ones that came back (their link closed and reopened) and took their
    /// robots again.
    pub came_back: u64,
}

/// What Zenoh's threads hand the bridge's loop.
enum Event {
    Query(zenoh::query::Query),
    Actions { agent_id: Option<u32>, bytes: Vec<u8>, secret: Option<[u8; wire::SECRET_LEN]> },
    Alive { agent_id: Option<u32>, up: bool },
}

/// How often the loop checks that the hub is alive and no signal came.
const CHECK_EVERY: Duration = Duration::from_millis(10);
/// How long the bridge stays after the run for its remote agents to leave.
const LINGER: Duration = Duration::from_secs(3);
/// Events kept for the loop at most.
const MAX_EVENTS: usize = 4096;
/// Robot registrations waiting for a free slot towards the hub, at most.
const MAX_QUEUED: usize = 1024;
/// Remote agents one bridge serves.
const MAX_REMOTE_AGENTS: usize = 256;
/// Robot registrations sent to the hub and not answered yet, counting the ready request: the
/// hub holds 4 requests per agent, and one slot stays free for the bridge's goodbye.
const MAX_REQUESTS_IN_FLIGHT: usize = 2;

/// A remote agent.
struct RemoteAgent {
    /// What proves a request or actions payload is this agent's (see `ipc_types::remote`).
    secret: [u8; wire::SECRET_LEN],
    robots: Vec<u32>,
    sensors: zenoh::pubsub::Publisher<'static>,
    /// The last tick this agent was sent sensor blocks for.
    sent: Option<u64>,
    /// The tick its last actions answer.
    answered: Option<u64>,
    /// Its last actions, one per robot.
    actions: BTreeMap<u32, ActionBlock>,
    /// Answered at the deadline without it: not waited for until it speaks again.
    waited_out: bool,
    /// Its liveliness token went (and has not come back): its robots are orphans meanwhile.
    gone: bool,
    /// When its last actions came (or its hello): in real time, a silence longer than
    /// [`Bridge::silence`] rests its robots.
    heard: Instant,
    /// Its robots were rested for its silence; it is not rested again until it speaks.
    rested: bool,
}

/// A robot whose remote agent went: it stands until an agent takes it back.
struct Orphan {
    robot_id: u32,
    name: String,
    answer: RegisterResponse,
    /// The remote agent it was left by (0: none; its registration was answered after it went).
    from: u32,
}

/// A registration the hub has not answered yet.
struct Joining {
    query: zenoh::query::Query,
    agent_id: u32,
    name: String,
    pending: PendingRequest,
}

/// A running bridge.
pub struct Bridge {
    agent: Agent,
    /// The truth for remote observers, when served.
    observing: Option<Observing>,
    control: Option<agent_sdk::ControlClient>,
    session: String,
    map: (MapHeader, Vec<MapItem>),
    z: zenoh::Session,
    prefix: String,
    events: Arc<Inbox<Event>>,
    wake: Doorbell,
    _queryables: Vec<zenoh::query::Queryable<()>>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    _token: zenoh::liveliness::LivelinessToken,
    remotes: BTreeMap<u32, RemoteAgent>,
    next_id: u32,
    /// Registrations forwarded to the hub, and those waiting for a free slot.
    joining: Vec<Joining>,
    queued: VecDeque<(zenoh::query::Query, RegisterRequest)>,
    /// Whether the hub counts the bridge ready, and the way there.
    readiness: Readiness,
    wait_agents: usize,
    /// Every put's congestion control (`congestion_control`): fixed by the hub's mode.
    congestion: zenoh::qos::CongestionControl,
    orphans: Vec<Orphan>,
    /// The robots' names, for taking a robot back.
    names: BTreeMap<u32, (String, RegisterResponse)>,
    /// The hub tick in hand and when it came.
    tick: Option<(u64, Instant)>,
    answered: bool,
    /// Actions arrived since the last answer (what real time answers on).
    changed: bool,
    /// When the hub's liveness was last checked.
    checked: Instant,
    /// Set by whoever runs the bridge to end it (an episode host ending an episode): it then
    /// says goodbye to the hub at once, before the hub is stopped.
    stop: Arc<std::sync::atomic::AtomicBool>,
    /// Per-tick scratch, kept so a tick allocates nothing: the hub's blocks by robot id,
    /// one remote agent's blocks, and the actions answered.
    index: Vec<(u32, usize)>,
    mine: Vec<SensorBlock>,
    answer: Vec<ActionBlock>,
    /// Refused input.
    pub counters: Counters,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge").field("session", &self.session).field("prefix", &self.prefix).finish()
    }
}

impl Bridge {
    /// Connects to the hub and opens the Zenoh side.
    pub fn start(cfg: &BridgeConfig) -> Result<Self, BridgeError> {
        let agent =
            Agent::connect_within(&cfg.session, &format!("zenoh-bridge-{}", std::process::id()), cfg.connect_timeout)?;
        let zcfg = agent_sdk::remote::config(cfg.config.as_deref(), "peer", &cfg.listen, &cfg.connect)
            .map_err(|e| BridgeError::Zenoh(e.to_string()))?;
        let z = zenoh::open(zcfg).wait().map_err(zerr("open a session"))?;
        Self::serve_on(cfg, agent, z)
    }

    /// Connects to the hub and serves it on an open Zenoh session `z` (an episode host's, which
    /// serves one bridge per episode); `cfg`'s endpoints and Zenoh file are not used.
    pub fn start_on(cfg: &BridgeConfig, z: zenoh::Session) -> Result<Self, BridgeError> {
        let name = format!("zenoh-bridge-{}-{}", std::process::id(), cfg.session);
        let agent = Agent::connect_within(&cfg.session, &name, cfg.connect_timeout)?;
        Self::serve_on(cfg, agent, z)
    }

    fn serve_on(cfg: &BridgeConfig, agent: Agent, z: zenoh::Session) -> Result<Self, BridgeError> {
        let map = agent.map_items()?;
        let congestion = congestion_control(map.0.params.lockstep != 0);
        let prefix = cfg.prefix.clone().unwrap_or_else(|| wire::prefix(&cfg.session));
        let (events, wake) = inbox::<Event>(MAX_EVENTS).map_err(zerr("make a wake-up socket"))?;
        let observing = match cfg.observers {
            Observers::Off => None,
            Observers::World => Some(Observing::start(cfg, &z, &prefix, congestion)?),
        };
        let mut keys = vec![wire::register_key(&prefix), wire::map_key(&prefix)];
        if observing.is_some() {
            keys.extend([wire::observe_map_key(&prefix), wire::observe_robots_key(&prefix)]);
        }
        let mut queryables = Vec::new();
        for key in keys {
            let ev = events.clone();
            queryables.push(
                z.declare_queryable(key)
                    .callback(move |q| {
                        ev.push(Event::Query(q));
                    })
                    .wait()
                    .map_err(zerr("declare a queryable"))?,
            );
        }
        let mut subscribers = Vec::new();
        let (ev, p) = (events.clone(), prefix.clone());
        subscribers.push(
            z.declare_subscriber(wire::all_actions_key(&prefix))
                .callback(move |s: zenoh::sample::Sample| {
                    let agent_id = wire::agent_of_key(&p, s.key_expr().as_str());
                    let secret = s.attachment().and_then(|a| a.to_bytes().as_ref().try_into().ok());
                    ev.push(Event::Actions { agent_id, bytes: s.payload().to_bytes().into_owned(), secret });
                })
                .wait()
                .map_err(zerr("subscribe to actions"))?,
        );
        let (ev, p) = (events.clone(), prefix.clone());
        subscribers.push(
            z.liveliness()
                .declare_subscriber(wire::all_alive_key(&prefix))
                .callback(move |s: zenoh::sample::Sample| {
                    let agent_id = wire::agent_of_key(&p, s.key_expr().as_str());
                    ev.push(Event::Alive { agent_id, up: s.kind() == zenoh::sample::SampleKind::Put });
                })
                .wait()
                .map_err(zerr("watch the agents"))?,
        );
        let token = z
            .liveliness()
            .declare_token(wire::bridge_key(&prefix, instance()?))
            .wait()
            .map_err(zerr("declare the bridge"))?;
        Ok(Self {
            agent,
            observing,
            control: None,
            session: cfg.session.clone(),
            map,
            z,
            prefix,
            events,
            wake,
            _queryables: queryables,
            _subscribers: subscribers,
            _token: token,
            remotes: BTreeMap::new(),
            next_id: 1,
            joining: Vec::new(),
            queued: VecDeque::new(),
            readiness: Readiness::Counting { counted: BTreeSet::new(), waiting: Vec::new(), asked: None },
            wait_agents: cfg.wait_agents.max(1),
            congestion,
            orphans: Vec::new(),
            names: BTreeMap::new(),
            tick: None,
            answered: true,
            changed: false,
            checked: Instant::now(),
            stop: Arc::default(),
            index: Vec::new(),
            mine: Vec::new(),
            answer: Vec::new(),
            counters: Counters::default(),
        })
    }

    /// A flag that ends [`Bridge::run`] when set (it returns its counters and, dropped, says
    /// goodbye to the hub).
    pub fn stopper(&self) -> Arc<std::sync::atomic::AtomicBool> {
        self.stop.clone()
    }

    /// The key prefix served.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// Serves until the hub ends the run or goes away.
    pub fn run(mut self) -> Result<Counters, BridgeError> {
        loop {
            let timeout = self.next_wake();
            self.wake.wait(Some(self.agent.tick_fd()), timeout);
            while let Some(e) = self.events.take() {
                self.on_event(e);
            }
            self.serve_joining()?;
            // Read the hub before judging its liveness: its last tick may be waiting.
            // The world before the agents' blocks: a remote referee judging a tick finds it
            // there when the agent's answer to it arrives.
            if let Some(o) = &mut self.observing {
                o.poll()?;
            }
            if let Some(tick) = self.agent.try_tick()? {
                self.on_tick(tick.tick);
            }
            if self.agent.finished() {
                tracing::info!("the hub ended the run");
                // The last world (its run state says the run is over) for remote observers.
                if let Some(o) = &mut self.observing {
                    o.poll()?;
                }
                self.linger();
                return Ok(self.counters);
            }
            if self.stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Ok(self.counters);
            }
            // A look at /proc and at the signals: every few milliseconds, not on every one of
            // the tens of wake-ups a tick brings (one per remote agent's answer).
            if self.checked.elapsed() >= CHECK_EVERY {
                self.agent.check_alive()?;
                self.checked = Instant::now();
            }
            self.answer_hub()?;
        }
    }

    /// After the run: stays until every remote agent has left (they leave on the last tick's
    /// blocks), at most [`LINGER`], so that closing the session cannot cut the last tick off
    /// before it reached them.
    fn linger(&mut self) {
        let until = Instant::now() + LINGER;
        while self.remotes.values().any(|r| !r.gone) && Instant::now() < until {
            self.wake.wait(None, Duration::from_millis(50));
            while let Some(e) = self.events.take() {
                match e {
                    // Leaving after the run, as agents do: not lost.
                    Event::Alive { agent_id: Some(id), up: false } => {
                        if let Some(r) = self.remotes.get_mut(&id) {
                            r.gone = true;
                        }
                    }
                    // A goodbye after the run, answered so its agent does not wait.
                    Event::Query(q) => {
                        let _ = q.reply_err("the run is over").wait();
                    }
                    _ => {}
                }
            }
        }
    }

    /// How long the loop may sleep: until the answer to the hub is due at the latest.
    fn next_wake(&self) -> Duration {
        let idle = Duration::from_millis(20);
        match self.tick {
            Some((_, since)) if !self.answered && self.map.0.params.lockstep != 0 => {
                let due = Duration::from_millis(u64::from(self.map.0.params.deadline_ms) * 9 / 10);
                due.saturating_sub(since.elapsed()).clamp(Duration::from_millis(1), idle)
            }
            _ => idle,
        }
    }

    fn on_event(&mut self, e: Event) {
        match e {
            Event::Query(q) => {
                let key = q.key_expr().as_str();
                if key == wire::map_key(&self.prefix) {
                    let _ = q.reply(q.key_expr().clone(), wire::frame(&self.map.0, &self.map.1)).wait();
                } else if key == wire::register_key(&self.prefix) {
                    self.on_register(q);
                } else if let Some(o) = &self.observing {
                    o.answer(&q, &self.prefix);
                }
            }
            Event::Actions { agent_id, bytes, secret } => self.on_actions(agent_id, &bytes, secret),
            Event::Alive { agent_id: Some(id), up: false } => self.lost(id),
            Event::Alive { agent_id: Some(id), up: true } => self.came_back(id),
            Event::Alive { agent_id: None, .. } => {}
        }
    }

    fn on_register(&mut self, q: zenoh::query::Query) {
        let Some(req) = q.payload().and_then(|p| wire::one::<RegisterRequest>(&p.to_bytes()).ok()) else {
            self.counters.malformed += 1;
            let _ = q.reply_err(format!("a register request is {} bytes", size_of::<RegisterRequest>())).wait();
            return;
        };
        let refuse = |q: &zenoh::query::Query, status: Refusal, detail: &str| {
            let mut r = RegisterResponse { status: status as u32, ..bytemuck::Zeroable::zeroed() };
            r.set_detail(detail);
            let _ = q.reply(q.key_expr().clone(), bytemuck::bytes_of(&r).to_vec()).wait();
        };
        match RegisterKind::from_u32(req.kind) {
            Some(RegisterKind::Hello) => {
                let schema = q.attachment().map(|a| a.to_bytes().into_owned()).unwrap_or_default();
                if schema != wire::schema().as_bytes() {
                    self.counters.refused += 1;
                    let _ = q
                        .reply_err(format!(
                            "this bridge speaks {:?}, the agent {:?}: build both from the same iwsim",
                            wire::schema(),
                            String::from_utf8_lossy(&schema)
                        ))
                        .wait();
                    return;
                }
                if self.remotes.values().filter(|r| !r.gone).count() >= MAX_REMOTE_AGENTS {
                    self.counters.refused += 1;
                    return refuse(&q, Refusal::Capacity, "the bridge serves no more agents");
                }
                let id = self.next_id;
                let publisher = match self
                    .z
                    .declare_publisher(wire::sensors_key(&self.prefix, id))
                    .express(true)
                    .congestion_control(self.congestion)
                    .wait()
                {
                    Ok(p) => p,
                    Err(e) => {
                        let _ = q.reply_err(format!("the bridge could not declare the agent's sensors: {e}")).wait();
                        return;
                    }
                };
                let secret = match new_secret() {
                    Ok(s) => s,
                    Err(e) => {
                        let _ = q.reply_err(format!("the bridge could not draw the agent's secret: {e}")).wait();
                        return;
                    }
                };
                self.next_id += 1;
                self.remotes.insert(
                    id,
                    RemoteAgent {
                        secret,
                        robots: Vec::new(),
                        sensors: publisher,
                        sent: None,
                        answered: None,
                        actions: BTreeMap::new(),
                        waited_out: false,
                        gone: false,
                        heard: Instant::now(),
                        rested: false,
                    },
                );
                tracing::info!("remote agent {id} said hello");
                let r = RegisterResponse { agent_id: id, ..bytemuck::Zeroable::zeroed() };
                // The reply reaches the querier only: the secret stays between the two.
                let _ =
                    q.reply(q.key_expr().clone(), bytemuck::bytes_of(&r).to_vec()).attachment(secret.to_vec()).wait();
            }
            _ if !self.remotes.contains_key(&req.agent_id) => {
                refuse(&q, Refusal::UnknownAgent, &format!("agent {} has not said hello", req.agent_id));
            }
            _ if self
                .remotes
                .get(&req.agent_id)
                .is_none_or(|r| q.attachment().is_none_or(|a| a.to_bytes().as_ref() != r.secret.as_slice())) =>
            {
                self.counters.foreign += 1;
                refuse(
                    &q,
                    Refusal::NotYours,
                    &format!("a request in agent {}'s name without its secret", req.agent_id),
                );
            }
            // Bounded: a flood of registrations is refused, not kept.
            Some(RegisterKind::Robot) if self.queued.len() >= MAX_QUEUED => {
                refuse(&q, Refusal::Capacity, "too many registrations waiting at the bridge");
            }
            Some(RegisterKind::Robot) => self.queued.push_back((q, req)),
            Some(RegisterKind::Ready) => {
                let enough = self.ready_remote_agents(Some(req.agent_id)) >= self.wait_agents;
                // An agent counted while the bridge waits for more is answered at once, as the
                // hub answers a local one (it then waits for the first tick, not for a reply
                // that could time out); the one that completes the count, once the hub has
                // answered the bridge.
                match &mut self.readiness {
                    Readiness::Counting { counted, waiting, .. } => {
                        counted.insert(req.agent_id);
                        if enough {
                            waiting.push(q);
                            return;
                        }
                    }
                    Readiness::Ready => {}
                }
                let r = RegisterResponse { agent_id: req.agent_id, ..bytemuck::Zeroable::zeroed() };
                let _ = q.reply(q.key_expr().clone(), bytemuck::bytes_of(&r).to_vec()).wait();
            }
            Some(RegisterKind::Bye) => {
                // As a local agent's goodbye: its robots leave the run.
                if let Readiness::Counting { counted, .. } = &mut self.readiness {
                    counted.remove(&req.agent_id);
                }
                if let Some(r) = self.remotes.remove(&req.agent_id) {
                    tracing::info!("remote agent {} said goodbye", req.agent_id);
                    for id in r.robots {
                        self.names.remove(&id);
                        self.command(Command::RemoveRobot, id);
                    }
                }
                let _ = q.reply(q.key_expr().clone(), vec![0u8; size_of::<RegisterResponse>()]).wait();
            }
            None => refuse(&q, Refusal::Malformed, &format!("unknown request kind {}", req.kind)),
        }
    }

    /// The remote agents that said they are ready and are still there (one that went before
    /// the run started no longer counts, and counts again if its link comes back), with
    /// `also` among them.
    fn ready_remote_agents(&self, also: Option<u32>) -> usize {
        let Readiness::Counting { counted, .. } = &self.readiness else { return 0 };
        let there = |id: &u32| self.remotes.get(id).is_some_and(|r| !r.gone);
        let also = also.filter(there);
        counted.iter().filter(|&id| Some(*id) != also && there(id)).count() + usize::from(also.is_some())
    }

    /// The bridge's own ready request to the hub, while it waits for the answer.
    fn asking_hub(&self) -> bool {
        matches!(self.readiness, Readiness::Counting { asked: Some(_), .. })
    }

    /// Forwards queued registrations to the hub, and the answers back.
    fn serve_joining(&mut self) -> Result<(), BridgeError> {
        // Ready once a remote robot exists (a bridge with no robots must not count towards a
        // hub's --wait-agents), and once --wait-agents remote agents say they are, with every
        // registration sent before answered: none of them then misses the first tick.
        let enough = self.ready_remote_agents(None) >= self.wait_agents;
        let settled = self.joining.is_empty() && self.queued.is_empty();
        if let Readiness::Counting { waiting, asked, .. } = &mut self.readiness {
            if asked.is_none() && !waiting.is_empty() && enough && settled {
                *asked = Some(Box::new(self.agent.start_ready()?));
            }
            if let Some(p) = asked {
                match self.agent.poll_answer(p) {
                    Ok(Some(_)) | Err(AgentError::Refused { .. }) => {
                        for q in waiting.drain(..) {
                            let _ = q.reply(q.key_expr().clone(), vec![0u8; size_of::<RegisterResponse>()]).wait();
                        }
                        self.readiness = Readiness::Ready;
                    }
                    Ok(None) => {}
                    Err(e) => return Err(e.into()),
                }
            }
        }
        while self.joining.len() + usize::from(self.asking_hub()) < MAX_REQUESTS_IN_FLIGHT {
            let Some((q, req)) = self.queued.pop_front() else { break };
            let name = req.robot.name.as_str().unwrap_or("").to_owned();
            // A robot whose remote agent went is taken back by a registration that names it.
            if let Some(i) = self
                .orphans
                .iter()
                .position(|o| o.name == name && (req.robot.requested_id == 0 || req.robot.requested_id == o.robot_id))
            {
                let o = self.orphans.remove(i);
                if let Some(r) = self.remotes.get_mut(&req.agent_id) {
                    r.robots.push(o.robot_id);
                }
                tracing::info!("remote agent {} took robot {} ({name:?}) back", req.agent_id, o.robot_id);
                let answer = RegisterResponse { agent_id: req.agent_id, ..o.answer };
                let _ = q.reply(q.key_expr().clone(), bytemuck::bytes_of(&answer).to_vec()).wait();
                continue;
            }
            let pending = self.agent.start_register(&req.robot)?;
            self.joining.push(Joining { query: q, agent_id: req.agent_id, name, pending });
        }
        let mut i = 0;
        while i < self.joining.len() {
            let j = &self.joining[i];
            let answer = match self.agent.poll_answer(&j.pending) {
                Ok(None) => {
                    i += 1;
                    continue;
                }
                Ok(Some(r)) => r,
                Err(AgentError::Refused { reason, detail }) => {
                    let mut r = RegisterResponse { status: reason as u32, ..bytemuck::Zeroable::zeroed() };
                    r.set_detail(&detail);
                    r
                }
                Err(e) => return Err(e.into()),
            };
            let j = self.joining.remove(i);
            let answer = RegisterResponse { agent_id: j.agent_id, hub_pid: 0, ..answer };
            if answer.status == Refusal::Accepted as u32 {
                match self.remotes.get_mut(&j.agent_id) {
                    Some(r) if !r.gone => {
                        r.robots.push(answer.robot_id);
                        self.names.insert(answer.robot_id, (j.name.clone(), answer));
                    }
                    Some(_) => {
                        self.names.insert(answer.robot_id, (j.name.clone(), answer));
                        let from = j.agent_id;
                        self.orphans.push(Orphan { robot_id: answer.robot_id, name: j.name.clone(), answer, from });
                    }
                    // Its agent went while the hub thought: the robot stands as an orphan.
                    None => {
                        self.orphans.push(Orphan { robot_id: answer.robot_id, name: j.name.clone(), answer, from: 0 })
                    }
                }
            }
            let _ = j.query.reply(j.query.key_expr().clone(), bytemuck::bytes_of(&answer).to_vec()).wait();
        }
        Ok(())
    }

    fn on_actions(&mut self, agent_id: Option<u32>, bytes: &[u8], secret: Option<[u8; wire::SECRET_LEN]>) {
        let Some(id) = agent_id else {
            self.counters.malformed += 1;
            return;
        };
        let Ok((h, blocks)) = wire::unframe::<ActionHeader, ActionBlock>(bytes) else {
            self.counters.malformed += 1;
            return;
        };
        if wire::check_count(h.count, blocks.len()).is_err() {
            self.counters.malformed += 1;
            return;
        }
        let Some(r) = self.remotes.get_mut(&id) else {
            self.counters.foreign += 1;
            return;
        };
        // Another session acting in this agent's name: it does not hold the agent's secret.
        if h.agent_id != id || secret != Some(r.secret) {
            self.counters.foreign += 1;
            return;
        }
        // Its own actions from an agent taken for gone: it is back, whatever its token said
        // (a token's news can arrive out of order across a restarted router, its going after
        // its coming back).
        if r.gone {
            self.came_back(id);
        }
        let Some(r) = self.remotes.get_mut(&id) else { return };
        for b in blocks {
            if r.robots.contains(&b.robot_id) {
                r.actions.insert(b.robot_id, b);
            } else {
                self.counters.foreign += 1;
            }
        }
        r.answered = Some(r.answered.map_or(h.tick, |t| t.max(h.tick)));
        r.waited_out = false;
        r.heard = Instant::now();
        r.rested = false;
        self.changed = true;
    }

    /// A remote agent's liveliness token went (its process, its host or its link): its robots
    /// stand until it comes back or another agent takes them back.
    fn lost(&mut self, id: u32) {
        let Some(r) = self.remotes.get_mut(&id) else { return };
        if r.gone {
            return;
        }
        r.gone = true;
        r.actions.clear();
        self.counters.lost += 1;
        tracing::warn!("remote agent {id} is gone: its robots {:?} stand until it comes back", r.robots);
        for robot_id in std::mem::take(&mut r.robots) {
            if let Some((name, answer)) = self.names.get(&robot_id).cloned() {
                self.orphans.push(Orphan { robot_id, name, answer, from: id });
            }
        }
        self.changed = true;
    }

    /// A remote agent's liveliness token came back (Zenoh reconnected its link): it takes its
    /// robots again, those no other agent took meanwhile.
    fn came_back(&mut self, id: u32) {
        let Some(r) = self.remotes.get_mut(&id) else { return };
        if !r.gone {
            return;
        }
        r.gone = false;
        r.waited_out = false;
        self.counters.came_back += 1;
        let mut k = 0;
        while k < self.orphans.len() {
            if self.orphans[k].from == id {
                r.robots.push(self.orphans.remove(k).robot_id);
            } else {
                k += 1;
            }
        }
        tracing::info!("remote agent {id} is back: its robots {:?}", r.robots);
    }

    fn on_tick(&mut self, tick: u64) {
        if self.tick.map(|t| t.0) != Some(tick) {
            self.tick = Some((tick, Instant::now()));
            self.answered = false;
        }
        let header = *self.agent.tick_header();
        let blocks = self.agent.sensors();
        let (index, mine) = (&mut self.index, &mut self.mine);
        index.clear();
        index.extend(blocks.iter().enumerate().map(|(i, b)| (b.robot_id, i)));
        index.sort_unstable();
        for r in self.remotes.values_mut() {
            mine.clear();
            mine.extend(
                r.robots
                    .iter()
                    .filter_map(|id| index.binary_search_by_key(id, |&(rid, _)| rid).ok().map(|k| blocks[index[k].1])),
            );
            if mine.is_empty() && RunState::from_u32(header.run_state) != Some(RunState::Finished) {
                continue;
            }
            // The remote agent spins for nothing: its ticks come over a network.
            let h = TickHeader { count: mine.len() as u32, spin_us: 0, ..header };
            if let Err(e) = r.sensors.put(wire::frame(&h, mine)).wait() {
                tracing::warn!("sensor blocks for a remote agent: {e}");
            }
            r.sent = Some(tick);
        }
    }

    /// Sends the remote agents' actions to the hub. In lock-step: once per tick, when every
    /// remote agent sent this tick's blocks has answered, or the hub's deadline is near (a
    /// silent agent then lags like any agent). In real time: whenever some actions came.
    fn answer_hub(&mut self) -> Result<(), BridgeError> {
        let Some((tick, since)) = self.tick else { return Ok(()) };
        // Not before the hub counts the bridge ready: while it waits for more remote agents,
        // an early one's answer to the tick in hand would be the bridge's, and a lock-step
        // hub takes one answer per agent and tick; the later agents' would be lost.
        if !matches!(self.readiness, Readiness::Ready) {
            return Ok(());
        }
        let p = &self.map.0.params;
        let mut late = false;
        let due = if p.lockstep != 0 {
            let all = self.queued.is_empty()
                && self.joining.is_empty()
                && self
                    .remotes
                    .values()
                    .all(|r| r.gone || r.waited_out || r.sent != Some(tick) || r.answered >= Some(tick));
            let near_deadline = since.elapsed() >= Duration::from_millis(u64::from(p.deadline_ms) * 9 / 10);
            late = !all;
            !self.answered && (all || near_deadline)
        } else {
            // In real time the hub keeps a robot's last powers: a remote agent silent for
            // longer than a few ticks (its link stalls) gets its robots rested once, rather
            // than driven blind until Zenoh's lease (10 s) declares it gone.
            let silence = self.silence();
            let mut rest = false;
            for r in self.remotes.values_mut() {
                if !r.gone && !r.rested && !r.robots.is_empty() && r.heard.elapsed() > silence {
                    r.rested = true;
                    r.actions.clear();
                    rest = true;
                    tracing::warn!(
                        "remote agent silent for {silence:?}: its robots {:?} rest until it speaks",
                        r.robots
                    );
                }
            }
            std::mem::take(&mut self.changed) || rest
        };
        if !due {
            return Ok(());
        }
        // In lock-step, a remote agent that has not answered this tick (it is slow, or its link
        // stalls) gets its robots' motors at rest rather than its last powers: over a network
        // silence can last a lease (10 s), too long to drive blind.
        let lockstep = p.lockstep != 0;
        let actions = &mut self.answer;
        actions.clear();
        for r in self.remotes.values() {
            if r.rested || lockstep && r.sent == Some(tick) && r.answered < Some(tick) {
                actions.extend(r.robots.iter().map(|&id| ActionBlock::motors(id, 0.0, 0.0)));
            } else {
                actions.extend(r.actions.values().copied());
            }
        }
        // A robot whose agent went stands: its motors at rest, until it is taken back.
        actions.extend(self.orphans.iter().map(|o| ActionBlock::motors(o.robot_id, 0.0, 0.0)));
        self.agent.send(tick, actions)?;
        self.answered = true;
        if late {
            for r in self.remotes.values_mut() {
                if r.sent == Some(tick) && r.answered < Some(tick) {
                    r.waited_out = true;
                }
            }
        }
        Ok(())
    }

    /// How long a remote agent may be silent in real time before its robots rest: five ticks,
    /// and at least half a second.
    fn silence(&self) -> Duration {
        Duration::from_millis(u64::from(self.map.0.cycle_ms) * 5).max(Duration::from_millis(500))
    }

    /// Sends a run-control command without waiting for the hub's answer.
    fn command(&mut self, command: Command, robot_id: u32) {
        if let Err(e) = agent_sdk::ControlClient::send_lazily(&mut self.control, &self.session, command, robot_id) {
            tracing::warn!("{command:?} for the hub failed: {e}");
        }
    }
}
