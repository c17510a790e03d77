//! The viewer process: reads the world from the hub over shared memory (read-only) and serves
//! a page plus a WebSocket stream of frames to any number of browsers.
//!
//! The iceoryx2 ports are not `Send`, so the main thread reads the hub and publishes the newest
//! frame in a shared slot; each browser connection runs on a thread of its own and sends the
//! newest frame at most [`MAX_FPS`] times a second, whatever the tick rate.
//!
//! Physical chairs (mixed reality) come on the observers' `observer/chairs` service: their
//! sensor modes, real and virtual readings and a test bench's true pose travel in the frame of
//! the world they belong to, so a page draws both from one message. A session without chairs
//! (or a served replay, which has no such service) sends frames with none.
//!
//! What one browser (or a hostile page) can cost everyone is bounded: at most
//! [`MAX_CONNECTIONS`] connections at once, [`IO_TIMEOUT`] on every read and on every whole
//! message written, at most [`MAX_UNACKED_BYTES`] sent to a page that it has not acknowledged
//! (a page that never reads is dropped after [`IO_TIMEOUT`]), [`MAX_MESSAGE_BYTES`] per incoming
//! WebSocket message, a WebSocket only from the viewer's own origin (or one named with
//! `--allow-origin`), and one control client for every page's commands.
//!
//! Every request must also be addressed to a name the viewer is served under (its `Host`
//! header; see `host_allowed` for which): an origin check alone is beaten by DNS rebinding, where a
//! site's own name is made to resolve to this machine, and its page's requests then carry
//! that name as both `Host` and `Origin`.

use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use agent_sdk::{AgentError, ControlClient};
use ipc_types::{ChairState, Command, ControlResponse, RunState};
use observer::Observer;
use tungstenite::Message;
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::protocol::WebSocketConfig;

use crate::frame;

/// At most this many frames per second go to a page.
pub const MAX_FPS: u32 = 60;

/// Connections served at once (pages, WebSockets and file requests together); one more is
/// answered `503 Service Unavailable` and closed. Each costs a thread and its buffers.
pub const MAX_CONNECTIONS: usize = 64;

/// The largest WebSocket message (and frame) a page may send; a page's commands are a few
/// bytes, and a larger message closes its connection.
pub const MAX_MESSAGE_BYTES: usize = 4096;

/// How long one read on a connection may block, how long the socket may take to accept one
/// whole message, and how long a page may leave what it was sent unacknowledged: a client that
/// stops reading is dropped after this, so it cannot pin a thread, a slot and kernel buffers
/// for good.
pub const IO_TIMEOUT: Duration = Duration::from_secs(5);

/// The most a page may have been sent without acknowledging it (a WebSocket ping follows every
/// message; its pong says the page has read up to there). A frame that would go beyond this
/// is skipped (the page gets a newer one once it catches up: a view only needs the newest
/// world); a frame goes whatever its size when nothing is outstanding. Without this bound the
/// kernel buffers up to `tcp_wmem`'s maximum (4 MB by default) for every page that does not
/// read, before a single write blocks.
pub const MAX_UNACKED_BYTES: usize = 256 * 1024;

/// Page commands waiting for the control client; more are answered "busy".
const CONTROL_QUEUE: usize = 16;

/// The page's files, built into the binary so `iwsim view` needs nothing beside it.
const STATIC_FILES: &[(&str, &str, &str)] = &[
    ("/", "text/html; charset=utf-8", include_str!("../static/index.html")),
    ("/index.html", "text/html; charset=utf-8", include_str!("../static/index.html")),
    ("/app.js", "text/javascript; charset=utf-8", include_str!("../static/app.js")),
    ("/view3d.js", "text/javascript; charset=utf-8", include_str!("../static/view3d.js")),
    ("/three.module.min.js", "text/javascript; charset=utf-8", include_str!("../static/three.module.min.js")),
    ("/three.core.min.js", "text/javascript; charset=utf-8", include_str!("../static/three.core.min.js")),
    ("/three-LICENSE.txt", "text/plain; charset=utf-8", include_str!("../static/three-LICENSE.txt")),
];

/// How to run the viewer.
#[derive(Debug, Clone)]
pub struct ViewerConfig {
    /// The hub's session.
    pub session: String,
    /// Where to serve HTTP (loopback unless the LAN is wanted).
    pub http: SocketAddr,
    /// Whether pages may send run-control commands.
    pub allow_control: bool,
    /// WebSocket origins accepted besides the viewer's own (`http://` + the `Host` it is
    /// served as), e.g. `http://lab-pc:8080`.
    pub allowed_origins: Vec<String>,
    /// Host names requests may be addressed to besides the address the viewer is served at
    /// (and `localhost` on loopback), e.g. `lab-pc` (any port) or `lab-pc:8080`: the names a
    /// user opens the page under on a LAN; `--allow-host` on the command line.
    pub allowed_hosts: Vec<String>,
    /// How long to wait for the hub.
    pub connect_timeout: Duration,
    /// The hub's Zenoh bridge, when the hub is on another machine (the bridge must serve
    /// observers: `iwsim zenoh --observers world`).
    pub remote: Option<agent_sdk::remote::Remote>,
}

/// Why the viewer stopped.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The hub could not be reached.
    #[error(transparent)]
    Hub(#[from] AgentError),
    /// Run control asked of a viewer on another machine.
    #[error("--allow-control needs the hub's machine: a viewer through --zenoh only shows the run")]
    RemoteControl,
    /// The HTTP port could not be bound.
    #[error("cannot serve HTTP on {addr}: {source}")]
    Bind {
        /// Address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The thread that sends the pages' commands could not start.
    #[error("cannot start the control thread: {0}")]
    Thread(std::io::Error),
}

#[derive(Debug, Default)]
struct Latest {
    frame: Arc<Vec<u8>>,
    frame_seq: u64,
    roster: Arc<String>,
    roster_seq: u64,
    finished: bool,
}

type Shared = Arc<(Mutex<Latest>, Condvar)>;

/// What every connection's thread shares.
#[derive(Debug)]
struct Context {
    shared: Shared,
    map_json: Arc<String>,
    allowed_origins: Vec<String>,
    /// The address the viewer listens on (with its real port when bound to port 0).
    served_at: SocketAddr,
    allowed_hosts: Vec<String>,
    /// Requests for other hosts, reported at a bounded rate.
    refused_hosts: Mutex<Throttle>,
    /// The control thread's queue, when pages may control the run.
    control: Option<SyncSender<ControlJob>>,
    /// Refused origins, reported at a bounded rate.
    refused_origins: Mutex<Throttle>,
}

/// Counts events and says when one may be reported: at most once a second, so a flood of
/// refused clients cannot flood stderr.
#[derive(Debug, Default)]
struct Throttle {
    last: Option<Instant>,
    count: u64,
}

impl Throttle {
    /// Counts one event; returns the count so far when it may be reported now.
    fn note(&mut self, now: Instant) -> Option<u64> {
        self.count += 1;
        let due = self.last.is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1));
        due.then(|| {
            self.last = Some(now);
            self.count
        })
    }
}

/// Frees a connection's slot when its thread ends, however it ends.
#[derive(Debug)]
struct Slot(Arc<AtomicUsize>);

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// One page command for the control thread, and where its answer goes.
#[derive(Debug)]
struct ControlJob {
    command: Command,
    robot_id: u32,
    reply: mpsc::Sender<Result<ControlResponse, String>>,
}

/// The one control client of the viewer, on a thread of its own (iceoryx2 ports are not
/// `Send`): pages queue commands and it sends them one at a time. Dropping it ends the
/// thread and closes the client's node, before the viewer's own node is closed.
#[derive(Debug)]
struct ControlThread {
    jobs: SyncSender<ControlJob>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl ControlThread {
    fn spawn(session: String) -> std::io::Result<Self> {
        let (jobs, rx) = mpsc::sync_channel(CONTROL_QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let handle = std::thread::Builder::new()
            .name("viewer-control".into())
            .spawn(move || serve_control(&session, &rx, &flag))?;
        Ok(Self { jobs, stop, handle: Some(handle) })
    }
}

impl Drop for ControlThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// The control thread: connects on the first command (and again after a failure, so a
/// hiccup is not for good), then answers each job with the hub's answer.
fn serve_control(session: &str, jobs: &Receiver<ControlJob>, stop: &AtomicBool) {
    let mut client: Option<ControlClient> = None;
    while !stop.load(Ordering::SeqCst) {
        let job = match jobs.recv_timeout(Duration::from_millis(100)) {
            Ok(job) => job,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        let answer = match client.as_mut() {
            Some(c) => c.ask(job.command, job.robot_id),
            None => ControlClient::connect(session).and_then(|c| client.insert(c).ask(job.command, job.robot_id)),
        };
        if answer.is_err() {
            client = None;
        }
        let _ = job.reply.send(answer.map_err(|e| e.to_string()));
    }
}

/// Whether a WebSocket handshake may proceed: browsers always send `Origin` on one, so a
/// request without it is no page's (a script on this machine, which could send anything);
/// with it, it must be the viewer's own origin (`http://` + the `Host` asked for) or one of
/// `allowed`. Hosts compare without case, as DNS does.
fn origin_allowed(origin: Option<&str>, host: Option<&str>, allowed: &[String]) -> bool {
    let Some(origin) = origin else { return true };
    let origin = origin.trim().trim_end_matches('/');
    if allowed.iter().any(|a| a.trim().trim_end_matches('/').eq_ignore_ascii_case(origin)) {
        return true;
    }
    host.and_then(|h| Some(origin.strip_prefix("http://")?.eq_ignore_ascii_case(h.trim()))).unwrap_or(false)
}

/// A `Host` header's name: an IP literal (an IPv6 one in brackets) or a DNS name.
#[derive(Debug)]
enum HostName<'a> {
    Ip(IpAddr),
    Dns(&'a str),
}

impl HostName<'_> {
    fn same(&self, other: &HostName<'_>) -> bool {
        match (self, other) {
            (HostName::Ip(a), HostName::Ip(b)) => a.to_canonical() == b.to_canonical(),
            // DNS names compare without case, and a fully qualified `name.` is `name`.
            (HostName::Dns(a), HostName::Dns(b)) => {
                a.trim_end_matches('.').eq_ignore_ascii_case(b.trim_end_matches('.'))
            }
            _ => false,
        }
    }
}

/// Splits a `Host` header (or an `--allow-host` entry) into its name and its port, if it
/// has one: `name`, `name:port`, `[v6]`, `[v6]:port`. `None` when it is none of these.
fn split_host(host: &str) -> Option<(HostName<'_>, Option<u16>)> {
    let host = host.trim();
    let (name, port) = match host.strip_prefix('[') {
        Some(rest) => {
            let (inside, after) = rest.split_once(']')?;
            let port = if after.is_empty() { None } else { Some(after.strip_prefix(':')?) };
            (HostName::Ip(IpAddr::V6(inside.parse().ok()?)), port)
        }
        None => {
            let (name, port) = host.split_once(':').map_or((host, None), |(n, p)| (n, Some(p)));
            let valid = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '.' | '_');
            if name.is_empty() || !name.chars().all(valid) {
                return None;
            }
            (name.parse().map_or(HostName::Dns(name), HostName::Ip), port)
        }
    };
    let port = match port {
        Some(p) => Some(p.parse().ok()?),
        None => None,
    };
    Some((name, port))
}

/// Whether a request addressed to `host` (its `Host` header) is for this viewer, which
/// listens on `served_at` and got the request on its address `arrived_at`. DNS rebinding
/// makes a site's name resolve to this machine; its page's requests then name that site as
/// both `Host` and `Origin`, so only the `Host` tells them apart. Served are:
/// - an IP literal, with the port the viewer listens on, for the address the request
///   arrived at (the bound address, or any of this machine's when bound to `0.0.0.0`/`[::]`):
///   an IP cannot be rebound;
/// - `localhost`, `127.0.0.1` and `[::1]` with that port, when the request came over
///   loopback (browsers resolve `localhost` themselves);
/// - whatever `allowed` names (`--allow-host`): `name` for any port, `name:port` for that
///   one.
///
/// A request without `Host` is served: every browser sends one, so it is no web page's (an
/// HTTP/1.0 program's, say), and a program could send any `Host` it liked. The port is 80
/// when the header gives none, as HTTP says.
fn host_allowed(host: Option<&str>, served_at: SocketAddr, arrived_at: IpAddr, allowed: &[String]) -> bool {
    let Some(host) = host else { return true };
    let Some((name, port)) = split_host(host) else { return false };
    let port = port.unwrap_or(80);
    let allowed_by_user = allowed
        .iter()
        .filter_map(|a| split_host(a))
        .any(|(a_name, a_port)| a_name.same(&name) && a_port.is_none_or(|p| p == port));
    if allowed_by_user {
        return true;
    }
    if port != served_at.port() {
        return false;
    }
    let loopback = arrived_at.to_canonical().is_loopback();
    match name {
        HostName::Ip(ip) => {
            let ip = ip.to_canonical();
            ip == arrived_at.to_canonical()
                || (loopback && (ip == IpAddr::from([127, 0, 0, 1]) || ip == IpAddr::from([0u16, 0, 0, 0, 0, 0, 0, 1])))
        }
        HostName::Dns(_) => loopback && name.same(&HostName::Dns("localhost")),
    }
}

/// Checks an `--allow-host` value: a host name or IP address, with `:PORT` or without.
pub fn allowed_host(value: &str) -> Result<String, String> {
    match split_host(value) {
        Some(_) => Ok(value.trim().to_owned()),
        None => Err(format!(
            "{value:?} is no host: give a name or address, with :PORT or without (lab-pc, lab-pc:8080, [::1]:8080), not a URL"
        )),
    }
}

/// Where the page may be opened, for a refusal's advice.
fn own_url(served_at: SocketAddr) -> String {
    if served_at.ip().is_unspecified() {
        format!("http://<this machine's address>:{}/", served_at.port())
    } else {
        format!("http://{served_at}/")
    }
}

/// What a request for a host the viewer is not served under is told.
fn misdirected_text(host: &str, served_at: SocketAddr) -> String {
    format!(
        "this viewer is not served as host {host:?}: open {}, or start iwsim view with --allow-host {}\n",
        own_url(served_at),
        host.trim()
    )
}

impl Context {
    /// Reports a request for another host, at a bounded rate.
    fn note_refused_host(&self, host: &str) {
        let mut refused = self.refused_hosts.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = refused.note(Instant::now()) {
            agent_sdk::report!(
                "iwsim view: refused a request for host {host:?} ({n} so far): the viewer is served at {}; allow a name with --allow-host",
                own_url(self.served_at)
            );
        }
    }
}

/// A bound viewer, before it serves.
#[derive(Debug)]
pub struct Viewer {
    cfg: ViewerConfig,
    observer: Observer,
    listener: TcpListener,
    map_json: Arc<String>,
}

impl Viewer {
    /// Attaches to the hub and binds the HTTP port.
    pub fn start(cfg: ViewerConfig) -> Result<Self, ViewerError> {
        let observer = match &cfg.remote {
            // Run control goes to the hub's own services, which only its machine reaches.
            Some(_) if cfg.allow_control => return Err(ViewerError::RemoteControl),
            Some(remote) => Observer::connect_zenoh(remote, &cfg.session, cfg.connect_timeout)?,
            None => {
                Observer::connect_within(&cfg.session, &format!("viewer-{}", std::process::id()), cfg.connect_timeout)?
            }
        };
        let map_json = Arc::new(frame::map_json(&observer.map()?));
        let listener = TcpListener::bind(cfg.http).map_err(|source| ViewerError::Bind { addr: cfg.http, source })?;
        Ok(Self { cfg, observer, listener, map_json })
    }

    /// The address pages are served on.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.listener.local_addr().ok()
    }

    /// Serves until the hub ends the run, or SIGINT/SIGTERM arrives (both `Ok`), or the hub's
    /// process goes away without ending it (`ViewerError::Hub` with `AgentError::HubGone`):
    /// then the viewer leaves at once, so its ports do not keep a restarted hub of the same
    /// session from creating its services.
    pub fn run(mut self) -> Result<(), ViewerError> {
        let shared: Shared = Arc::new((Mutex::new(Latest::default()), Condvar::new()));
        // Declared before anything that can fail: dropped first on every way out, so its
        // node is gone before the observer's.
        let control = if self.cfg.allow_control {
            Some(ControlThread::spawn(self.cfg.session.clone()).map_err(ViewerError::Thread)?)
        } else {
            None
        };
        let ctx = Arc::new(Context {
            shared: shared.clone(),
            map_json: self.map_json.clone(),
            allowed_origins: self.cfg.allowed_origins.clone(),
            served_at: self.listener.local_addr().unwrap_or(self.cfg.http),
            allowed_hosts: self.cfg.allowed_hosts.clone(),
            refused_hosts: Mutex::new(Throttle::default()),
            control: control.as_ref().map(|c| c.jobs.clone()),
            refused_origins: Mutex::new(Throttle::default()),
        });
        let listener = self.listener;
        std::thread::spawn(move || accept_connections(&listener, &ctx));
        let mut ids: Vec<u32> = Vec::new();
        let mut sensors: Vec<ipc_types::RobotInfo> = Vec::new();
        let mut roster_dirty = false;
        let mut chairs: Option<(u64, Vec<ChairState>)> = None;
        let mut chair_poll = ChairPoll::default();
        loop {
            // The hub republishes sensor geometry when robots come or go; it may land apart
            // from the snapshot that shows them, so either change re-sends the roster.
            if self.observer.refresh_robot_info()? {
                sensors = self.observer.robot_infos().to_vec();
                roster_dirty = true;
            }
            // Read where the hub wrote it: only the roster, when the robots changed, is made
            // from it here; the frame below is encoded from the same held snapshot.
            let new_world = self.observer.try_with_world(|_, robots| {
                let changed = roster_dirty || !ids.iter().copied().eq(robots.iter().map(|r| r.id));
                if changed {
                    ids.clear();
                    ids.extend(robots.iter().map(|r| r.id));
                }
                changed.then(|| frame::roster_json(robots, &sensors))
            })?;
            let new_chairs = chair_poll.poll(&mut self.observer, Instant::now())?;
            if new_world.is_none() && new_chairs.is_none() {
                // The world arrives once per tick; checking 100 times a second is plenty
                // for a display that shows at most 60. A silent hub may be a paused one or a
                // dead one: only its process can tell.
                match self.observer.check_alive() {
                    Ok(()) => std::thread::sleep(Duration::from_millis(10)),
                    Err(AgentError::Interrupted) => return Ok(()),
                    Err(e) => return Err(e.into()),
                }
                continue;
            }
            if new_chairs.is_some() {
                chairs = new_chairs;
            }
            if new_world.is_some() {
                roster_dirty = false;
            }
            let roster = new_world.flatten();
            // Chair states alone (they land just after their tick's world) re-send the
            // newest world with them, so a page never waits a tick to see them.
            let Some((bytes, finished)) = self.observer.with_last_world(|h, robots| {
                let bytes = frame::encode_with_chairs(h, robots, &frame::chairs_for(h.tick, robots, chairs.as_ref()));
                (bytes, h.run_state == RunState::Finished as u32)
            }) else {
                continue;
            };
            let (lock, cv) = &*shared;
            let mut l = lock.lock().unwrap_or_else(|p| p.into_inner());
            l.frame = Arc::new(bytes);
            l.frame_seq += 1;
            if let Some(r) = roster {
                l.roster = Arc::new(r);
                l.roster_seq += 1;
            }
            l.finished = finished;
            cv.notify_all();
            drop(l);
            if finished {
                // Let the pages draw the last frame, then leave no file behind.
                std::thread::sleep(Duration::from_millis(200));
                drop(control);
                self.observer.close();
                return Ok(());
            }
        }
    }
}

/// Reads the physical chairs' states. Until the first sample arrives it looks at most once a
/// second: a served replay has no chair service, and each look for one costs the observer an
/// attempt to open it; a live hub without chairs costs a look a second. Once chairs have been
/// seen, it reads at every turn of the loop, as the world is read.
#[derive(Debug, Default)]
struct ChairPoll {
    seen: bool,
    next_look: Option<Instant>,
}

impl ChairPoll {
    /// How long to wait between looks while no chair has been seen.
    const IDLE_LOOK: Duration = Duration::from_secs(1);

    fn poll(&mut self, observer: &mut Observer, now: Instant) -> Result<Option<(u64, Vec<ChairState>)>, AgentError> {
        if !self.due(now) {
            return Ok(None);
        }
        let got = observer.try_chairs()?;
        self.saw(got.is_some(), now);
        Ok(got)
    }

    /// Whether to look now.
    fn due(&self, now: Instant) -> bool {
        self.seen || self.next_look.is_none_or(|t| now >= t)
    }

    /// Notes what a look found.
    fn saw(&mut self, found: bool, now: Instant) {
        self.seen |= found;
        if !self.seen {
            self.next_look = Some(now + Self::IDLE_LOOK);
        }
    }
}

/// Accepts connections for good, each on a thread of its own, at most [`MAX_CONNECTIONS`] at
/// once; beyond that a connection is answered 503 and closed at once.
fn accept_connections(listener: &TcpListener, ctx: &Arc<Context>) {
    let live = Arc::new(AtomicUsize::new(0));
    let mut refused = Throttle::default();
    for stream in listener.incoming().flatten() {
        if live.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
            live.fetch_sub(1, Ordering::SeqCst);
            if let Some(n) = refused.note(Instant::now()) {
                agent_sdk::report!(
                    "iwsim view: refused a connection: at most {MAX_CONNECTIONS} at once ({n} refused so far)"
                );
            }
            refuse_busy(stream);
            continue;
        }
        let slot = Slot(live.clone());
        let ctx = ctx.clone();
        let spawned = std::thread::Builder::new().name("viewer-connection".into()).spawn(move || {
            let _slot = slot;
            if let Err(e) = serve_connection(stream, &ctx) {
                tracing::debug!("viewer connection: {e}");
            }
        });
        // Out of threads: the stream and its slot went with the closure.
        if let Err(e) = spawned {
            tracing::debug!("viewer connection: no thread: {e}");
        }
    }
}

/// Answers a connection over the cap without serving it. The accept loop must not wait on
/// it: whatever request already arrived is read without blocking (closing a socket with
/// unread data would reset it and lose the answer), and the write is short and bounded.
fn refuse_busy(mut stream: TcpStream) {
    let body = format!("the viewer serves at most {MAX_CONNECTIONS} connections at once; try again later\n");
    let _ = stream.set_nonblocking(true);
    let mut sink = [0u8; 4096];
    let _ = stream.read(&mut sink);
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
    let _ = write!(
        stream,
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = stream.shutdown(std::net::Shutdown::Write);
}

fn serve_connection(mut stream: TcpStream, ctx: &Context) -> std::io::Result<()> {
    stream.set_read_timeout(Some(IO_TIMEOUT))?;
    stream.set_write_timeout(Some(IO_TIMEOUT))?;
    // Route on the request line without consuming it (a WebSocket handshake must reach
    // tungstenite whole); it may arrive in pieces, so peek until the head is complete.
    let mut peek = [0u8; 2048];
    let mut n = stream.peek(&mut peek)?;
    let until = Instant::now() + Duration::from_secs(2);
    while !peek[..n].windows(4).any(|w| w == b"\r\n\r\n") && n < peek.len() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(1));
        n = stream.peek(&mut peek)?;
    }
    let head = String::from_utf8_lossy(&peek[..n]);
    let path = head.split_whitespace().nth(1).unwrap_or("/").to_owned();
    let arrived_at = stream.local_addr()?.ip();
    if path == "/ws" {
        // tungstenite reads the whole head: the Host is checked there.
        return serve_websocket(stream, ctx, arrived_at);
    }
    // Consume the request (up to the blank line) before answering.
    let mut req = Vec::new();
    let mut buf = [0u8; 1024];
    let ended = |req: &[u8]| req.windows(4).any(|w| w == b"\r\n\r\n");
    while !ended(&req) && req.len() < MAX_HEAD_BYTES {
        let n = stream.read(&mut buf)?;
        if n == 0 {
            break;
        }
        req.extend_from_slice(&buf[..n]);
    }
    // A head that does not end could hide its Host past what was read.
    if !ended(&req) {
        return answer(&mut stream, "431 Request Header Fields Too Large", "text/plain", "request head too long\n");
    }
    let req = String::from_utf8_lossy(&req);
    let host = header(&req, "host");
    if !host_allowed(host, ctx.served_at, arrived_at, &ctx.allowed_hosts) {
        let host = host.unwrap_or_default();
        ctx.note_refused_host(host);
        return answer(
            &mut stream,
            "421 Misdirected Request",
            "text/plain; charset=utf-8",
            &misdirected_text(host, ctx.served_at),
        );
    }
    // The query string only tunes the page (view, camera, chair); the file is the path.
    let file = path.split('?').next().unwrap_or("/");
    let (status, ctype, body) = match STATIC_FILES.iter().find(|(p, _, _)| *p == file) {
        Some((_, ctype, body)) => ("200 OK", *ctype, *body),
        None => ("404 Not Found", "text/plain", "not found\n"),
    };
    answer(&mut stream, status, ctype, body)
}

/// The most of a plain HTTP request's head the viewer reads; a longer one is refused.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// The first header `name` (without case) in a request head.
fn header<'a>(head: &'a str, name: &str) -> Option<&'a str> {
    head.split("\r\n").skip(1).take_while(|l| !l.is_empty()).find_map(|l| {
        let (n, v) = l.split_once(':')?;
        n.trim().eq_ignore_ascii_case(name).then(|| v.trim())
    })
}

/// Writes a whole plain HTTP answer; the connection closes after it.
fn answer(stream: &mut TcpStream, status: &str, ctype: &str, body: &str) -> std::io::Result<()> {
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body.as_bytes())
}

/// A connection's socket whose writes share one deadline, so that a whole message must be
/// taken within [`IO_TIMEOUT`]. The socket's own send timeout counts per write call: a call
/// that copied part of a message before timing out returns that part, and the WebSocket layer's
/// next call for the rest waits a full timeout again, so a page that takes a trickle (or whose
/// kernel frees a little room now and then) was never dropped.
#[derive(Debug)]
struct DeadlineStream {
    stream: TcpStream,
    deadline: Option<Instant>,
    /// A write ran into the deadline: the page is dropped, whatever the WebSocket layer makes
    /// of the error (it takes a blocked write while it reads for "try again later").
    expired: bool,
}

impl DeadlineStream {
    fn new(stream: TcpStream) -> Self {
        Self { stream, deadline: None, expired: false }
    }

    /// Gives the next whole message (however many writes it takes) until `within` from now.
    fn arm(&mut self, within: Duration) {
        self.deadline = Some(Instant::now() + within);
    }
}

impl Read for DeadlineStream {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.stream.read(buf)
    }
}

impl Write for DeadlineStream {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Some(deadline) = self.deadline {
            let left = deadline.saturating_duration_since(Instant::now());
            // The socket takes no zero timeout (it would mean none); under a millisecond left
            // is as good as none.
            if left < Duration::from_millis(1) {
                self.expired = true;
                return Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    "the page took no whole message in time",
                ));
            }
            self.stream.set_write_timeout(Some(left))?;
        }
        let written = self.stream.write(buf);
        if let Err(e) = &written
            && matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut)
        {
            self.expired = true;
        }
        written
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.stream.flush()
    }
}

/// What a page has been sent and has acknowledged, counted in bytes of messages: a ping after
/// each message carries the count so far, and the page's pong echoes it (browsers answer pings
/// by themselves, whatever the page's script is doing).
#[derive(Debug, Default)]
struct Pace {
    sent: u64,
    acked: u64,
    /// Since when the page has owed an acknowledgement without giving any.
    owed_since: Option<Instant>,
}

impl Pace {
    /// Whether a frame of `len` bytes may go now: when nothing is outstanding (so a frame
    /// larger than the bound still goes, one at a time), or when it stays within
    /// [`MAX_UNACKED_BYTES`].
    fn may_send(&self, len: usize) -> bool {
        let outstanding = self.sent - self.acked;
        outstanding == 0 || outstanding + len as u64 <= MAX_UNACKED_BYTES as u64
    }

    /// Counts a message of `len` bytes sent at `now`; returns the ping payload that follows it.
    fn sent(&mut self, len: usize, now: Instant) -> [u8; 8] {
        if self.sent == self.acked {
            self.owed_since = Some(now);
        }
        self.sent += len as u64;
        self.sent.to_be_bytes()
    }

    /// Counts a pong that arrived at `now`. One that acknowledges nothing new (a page may send
    /// pongs of its own as a heartbeat, with any payload) changes nothing.
    fn pong(&mut self, payload: &[u8], now: Instant) {
        let Ok(bytes) = <[u8; 8]>::try_from(payload) else { return };
        let upto = u64::from_be_bytes(bytes);
        if upto > self.acked && upto <= self.sent {
            self.acked = upto;
            self.owed_since = (self.acked < self.sent).then_some(now);
        }
    }

    /// Whether the page has acknowledged nothing for [`IO_TIMEOUT`] while it owed some.
    fn stalled(&self, now: Instant) -> bool {
        self.owed_since.is_some_and(|t| now.duration_since(t) >= IO_TIMEOUT)
    }
}

/// Messages read from a page per turn of its loop: enough to take the pongs of every message
/// sent since the last turn, few enough that a page flooding the viewer cannot keep its own
/// stream from being served.
const READS_PER_TURN: usize = 32;

/// A page's command: `start`, `pause`, `step`, `stop` or `remove:<robot id>` (public for the
/// fuzz target, which feeds it whatever a WebSocket can carry).
pub fn parse_command(text: &str) -> Option<(Command, u32)> {
    match text {
        "start" => Some((Command::Start, 0)),
        "pause" => Some((Command::Pause, 0)),
        "step" => Some((Command::Step, 0)),
        "stop" => Some((Command::Stop, 0)),
        _ => Some((Command::RemoveRobot, text.strip_prefix("remove:")?.parse().ok()?)),
    }
}

/// The WebSocket limits every page connection is read with: messages and frames of at most
/// [`MAX_MESSAGE_BYTES`] (public for the fuzz target, which reads junk streams with them).
pub fn websocket_config() -> WebSocketConfig {
    WebSocketConfig::default()
        .read_buffer_size(MAX_MESSAGE_BYTES * 2)
        .max_message_size(Some(MAX_MESSAGE_BYTES))
        .max_frame_size(Some(MAX_MESSAGE_BYTES))
}

/// The answer to a handshake from an origin that is not allowed.
fn forbidden(origin: &str) -> ErrorResponse {
    let mut r = ErrorResponse::new(Some(format!(
        "origin {origin} may not connect: open the page from this viewer, or start iwsim view with --allow-origin {origin}\n"
    )));
    *r.status_mut() = tungstenite::http::StatusCode::FORBIDDEN;
    r
}

/// The answer to a handshake addressed to a host the viewer is not served under.
fn misdirected(host: &str, served_at: SocketAddr) -> ErrorResponse {
    let mut r = ErrorResponse::new(Some(misdirected_text(host, served_at)));
    *r.status_mut() = tungstenite::http::StatusCode::MISDIRECTED_REQUEST;
    r
}

fn serve_websocket(stream: TcpStream, ctx: &Context, arrived_at: IpAddr) -> std::io::Result<()> {
    let config = websocket_config();
    // The error type is tungstenite's handshake callback's, not ours to shrink.
    #[allow(clippy::result_large_err)]
    let check = |req: &Request, resp: Response| -> Result<Response, ErrorResponse> {
        let header = |name: &str| req.headers().get(name).map(|v| v.to_str().unwrap_or("\u{fffd}"));
        let host = header("host");
        if !host_allowed(host, ctx.served_at, arrived_at, &ctx.allowed_hosts) {
            let host = host.unwrap_or_default();
            ctx.note_refused_host(host);
            return Err(misdirected(host, ctx.served_at));
        }
        let origin = header("origin");
        if origin_allowed(origin, header("host"), &ctx.allowed_origins) {
            return Ok(resp);
        }
        let origin = origin.unwrap_or_default();
        let mut refused = ctx.refused_origins.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = refused.note(Instant::now()) {
            agent_sdk::report!(
                "iwsim view: refused a WebSocket from origin {origin:?} ({n} so far); allow it with --allow-origin"
            );
        }
        Err(forbidden(origin))
    };
    let ws = tungstenite::accept_hdr_with_config(DeadlineStream::new(stream), check, Some(config))
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    let mut page = Page { ws, pace: Pace::default() };
    page.send(Message::text(ctx.map_json.as_str().to_owned()))?;
    // Reads must not block the frame stream: poll them with a short timeout.
    page.ws.get_mut().stream.set_read_timeout(Some(Duration::from_millis(5)))?;
    let shared = &ctx.shared;
    let (mut frame_seq, mut roster_seq) = (0u64, 0u64);
    let min_gap = Duration::from_millis(1000 / MAX_FPS as u64);
    let mut last_sent = Instant::now() - min_gap;
    loop {
        let (frame, roster, finished) = {
            let (lock, cv) = &**shared;
            let mut l = lock.lock().unwrap_or_else(|p| p.into_inner());
            if l.frame_seq == frame_seq {
                l = cv.wait_timeout(l, Duration::from_millis(200)).unwrap_or_else(|p| p.into_inner()).0;
            }
            let roster = (l.roster_seq != roster_seq).then(|| (l.roster.clone(), l.roster_seq));
            let frame = (l.frame_seq != frame_seq).then(|| (l.frame.clone(), l.frame_seq));
            (frame, roster, l.finished)
        };
        // The roster is state the page cannot do without: it goes whatever the page owes.
        if let Some((r, seq)) = roster {
            page.send(Message::text(r.as_str().to_owned()))?;
            roster_seq = seq;
        }
        // A frame the page has no room for is skipped; a newer one goes once it catches up.
        if let Some((f, seq)) = frame
            && last_sent.elapsed() >= min_gap
            && page.pace.may_send(f.len())
        {
            page.send(Message::binary(f.as_slice().to_vec()))?;
            frame_seq = seq;
            last_sent = Instant::now();
        }
        for _ in 0..READS_PER_TURN {
            match page.read()? {
                Some(Message::Text(cmd)) => {
                    let reply = match (parse_command(cmd.as_str()), &ctx.control) {
                        (Some((c, robot)), Some(control)) => command_reply(control, cmd.as_str(), c, robot),
                        (Some(_), None) => {
                            "{\"type\":\"error\",\"message\":\"control is off: start iwsim view with --allow-control\"}"
                                .to_owned()
                        }
                        (None, _) => "{\"type\":\"error\",\"message\":\"unknown command\"}".to_owned(),
                    };
                    page.send(Message::text(reply))?;
                }
                Some(Message::Pong(p)) => page.pace.pong(&p, Instant::now()),
                Some(Message::Close(_)) => return Ok(()),
                Some(_) => {}
                None => break,
            }
        }
        // Judged after the page's pongs have been read, so a turn that waited on the hub
        // (a command's answer) does not count against it.
        if page.pace.stalled(Instant::now()) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                format!("the page acknowledged nothing for {IO_TIMEOUT:?}"),
            ));
        }
        if finished && frame_seq > 0 {
            page.ws.get_mut().arm(IO_TIMEOUT);
            let _ = page.ws.close(None);
            return Ok(());
        }
    }
}

/// One page's WebSocket and what it has acknowledged.
#[derive(Debug)]
struct Page {
    ws: tungstenite::WebSocket<DeadlineStream>,
    pace: Pace,
}

impl Page {
    /// Writes `msg` whole within [`IO_TIMEOUT`], followed by the ping that counts it.
    /// tungstenite never holds more than the message in hand (it is written out, or the page
    /// is dropped), so what a page can cost is what the kernel holds of its last
    /// [`MAX_UNACKED_BYTES`].
    fn send(&mut self, msg: Message) -> std::io::Result<()> {
        let ping = self.pace.sent(msg.len(), Instant::now());
        self.ws.get_mut().arm(IO_TIMEOUT);
        let sent = self
            .ws
            .write(msg)
            .and_then(|()| self.ws.write(Message::Ping(ping.to_vec().into())))
            .and_then(|()| self.ws.flush());
        sent.map_err(|e| std::io::Error::other(e.to_string()))
    }

    /// The page's next message, or `None` when none has arrived within the read timeout.
    fn read(&mut self) -> std::io::Result<Option<Message>> {
        // Reading may answer the page's pings: those writes get a deadline too.
        self.ws.get_mut().arm(IO_TIMEOUT);
        let got = match self.ws.read() {
            Ok(m) => Some(m),
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) =>
            {
                None
            }
            Err(e) => return Err(std::io::Error::other(e.to_string())),
        };
        if self.ws.get_ref().expired {
            return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, "the page took no whole message in time"));
        }
        Ok(got)
    }
}

/// Has the control thread send a page's command and turns the hub's answer into the page's
/// reply. Waits for the answer (this page's stream pauses meanwhile, as a click expects), but
/// never queues behind a full queue.
fn command_reply(control: &SyncSender<ControlJob>, text: &str, command: Command, robot_id: u32) -> String {
    let refused = |why: &str| format!("{{\"type\":\"error\",\"message\":{}}}", frame::json_str(why));
    let (reply, answer) = mpsc::channel();
    match control.try_send(ControlJob { command, robot_id, reply }) {
        Ok(()) => {}
        Err(TrySendError::Full(_)) => return refused(&format!("{text}: busy, try again")),
        Err(TrySendError::Disconnected(_)) => return refused(&format!("{text}: the viewer is closing")),
    }
    // The control client gives up after 5 s itself; the extra second covers the queue.
    match answer.recv_timeout(Duration::from_secs(6)) {
        Ok(Ok(r)) if r.status == 0 => format!("{{\"type\":\"ack\",\"command\":{}}}", frame::json_str(text)),
        Ok(Ok(r)) if r.status == 2 => refused(&format!("{text}: no robot {robot_id}")),
        Ok(Ok(_)) => refused(&format!("{text}: not possible now")),
        Ok(Err(e)) => refused(&e),
        Err(_) => refused(&format!("{text}: the hub did not answer")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_websocket_is_accepted_only_from_the_viewers_own_origin_or_an_allowed_one() {
        let none: &[String] = &[];
        let host = Some("127.0.0.1:8080");
        assert!(origin_allowed(Some("http://127.0.0.1:8080"), host, none));
        assert!(origin_allowed(Some("http://LAB-PC:8080/"), Some("lab-pc:8080"), none));
        assert!(!origin_allowed(Some("http://evil.example"), host, none));
        assert!(!origin_allowed(Some("http://127.0.0.1:9090"), host, none), "another port is another origin");
        assert!(!origin_allowed(Some("https://127.0.0.1:8080"), host, none), "the viewer serves http only");
        assert!(!origin_allowed(Some("null"), host, none), "a file:// page");
        assert!(!origin_allowed(Some("http://127.0.0.1:8080"), None, none), "no Host, no own origin");
        let allowed = vec!["http://evil.example/".to_owned()];
        assert!(origin_allowed(Some("http://evil.example"), host, &allowed));
        assert!(!origin_allowed(Some("http://evil.example.net"), host, &allowed));
        // Browsers always send Origin on a WebSocket handshake; a request without one is a
        // program's, which could send any Origin it liked.
        assert!(origin_allowed(None, host, none));
    }

    #[test]
    fn requests_are_served_only_for_the_address_the_viewer_is_at_localhost_or_an_allowed_host() {
        let none: &[String] = &[];
        let loopback: SocketAddr = "127.0.0.1:8080".parse().expect("address");
        let lo: IpAddr = "127.0.0.1".parse().expect("address");
        let ok = |host: &str| host_allowed(Some(host), loopback, lo, none);
        for host in
            ["127.0.0.1:8080", "localhost:8080", "LocalHost:8080", "localhost.:8080", "[::1]:8080", " 127.0.0.1:8080 "]
        {
            assert!(ok(host), "{host}");
        }
        // DNS rebinding: another site's name, resolved to this machine.
        assert!(!ok("attacker.example"));
        assert!(!ok("attacker.example:8080"));
        assert!(!ok("127.0.0.1:9090"), "another port is another server");
        assert!(!ok("127.0.0.1"), "no port is port 80");
        assert!(!ok("localhost.attacker.example:8080"));
        assert!(!ok("192.168.1.5:8080"), "the request did not arrive there");
        for junk in
            ["", ":8080", "::1:8080", "[::1", "[::1]8080", "[lab]:8080", "127.0.0.1:80800", "a b:8080", "x\u{fffd}"]
        {
            assert!(!ok(junk), "{junk:?}");
        }
        // Every browser sends Host; a program without it could have sent any.
        assert!(host_allowed(None, loopback, lo, none));

        // Bound to every address: the one the request arrived at, and localhost only over loopback.
        let any: SocketAddr = "0.0.0.0:8080".parse().expect("address");
        let lan: IpAddr = "192.168.1.5".parse().expect("address");
        assert!(host_allowed(Some("192.168.1.5:8080"), any, lan, none));
        assert!(!host_allowed(Some("192.168.1.6:8080"), any, lan, none));
        assert!(!host_allowed(Some("localhost:8080"), any, lan, none));
        assert!(host_allowed(Some("localhost:8080"), any, lo, none));
        assert!(!host_allowed(Some("lab-pc:8080"), any, lan, none));
        let mapped: IpAddr = "::ffff:192.168.1.5".parse().expect("address");
        assert!(host_allowed(Some("192.168.1.5:8080"), "[::]:8080".parse().expect("address"), mapped, none));
        let port80: SocketAddr = "192.168.1.5:80".parse().expect("address");
        assert!(host_allowed(Some("192.168.1.5"), port80, lan, none));

        // Names the user allows: without a port, on any; with one, on that one.
        let lab = vec!["LAB-PC".to_owned(), "viewer.lab.example:9000".to_owned()];
        assert!(host_allowed(Some("lab-pc:8080"), any, lan, &lab));
        assert!(host_allowed(Some("lab-pc"), any, lan, &lab));
        assert!(host_allowed(Some("viewer.lab.example:9000"), any, lan, &lab));
        assert!(!host_allowed(Some("viewer.lab.example:8080"), any, lan, &lab));
        assert!(!host_allowed(Some("lab-pc.attacker.example:8080"), any, lan, &lab));
    }

    #[test]
    fn an_allowed_host_is_a_name_or_address_with_or_without_a_port_never_a_url() {
        for ok in ["lab-pc", "lab-pc:8080", "192.168.1.5:8080", "[::1]:8080", "viewer.lab.example"] {
            assert_eq!(allowed_host(ok).as_deref(), Ok(ok));
        }
        for bad in ["http://lab-pc:8080", "lab-pc:http", "", "lab pc"] {
            assert!(allowed_host(bad).is_err_and(|e| e.contains("not a URL")), "{bad:?}");
        }
    }

    #[test]
    fn a_header_is_found_without_case_in_the_head_only() {
        let head = "GET / HTTP/1.1\r\nhOsT:  lab-pc:8080 \r\nOrigin: http://x\r\n\r\nHost: body";
        assert_eq!(header(head, "host"), Some("lab-pc:8080"));
        assert_eq!(header(head, "origin"), Some("http://x"));
        assert_eq!(header("GET / HTTP/1.0\r\n\r\n", "host"), None);
        assert_eq!(header("GET /Host: x HTTP/1.0\r\n\r\n", "host"), None, "not in the request line");
    }

    #[test]
    fn a_throttle_reports_the_first_event_then_at_most_once_a_second_with_the_count() {
        let mut t = Throttle::default();
        let t0 = Instant::now();
        assert_eq!(t.note(t0), Some(1));
        assert_eq!(t.note(t0 + Duration::from_millis(500)), None);
        assert_eq!(t.note(t0 + Duration::from_millis(999)), None);
        assert_eq!(t.note(t0 + Duration::from_millis(1000)), Some(4));
        assert_eq!(t.note(t0 + Duration::from_millis(1001)), None);
    }

    #[test]
    fn chairs_are_looked_for_once_a_second_until_seen_then_at_every_turn() {
        let mut p = ChairPoll::default();
        let t0 = Instant::now();
        assert!(p.due(t0), "the first look is at once");
        p.saw(false, t0);
        assert!(!p.due(t0 + Duration::from_millis(999)));
        assert!(p.due(t0 + Duration::from_millis(1000)));
        p.saw(true, t0 + Duration::from_millis(1000));
        assert!(p.due(t0 + Duration::from_millis(1001)));
        // A turn with no new sample (between ticks) does not slow the looks again.
        p.saw(false, t0 + Duration::from_millis(1001));
        assert!(p.due(t0 + Duration::from_millis(1002)));
    }

    #[test]
    fn a_page_is_sent_frames_only_while_it_acknowledges_what_it_was_sent() {
        let t0 = Instant::now();
        let mut p = Pace::default();
        assert!(p.may_send(10 * MAX_UNACKED_BYTES), "a frame of any size goes when nothing is owed");
        let first = p.sent(100_000, t0);
        assert!(p.may_send(MAX_UNACKED_BYTES - 100_000));
        assert!(!p.may_send(MAX_UNACKED_BYTES - 100_000 + 1), "beyond the bound the frame is skipped");
        let second = p.sent(100_000, t0 + Duration::from_millis(10));
        // The page reads the first message: its pong echoes the first ping.
        p.pong(&first, t0 + Duration::from_secs(4));
        assert!(p.may_send(MAX_UNACKED_BYTES - 100_000));
        assert!(!p.stalled(t0 + Duration::from_secs(8)), "it acknowledged something 4 s in");
        assert!(p.stalled(t0 + Duration::from_secs(9)), "then nothing for IO_TIMEOUT");
        p.pong(&second, t0 + Duration::from_secs(9));
        assert!(!p.stalled(t0 + Duration::from_secs(60)), "nothing owed, nothing to wait for");
        // The next message starts a new wait.
        p.sent(10, t0 + Duration::from_secs(60));
        assert!(!p.stalled(t0 + Duration::from_secs(64)));
        assert!(p.stalled(t0 + Duration::from_secs(65)));
    }

    #[test]
    fn pongs_that_acknowledge_nothing_new_change_nothing() {
        let t0 = Instant::now();
        let mut p = Pace::default();
        let first = p.sent(1000, t0);
        p.sent(1000, t0);
        for junk in [&b""[..], b"hello", &2001u64.to_be_bytes(), &0u64.to_be_bytes()] {
            p.pong(junk, t0 + Duration::from_secs(1));
            assert_eq!(p.acked, 0, "{junk:?}");
        }
        p.pong(&first, t0 + Duration::from_secs(1));
        p.pong(&first, t0 + Duration::from_secs(5));
        assert_eq!(p.acked, 1000);
        assert!(p.stalled(t0 + Duration::from_secs(6)), "a repeated pong is no progress");
    }

    #[test]
    fn a_message_gets_one_deadline_however_many_writes_it_takes() {
        // A peer that reads a trickle: every write call makes a little progress, so the
        // socket's own send timeout (per call) would never fire, and 8 MB would take tens of
        // seconds.
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let writer = TcpStream::connect(listener.local_addr().expect("address")).expect("connect");
        let (mut peer, _) = listener.accept().expect("accept");
        let done = Arc::new(AtomicBool::new(false));
        let reading = done.clone();
        let trickle = std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            peer.set_read_timeout(Some(Duration::from_millis(50))).expect("timeout");
            while !reading.load(Ordering::SeqCst) {
                let _ = peer.read(&mut buf);
                // Pacing the trickle, not waiting for anything.
                std::thread::sleep(Duration::from_millis(20));
            }
        });
        let mut stream = DeadlineStream::new(writer);
        let within = Duration::from_millis(500);
        let start = Instant::now();
        stream.arm(within);
        let err = stream.write_all(&vec![7u8; 8 << 20]).expect_err("8 MB cannot pass a trickle in 0.5 s");
        let took = start.elapsed();
        done.store(true, Ordering::SeqCst);
        trickle.join().expect("the peer's thread");
        assert!(matches!(err.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock), "{err}");
        assert!(stream.expired);
        assert!(took >= within, "gave up after {took:?}");
        // Generous: the point is that it ends near its deadline, not after minutes.
        assert!(took < within + Duration::from_secs(10), "took {took:?}");
    }

    #[test]
    fn page_commands_parse_and_anything_else_is_unknown() {
        assert_eq!(parse_command("pause"), Some((Command::Pause, 0)));
        assert_eq!(parse_command("remove:7"), Some((Command::RemoveRobot, 7)));
        assert_eq!(parse_command("remove:x"), None);
        assert_eq!(parse_command("PAUSE"), None);
    }
}
