//! An agent's link to a hub on another machine: Zenoh, through the hub's bridge (`iwsim
//! zenoh`). The payloads are the shared-memory ones, byte for byte (`ipc_types::remote`), so an
//! [`Agent`](crate::Agent) on this link serves the same calls as on the hub's machine; only
//! its sensor blocks are copied (out of the network buffer) instead of lent in place.
//!
//! ```no_run
//! use agent_sdk::{Agent, Wait, remote::Remote};
//! use std::time::Duration;
//!
//! let remote = Remote::new("tcp/10.0.0.5:7447");
//! let mut agent = Agent::connect_zenoh(&remote, "demo", Duration::from_secs(5)).expect("a bridge answers");
//! # let _ = agent.wait_tick(Wait::Blocking);
//! ```

use std::collections::VecDeque;
use std::io::{Read as _, Write as _};
use std::os::fd::AsRawFd as _;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ipc_types::remote::{self as wire, FrameError};
use ipc_types::{
    ActionBlock, ActionHeader, MapHeader, MapItem, RegisterRequest, RegisterResponse, SensorBlock, TickHeader,
};
use zenoh::Wait as _;

use crate::{ANSWER_TIMEOUT, AgentError};

/// How long the bridge may be out of reach before the agent gives up on it: a cable pulled
/// for a moment, or a router restarted, costs ticks but not the agent (Zenoh reconnects and
/// declares the agent's subscriptions and token again by itself).
pub const BRIDGE_GRACE: Duration = Duration::from_secs(5);

/// Sensor frames kept between two reads of the agent. More means it fell behind: the oldest
/// go, since only the newest tick matters (as in shared memory, where the hub keeps one).
const INBOX_FRAMES: usize = 8;

pub use ipc_services::install_stop_handlers;

/// Where a hub's Zenoh bridge is and how to reach it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Remote {
    /// The endpoint to connect to: the bridge's `--listen`, or a Zenoh router's.
    pub endpoint: String,
    /// A Zenoh configuration file (JSON5) to start from, for TLS, authentication and the
    /// like; the endpoint is added to it.
    pub config: Option<PathBuf>,
    /// The key prefix the bridge serves the session under; `iwsim/<session>` when `None`.
    pub prefix: Option<String>,
}

impl Remote {
    /// A bridge at `endpoint`, with Zenoh's defaults and the default key prefix.
    pub fn new(endpoint: &str) -> Self {
        Self { endpoint: endpoint.to_owned(), config: None, prefix: None }
    }
}

fn zerr<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> AgentError + '_ {
    move |e| AgentError::Zenoh(format!("{what}: {e}"))
}

/// A Zenoh configuration: the file's, or the defaults, with multicast scouting off (the peers
/// are named, and a lab's multicast must not join one session to another's) and `mode` and
/// `endpoints` set as given.
pub fn config(
    file: Option<&std::path::Path>,
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, AgentError> {
    let mut c = match file {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| AgentError::Zenoh(format!("read the Zenoh configuration {}: {e}", path.display())))?,
        None => zenoh::Config::default(),
    };
    let json = |v: &[String]| format!("[{}]", v.iter().map(|e| format!("{e:?}")).collect::<Vec<_>>().join(","));
    c.insert_json5("mode", &format!("{mode:?}")).map_err(zerr("set the mode"))?;
    c.insert_json5("scouting/multicast/enabled", "false").map_err(zerr("turn multicast scouting off"))?;
    if !listen.is_empty() {
        c.insert_json5("listen/endpoints", &json(listen)).map_err(zerr("set the listen endpoints"))?;
    }
    if !connect.is_empty() {
        c.insert_json5("connect/endpoints", &json(connect)).map_err(zerr("set the connect endpoints"))?;
    }
    Ok(c)
}

/// Opens a Zenoh client session to `remote`, trying until `timeout` passes (the bridge or the
/// router may be coming up) or a stop signal comes.
pub fn open_session(remote: &Remote, timeout: Duration) -> Result<zenoh::Session, AgentError> {
    let cfg = config(remote.config.as_deref(), "client", &[], std::slice::from_ref(&remote.endpoint))?;
    let start = Instant::now();
    loop {
        match zenoh::open(cfg.clone()).wait() {
            Ok(z) => return Ok(z),
            Err(_) if start.elapsed() < timeout && !ipc_services::stop_signalled() => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => return Err(AgentError::Zenoh(format!("connect to {}: {e}", remote.endpoint))),
        }
    }
}

/// Asks the bridge serving `session` at `key` (with `attachment`, if any) and returns the
/// payload of its answer: [`AgentError::NoBridge`] when none answers within
/// [`ANSWER_TIMEOUT`], the bridge's own words when it refuses.
pub fn ask(
    z: &zenoh::Session,
    key: &str,
    attachment: Option<String>,
    what: &str,
    session: &str,
) -> Result<Vec<u8>, AgentError> {
    query(z, key, None, attachment.map(String::into_bytes), ANSWER_TIMEOUT, what, session)
}

/// A query's one answer, as [`ask`], with a payload and a timeout of its own.
fn query(
    z: &zenoh::Session,
    key: &str,
    payload: Option<Vec<u8>>,
    attachment: Option<Vec<u8>>,
    timeout: Duration,
    what: &str,
    server: &str,
) -> Result<Vec<u8>, AgentError> {
    let mut get = z.get(key).timeout(timeout);
    if let Some(p) = payload {
        get = get.payload(p);
    }
    if let Some(a) = attachment {
        get = get.attachment(a);
    }
    let replies = get.wait().map_err(zerr(what))?;
    let reply = replies.recv().map_err(|_| AgentError::NoBridge(server.to_owned()))?;
    let sample = reply.result().map_err(|e| {
        AgentError::Zenoh(format!("{what}: the bridge said: {}", String::from_utf8_lossy(&e.payload().to_bytes())))
    })?;
    Ok(sample.payload().to_bytes().into_owned())
}

/// An episode host on another machine (`iwsim env-host` there): a learning environment
/// starts each episode there (a lock-step hub of its scenario, served by a bridge with
/// observers) and ends it.
pub struct EpisodeHost {
    z: zenoh::Session,
    prefix: String,
    endpoint: String,
}

impl std::fmt::Debug for EpisodeHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpisodeHost").field("endpoint", &self.endpoint).finish()
    }
}

/// How long an episode host may take to start or end an episode (it waits up to 20 s for a
/// hub to come up or to end).
const EPISODE_TIMEOUT: Duration = Duration::from_secs(30);

impl EpisodeHost {
    /// Opens a Zenoh session to the host at `remote`, waiting up to `timeout` for it.
    pub fn connect(remote: &Remote, timeout: Duration) -> Result<Self, AgentError> {
        let z = open_session(remote, timeout)?;
        let prefix = remote.prefix.clone().unwrap_or_else(|| wire::EPISODES_PREFIX.to_owned());
        Ok(Self { z, prefix, endpoint: remote.endpoint.clone() })
    }

    /// Starts an episode: a hub with `args` (scenario options only: `--ticks`, `--seed`,
    /// `--obstacle`, …; the host refuses others), its lab `lab_xml` when it is not a built-in
    /// one. Returns the session to join (with [`crate::Agent::connect_zenoh`] and an
    /// observer) at the same endpoint.
    pub fn start(&self, args: &[String], lab_xml: Option<Vec<u8>>) -> Result<String, AgentError> {
        let mut payload = String::new();
        for a in args {
            if a.contains('\n') {
                return Err(AgentError::Zenoh(format!("an episode option on two lines: {a:?}")));
            }
            payload.push_str(a);
            payload.push('\n');
        }
        let what = "start an episode";
        let key = wire::episode_start_key(&self.prefix);
        let answer = query(&self.z, &key, Some(payload.into_bytes()), lab_xml, EPISODE_TIMEOUT, what, &self.endpoint)
            .map_err(|e| self.no_host(e))?;
        String::from_utf8(answer).map_err(|_| AgentError::Zenoh("the episode host answered no session name".into()))
    }

    /// Ends the episode of `session` and returns its hub's end-of-run summary (its `--json`
    /// line; empty if it printed none).
    pub fn end(&self, session: &str) -> Result<String, AgentError> {
        let key = wire::episode_end_key(&self.prefix);
        let payload = Some(session.as_bytes().to_vec());
        let answer = query(&self.z, &key, payload, None, EPISODE_TIMEOUT, "end an episode", &self.endpoint)
            .map_err(|e| self.no_host(e))?;
        Ok(String::from_utf8_lossy(&answer).into_owned())
    }

    fn no_host(&self, e: AgentError) -> AgentError {
        match e {
            AgentError::NoBridge(_) => AgentError::Zenoh(format!(
                "no episode host answered at {} (is `iwsim env-host` running there?)",
                self.endpoint
            )),
            AgentError::Zenoh(m) => AgentError::Zenoh(m.replace("the bridge said", "the episode host said")),
            e => e,
        }
    }
}

/// Watches a bridge from a remote session: its liveliness token, whether the session is linked
/// at all, and the news its payloads bring. Agents and observers both use it.
pub struct BridgeWatch {
    tokens: Arc<Mutex<Tokens>>,
    /// Since when the session has had no transport at all.
    unlinked: std::cell::Cell<Option<Instant>>,
    /// When the last payload from the bridge came: set by the owner's subscriber.
    pub news: Arc<Mutex<Option<Instant>>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

/// What the bridge instances' liveliness tokens said.
#[derive(Debug, Default)]
struct Tokens {
    /// The instance this side knows (the first whose token it saw).
    known: Option<String>,
    /// Since when the known instance's token has been gone (`None`: it is there).
    down: Option<Instant>,
    /// Another instance's token, come since: the bridge was restarted.
    newer: Option<String>,
}

impl std::fmt::Debug for BridgeWatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BridgeWatch").field("tokens", &self.tokens).finish()
    }
}

impl BridgeWatch {
    /// Starts watching the bridge serving `prefix` (its instance's token, there now, is the
    /// one known).
    pub fn new(z: &zenoh::Session, prefix: &str) -> Result<Self, AgentError> {
        let tokens = Arc::new(Mutex::new(Tokens::default()));
        let t = tokens.clone();
        let subscriber = z
            .liveliness()
            .declare_subscriber(wire::all_bridges_key(prefix))
            .history(true)
            .callback(move |s: zenoh::sample::Sample| {
                let mut t = t.lock().unwrap_or_else(|p| p.into_inner());
                let key = s.key_expr().as_str();
                match s.kind() {
                    zenoh::sample::SampleKind::Put if t.known.is_none() => t.known = Some(key.to_owned()),
                    zenoh::sample::SampleKind::Put if t.known.as_deref() == Some(key) => t.down = None,
                    zenoh::sample::SampleKind::Put => t.newer = Some(key.to_owned()),
                    zenoh::sample::SampleKind::Delete if t.known.as_deref() == Some(key) => {
                        t.down = t.down.or(Some(Instant::now()));
                    }
                    zenoh::sample::SampleKind::Delete if t.newer.as_deref() == Some(key) => t.newer = None,
                    zenoh::sample::SampleKind::Delete => {}
                }
            })
            .wait()
            .map_err(zerr("watch the bridge"))?;
        Ok(Self {
            tokens,
            unlinked: std::cell::Cell::new(None),
            news: Arc::new(Mutex::new(None)),
            _subscriber: subscriber,
        })
    }

    /// Whether another run of the bridge has come up since the one this side knows (which
    /// has forgotten it): an agent says hello again ([`BridgeWatch::rejoined`] then).
    pub fn replaced(&self) -> bool {
        self.tokens.lock().unwrap_or_else(|p| p.into_inner()).newer.is_some()
    }

    /// The newer run of the bridge is now the one known.
    pub fn rejoined(&self) {
        let mut t = self.tokens.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(newer) = t.newer.take() {
            t.known = Some(newer);
            t.down = None;
        }
    }

    /// Whether the bridge is still there, or has been out of reach for less than
    /// [`BRIDGE_GRACE`]: its liveliness token (or a newer run's) is there, and `z` is connected
    /// to something (a client whose one peer or router went has no transport left, and no news
    /// of the token can reach it; Zenoh meanwhile tries to reconnect).
    pub fn alive(&self, z: &zenoh::Session) -> bool {
        let now = Instant::now();
        let info = z.info();
        let linked = info.peers_zid().wait().next().is_some() || info.routers_zid().wait().next().is_some();
        let unlinked = if linked { None } else { Some(self.unlinked.get().unwrap_or(now)) };
        self.unlinked.set(unlinked);
        let mut t = self.tokens.lock().unwrap_or_else(|p| p.into_inner());
        // A link Zenoh reopened may not bring the token's news again; the bridge's payloads
        // after it went are news enough.
        let last = *self.news.lock().unwrap_or_else(|p| p.into_inner());
        if t.down.is_some_and(|since| last.is_some_and(|l| l > since)) {
            t.down = None;
        }
        let down = if t.newer.is_some() { None } else { t.down };
        [unlinked, down].into_iter().flatten().all(|since| now.duration_since(since) < BRIDGE_GRACE)
    }
}

/// The sensor frames the link's subscriber received, and a socket it rings for each.
struct Inbox {
    frames: Mutex<VecDeque<Vec<u8>>>,
    ring: UnixStream,
    /// When the last frame came: proof the bridge is there, whatever its token said (shared
    /// with the link's [`BridgeWatch`]).
    last: Arc<Mutex<Option<Instant>>>,
}

impl Inbox {
    fn push(&self, bytes: Vec<u8>) {
        let mut q = self.frames.lock().unwrap_or_else(|p| p.into_inner());
        if q.len() >= INBOX_FRAMES {
            q.pop_front();
        }
        q.push_back(bytes);
        drop(q);
        *self.last.lock().unwrap_or_else(|p| p.into_inner()) = Some(Instant::now());
        // A full socket already rings; nothing is lost by a byte not written.
        let _ = (&self.ring).write(&[1]);
    }
}

/// A request sent over Zenoh whose answer has not been read yet.
pub struct PendingReply {
    replies: zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>,
}

impl std::fmt::Debug for PendingReply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PendingReply")
    }
}

/// An agent's Zenoh session with its hub's bridge.
pub(crate) struct ZenohLink {
    session: zenoh::Session,
    prefix: String,
    inbox: Arc<Inbox>,
    /// The read end of the inbox's ring.
    wake: UnixStream,
    sensors: Option<zenoh::pubsub::Subscriber<()>>,
    actions: Option<zenoh::pubsub::Publisher<'static>>,
    /// Held while the agent lives: the bridge sees it go when the agent's process or link does.
    _token: Option<zenoh::liveliness::LivelinessToken>,
    /// Whether the bridge is there.
    watch: BridgeWatch,
    /// The blocks of the tick in hand.
    pub(crate) held: Vec<SensorBlock>,
    /// The secret the bridge answered this agent's hello with: the attachment of every later
    /// request and actions payload, which proves they are this agent's.
    secret: std::cell::Cell<Option<[u8; wire::SECRET_LEN]>>,
    /// Each accepted robot's id and registration, in order: what a rejoin registers again.
    pub(crate) registrations: Vec<(u32, ipc_types::RobotRegistration)>,
}

impl ZenohLink {
    /// Opens a Zenoh session to `remote`, trying until `timeout` passes.
    pub(crate) fn open(remote: &Remote, session: &str, timeout: Duration) -> Result<Self, AgentError> {
        let z = open_session(remote, timeout)?;
        let prefix = remote.prefix.clone().unwrap_or_else(|| wire::prefix(session));
        let (wake, ring) = UnixStream::pair().map_err(|e| AgentError::Zenoh(format!("make a wake-up socket: {e}")))?;
        for s in [&wake, &ring] {
            s.set_nonblocking(true).map_err(|e| AgentError::Zenoh(format!("make a wake-up socket: {e}")))?;
        }
        let watch = BridgeWatch::new(&z, &prefix)?;
        Ok(Self {
            session: z,
            prefix,
            inbox: Arc::new(Inbox { frames: Mutex::new(VecDeque::new()), ring, last: watch.news.clone() }),
            wake,
            sensors: None,
            actions: None,
            _token: None,
            watch,
            held: Vec::new(),
            secret: std::cell::Cell::new(None),
            registrations: Vec::new(),
        })
    }

    /// After the bridge's welcome: subscribes to agent `id`'s sensor blocks, declares its
    /// actions publisher, and shows the bridge it is there.
    pub(crate) fn joined(&mut self, id: u32) -> Result<(), AgentError> {
        let inbox = self.inbox.clone();
        self.sensors = Some(
            self.session
                .declare_subscriber(wire::sensors_key(&self.prefix, id))
                .callback(move |s: zenoh::sample::Sample| inbox.push(s.payload().to_bytes().into_owned()))
                .wait()
                .map_err(zerr("subscribe to the sensor blocks"))?,
        );
        self.actions = Some(
            self.session
                .declare_publisher(wire::actions_key(&self.prefix, id))
                // One tick's actions go at once, not batched with the next.
                .express(true)
                // Never dropped (a put's default): a lock-step hub would step without them, and
                // the run would not be the run. A full queue holds this agent only, which
                // has nothing to do until its actions are out.
                .congestion_control(zenoh::qos::CongestionControl::Block)
                .wait()
                .map_err(zerr("declare the actions publisher"))?,
        );
        self._token = Some(
            self.session
                .liveliness()
                .declare_token(wire::alive_key(&self.prefix, id))
                .wait()
                .map_err(zerr("declare the agent's liveliness token"))?,
        );
        Ok(())
    }

    /// What a register request carries as its attachment: the layouts' names with a hello,
    /// the agent's secret with every later one.
    fn credentials(&self, req: &RegisterRequest) -> Vec<u8> {
        if req.kind == ipc_types::RegisterKind::Hello as u32 {
            wire::schema().into_bytes()
        } else {
            self.secret.get().map(|s| s.to_vec()).unwrap_or_default()
        }
    }

    /// Sends a register request; read the answer with [`ZenohLink::poll`].
    pub(crate) fn request(&self, req: &RegisterRequest) -> Result<PendingReply, AgentError> {
        let replies = self
            .session
            .get(wire::register_key(&self.prefix))
            .payload(bytemuck::bytes_of(req).to_vec())
            .attachment(self.credentials(req))
            // The bridge answers once the hub has (which may take up to ANSWER_TIMEOUT).
            .timeout(ANSWER_TIMEOUT + Duration::from_secs(1))
            .wait()
            .map_err(zerr("send a registration"))?;
        Ok(PendingReply { replies })
    }

    /// The answer to `pending`, if it came.
    pub(crate) fn poll(&self, pending: &PendingReply, session: &str) -> Result<Option<RegisterResponse>, AgentError> {
        match pending.replies.try_recv() {
            Ok(Some(reply)) => match reply.result() {
                Ok(sample) => {
                    // The welcome's secret, kept from the first answer that brings one.
                    if self.secret.get().is_none()
                        && let Some(a) = sample.attachment()
                        && let Ok(secret) = <[u8; wire::SECRET_LEN]>::try_from(a.to_bytes().as_ref())
                    {
                        self.secret.set(Some(secret));
                    }
                    wire::one::<RegisterResponse>(&sample.payload().to_bytes())
                        .map(Some)
                        .map_err(|error| AgentError::Frame { what: "registration answer", error })
                }
                Err(e) => Err(AgentError::Zenoh(format!(
                    "register: the bridge said: {}",
                    String::from_utf8_lossy(&e.payload().to_bytes())
                ))),
            },
            Ok(None) => Ok(None),
            // The query ended with no reply: no bridge serves the session's keys.
            Err(_) => Err(AgentError::NoBridge(session.to_owned())),
        }
    }

    /// Says goodbye without waiting for an answer.
    pub(crate) fn say_goodbye(&self, req: &RegisterRequest) {
        let _ = self
            .session
            .get(wire::register_key(&self.prefix))
            .payload(bytemuck::bytes_of(req).to_vec())
            .attachment(self.credentials(req))
            .callback(|_| {})
            .wait();
    }

    /// Sends actions.
    pub(crate) fn send(&self, header: &ActionHeader, actions: &[ActionBlock]) -> Result<(), AgentError> {
        let Some(p) = &self.actions else { return Err(AgentError::Zenoh("send actions before hello".into())) };
        let secret = self.secret.get().unwrap_or_default();
        p.put(wire::frame(header, actions)).attachment(secret.to_vec()).wait().map_err(zerr("send actions"))
    }

    /// The oldest sensor frame not read yet, checked; `None` when there is none.
    pub(crate) fn take(&mut self) -> Result<Option<(TickHeader, Vec<SensorBlock>)>, AgentError> {
        let mut drained = [0u8; 64];
        while matches!((&self.wake).read(&mut drained), Ok(n) if n > 0) {}
        let next = self.inbox.frames.lock().unwrap_or_else(|p| p.into_inner()).pop_front();
        let Some(bytes) = next else { return Ok(None) };
        let frame = |error: FrameError| AgentError::Frame { what: "sensor frame", error };
        let (h, blocks): (TickHeader, Vec<SensorBlock>) = wire::unframe(&bytes).map_err(frame)?;
        wire::check_count(h.count, blocks.len()).map_err(frame)?;
        Ok(Some((h, blocks)))
    }

    /// Readable when a sensor frame arrived.
    pub(crate) fn wake_fd(&self) -> i32 {
        self.wake.as_raw_fd()
    }

    /// Whether the bridge was restarted and has forgotten this agent.
    pub(crate) fn replaced(&self) -> bool {
        self.watch.replaced()
    }

    /// Leaves the bridge run that forgot this agent: its keys, its secret and its frames go,
    /// and the new run is the one watched. A hello to it follows.
    pub(crate) fn leave(&mut self) {
        self.sensors = None;
        self.actions = None;
        self._token = None;
        self.secret.set(None);
        self.inbox.frames.lock().unwrap_or_else(|p| p.into_inner()).clear();
        self.watch.rejoined();
    }

    /// Whether the bridge is still there (see [`BridgeWatch::alive`]).
    pub(crate) fn bridge_alive(&self) -> bool {
        self.watch.alive(&self.session)
    }

    /// The agents' map, from the bridge.
    pub(crate) fn map(&self, session: &str) -> Result<(MapHeader, Vec<MapItem>), AgentError> {
        let bytes = ask(&self.session, &wire::map_key(&self.prefix), None, "get the map", session)?;
        let frame = |error: FrameError| AgentError::Frame { what: "map", error };
        let (h, items): (MapHeader, Vec<MapItem>) = wire::unframe(&bytes).map_err(frame)?;
        wire::check_count(h.item_count, items.len()).map_err(frame)?;
        Ok((h, items))
    }
}
