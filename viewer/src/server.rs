//! The viewer process: reads the world from the hub over shared memory (read-only) and serves
//! a page plus a WebSocket stream of frames to any number of browsers.
//!
//! The iceoryx2 ports are not `Send`, so the main thread reads the hub and publishes the newest
//! frame in a shared slot; each browser connection runs on a thread of its own and sends the
//! newest frame at most ~30 times a second, whatever the tick rate.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use agent_sdk::{AgentError, Observer};
use ipc_types::{Command, RunState};
use tungstenite::Message;

use crate::frame;

/// At most this many frames per second go to a page.
pub const MAX_FPS: u32 = 60;

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
    /// How long to wait for the hub.
    pub connect_timeout: Duration,
}

/// Why the viewer stopped.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The hub could not be reached.
    #[error(transparent)]
    Hub(#[from] AgentError),
    /// The HTTP port could not be bound.
    #[error("cannot serve HTTP on {addr}: {source}")]
    Bind {
        /// Address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
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
        let observer =
            Observer::connect_within(&cfg.session, &format!("viewer-{}", std::process::id()), cfg.connect_timeout)?;
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
    pub fn run(self) -> Result<(), ViewerError> {
        let shared: Shared = Arc::new((Mutex::new(Latest::default()), Condvar::new()));
        {
            let shared = shared.clone();
            let map_json = self.map_json.clone();
            let session = self.cfg.session.clone();
            let allow = self.cfg.allow_control;
            let listener = self.listener;
            std::thread::spawn(move || {
                for stream in listener.incoming().flatten() {
                    let (shared, map_json, session) = (shared.clone(), map_json.clone(), session.clone());
                    std::thread::spawn(move || {
                        if let Err(e) = serve_connection(stream, &shared, &map_json, &session, allow) {
                            tracing::debug!("viewer connection: {e}");
                        }
                    });
                }
            });
        }
        let mut ids: Vec<u32> = Vec::new();
        let mut sensors: Vec<ipc_types::RobotSensors> = Vec::new();
        let mut roster_dirty = false;
        loop {
            // The hub republishes sensor geometry when robots come or go; it may land apart
            // from the snapshot that shows them, so either change re-sends the roster.
            if let Some(s) = self.observer.try_robot_sensors()? {
                sensors = s;
                roster_dirty = true;
            }
            match self.observer.try_world()? {
                Some((h, robots)) => {
                    let now_ids: Vec<u32> = robots.iter().map(|r| r.id).collect();
                    let roster = (now_ids != ids || roster_dirty).then(|| frame::roster_json(&robots, &sensors));
                    roster_dirty = false;
                    ids = now_ids;
                    let bytes = frame::encode(&h, &robots);
                    let (lock, cv) = &*shared;
                    let mut l = lock.lock().unwrap_or_else(|p| p.into_inner());
                    l.frame = Arc::new(bytes);
                    l.frame_seq += 1;
                    if let Some(r) = roster {
                        l.roster = Arc::new(r);
                        l.roster_seq += 1;
                    }
                    let finished = h.run_state == RunState::Finished as u32;
                    l.finished = finished;
                    cv.notify_all();
                    drop(l);
                    if finished {
                        // Let the pages draw the last frame, then leave no file behind.
                        std::thread::sleep(Duration::from_millis(200));
                        self.observer.close();
                        return Ok(());
                    }
                }
                // The world arrives once per tick; checking 100 times a second is plenty
                // for a display that shows at most 30. A silent hub may be a paused one or a
                // dead one: only its process can tell.
                None => match self.observer.check_alive() {
                    Ok(()) => std::thread::sleep(Duration::from_millis(10)),
                    Err(AgentError::Interrupted) => return Ok(()),
                    Err(e) => return Err(e.into()),
                },
            }
        }
    }
}

fn serve_connection(
    mut stream: TcpStream,
    shared: &Shared,
    map_json: &str,
    session: &str,
    allow_control: bool,
) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
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
    if path == "/ws" {
        return serve_websocket(stream, shared, map_json, session, allow_control);
    }
    // Consume the request (up to the blank line) before answering.
    let mut req = Vec::new();
    let mut buf = [0u8; 1024];
    while !req.windows(4).any(|w| w == b"\r\n\r\n") && req.len() < 16 * 1024 {
        let n = stream.read(&mut buf)?;
        if n == 0 {
            break;
        }
        req.extend_from_slice(&buf[..n]);
    }
    // The query string only tunes the page (view, camera, chair); the file is the path.
    let file = path.split('?').next().unwrap_or("/");
    let (status, ctype, body) = match STATIC_FILES.iter().find(|(p, _, _)| *p == file) {
        Some((_, ctype, body)) => ("200 OK", *ctype, *body),
        None => ("404 Not Found", "text/plain", "not found\n"),
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body.as_bytes())
}

/// A page's command: `start`, `pause`, `step`, `stop` or `remove:<robot id>`.
fn parse_command(text: &str) -> Option<(Command, u32)> {
    match text {
        "start" => Some((Command::Start, 0)),
        "pause" => Some((Command::Pause, 0)),
        "step" => Some((Command::Step, 0)),
        "stop" => Some((Command::Stop, 0)),
        _ => Some((Command::RemoveRobot, text.strip_prefix("remove:")?.parse().ok()?)),
    }
}

fn serve_websocket(
    stream: TcpStream,
    shared: &Shared,
    map_json: &str,
    session: &str,
    allow_control: bool,
) -> std::io::Result<()> {
    let mut ws = tungstenite::accept(stream).map_err(|e| std::io::Error::other(e.to_string()))?;
    let io = |e: tungstenite::Error| std::io::Error::other(e.to_string());
    ws.send(Message::text(map_json.to_owned())).map_err(io)?;
    // Reads must not block the frame stream: poll them with a short timeout.
    ws.get_mut().set_read_timeout(Some(Duration::from_millis(5)))?;
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
        if let Some((r, seq)) = roster {
            ws.send(Message::text(r.as_str().to_owned())).map_err(io)?;
            roster_seq = seq;
        }
        if let Some((f, seq)) = frame
            && last_sent.elapsed() >= min_gap
        {
            ws.send(Message::binary(f.as_slice().to_vec())).map_err(io)?;
            frame_seq = seq;
            last_sent = Instant::now();
        }
        match ws.read() {
            Ok(Message::Text(cmd)) => {
                let reply = match (parse_command(cmd.as_str()), allow_control) {
                    (Some((c, robot)), true) => {
                        let refused =
                            |why: &str| format!("{{\"type\":\"error\",\"message\":{}}}", frame::json_str(why));
                        match agent_sdk::control(session, c, robot) {
                            Ok(r) if r.status == 0 => {
                                format!("{{\"type\":\"ack\",\"command\":{}}}", frame::json_str(cmd.as_str()))
                            }
                            Ok(r) if r.status == 2 => refused(&format!("{cmd}: no robot {robot}")),
                            Ok(_) => refused(&format!("{cmd}: not possible now")),
                            Err(e) => refused(&e.to_string()),
                        }
                    }
                    (Some(_), false) => {
                        "{\"type\":\"error\",\"message\":\"control is off: start iwsim view with --allow-control\"}"
                            .to_owned()
                    }
                    (None, _) => "{\"type\":\"error\",\"message\":\"unknown command\"}".to_owned(),
                };
                ws.send(Message::text(reply)).map_err(io)?;
            }
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(e) => return Err(io(e)),
        }
        if finished && frame_seq > 0 {
            let _ = ws.close(None);
            return Ok(());
        }
    }
}
