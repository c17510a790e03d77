//! The episode host (`iwsim env-host`): learning environments on other machines (the Python
//! `ChairsParallelEnv(..., zenoh=…)`) start an episode with a query, and the host runs it
//! here: a lock-step hub of the scenario the query gives, as a child process, and a bridge
//! serving it (agents and observers) on the host's Zenoh session. Another query ends it and
//! answers the hub's end-of-run summary.
//!
//! What a query may set is a short list of hub options (the scenario: lab, tick, length,
//! seed, noise, obstacles, checkpoints, deadline), each checked here; the host adds the
//! session, lock-step and the agent count itself. A lab that is not built in comes as the
//! query's attachment (its XML) and is written to the host's work directory. Episodes are
//! bounded in number; one whose environment went (its machine, its link) runs to its time
//! limit with its chairs at rest and is reaped. On SIGINT or SIGTERM the host ends every
//! episode (SIGTERM to each hub, which ends its run; then its bridge) and leaves nothing
//! running, and its hubs die with it if it is killed.

use std::io::Read as _;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ipc_types::remote as wire;
use zenoh::Wait as _;

use crate::{Bridge, BridgeConfig, BridgeError, Counters, Observers, zerr};

/// How the episode host is set up.
#[derive(Debug, Clone)]
pub struct HostConfig {
    /// Zenoh endpoints to listen on.
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (a router).
    pub connect: Vec<String>,
    /// A Zenoh configuration file to start from.
    pub config: Option<PathBuf>,
    /// The key prefix of the host's own queries ([`wire::EPISODES_PREFIX`] when `None`).
    pub prefix: Option<String>,
    /// Episodes running at once, at most.
    pub max_episodes: usize,
    /// The `iwsim` binary that runs the hubs.
    pub iwsim: PathBuf,
}

/// Hub options a query may give, and whether each takes a value. Everything else (the
/// session, lock-step, the agents waited for, recording paths) is the host's to set.
const ALLOWED: [(&str, bool); 8] = [
    ("--lab", true),
    ("--cycle-ms", true),
    ("--ticks", true),
    ("--seed", true),
    ("--no-noise", false),
    ("--obstacle", true),
    ("--checkpoint", true),
    ("--deadline-ms", true),
];

/// Longest query payload, lab attachment included, accepted.
const MAX_REQUEST_BYTES: usize = 4 << 20;
/// How long a hub has to come up and its bridge to serve it.
const START_TIMEOUT: Duration = Duration::from_secs(20);
/// How long a hub has to end its run after SIGTERM before it is killed.
const END_TIMEOUT: Duration = Duration::from_secs(20);
/// Ended episodes whose summaries are kept for their environments, at most.
const MAX_ENDED: usize = 256;
/// Queries waiting for the host's loop, at most (more are dropped: their askers time out).
const MAX_WAITING: usize = 64;

/// One running episode.
struct Episode {
    session: String,
    hub: Child,
    /// The hub's stdout and stderr, read to their end on threads.
    out: JoinHandle<String>,
    err: JoinHandle<String>,
    bridge: JoinHandle<Result<Counters, BridgeError>>,
    /// Ends the bridge (see [`Bridge::stopper`]).
    stop: Arc<AtomicBool>,
    lab: Option<PathBuf>,
}

/// The hub arguments a query's payload gives (one per line), checked against [`ALLOWED`];
/// with `lab_file`, `--lab` is that file (and may not be given).
pub fn hub_args(payload: &str, lab_file: Option<&str>) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut lines = payload.lines().filter(|l| !l.is_empty());
    let mut lab = false;
    while let Some(flag) = lines.next() {
        let Some(&(_, takes_value)) = ALLOWED.iter().find(|(f, _)| *f == flag) else {
            return Err(format!(
                "{flag:?} is not an option an episode may set (only {})",
                ALLOWED.iter().map(|(f, _)| *f).collect::<Vec<_>>().join(", ")
            ));
        };
        out.push(flag.to_owned());
        if takes_value {
            let value = lines.next().ok_or_else(|| format!("{flag} needs a value"))?;
            if value.starts_with('-') && !value[1..].starts_with(|c: char| c.is_ascii_digit()) {
                return Err(format!("{flag} needs a value, not {value:?}"));
            }
            if flag == "--lab" {
                lab = true;
                if lab_file.is_some() {
                    return Err("--lab and a lab file both given: one lab per episode".into());
                }
                if !value.starts_with("builtin:") {
                    return Err(format!(
                        "--lab {value:?}: a lab on the environment's machine is sent as the query's attachment; \
                         only builtin:NAME labs are named"
                    ));
                }
            }
            out.push(value.to_owned());
        }
    }
    if let Some(file) = lab_file {
        out.extend(["--lab".to_owned(), file.to_owned()]);
    } else if !lab {
        out.extend(["--lab".to_owned(), "builtin:liacc".to_owned()]);
    }
    Ok(out)
}

/// Serves episodes until SIGINT or SIGTERM.
pub fn serve(cfg: &HostConfig) -> Result<(), BridgeError> {
    agent_sdk::remote::install_stop_handlers();
    let zcfg = agent_sdk::remote::config(cfg.config.as_deref(), "peer", &cfg.listen, &cfg.connect)
        .map_err(|e| BridgeError::Zenoh(e.to_string()))?;
    let z = zenoh::open(zcfg).wait().map_err(zerr("open a session"))?;
    let prefix = cfg.prefix.clone().unwrap_or_else(|| wire::EPISODES_PREFIX.to_owned());
    let (tx, rx) = std::sync::mpsc::sync_channel::<zenoh::query::Query>(MAX_WAITING);
    let mut queryables = Vec::new();
    for key in [wire::episode_start_key(&prefix), wire::episode_end_key(&prefix)] {
        let tx: SyncSender<_> = tx.clone();
        queryables.push(
            z.declare_queryable(key)
                .callback(move |q| {
                    let _ = tx.try_send(q);
                })
                .wait()
                .map_err(zerr("declare a queryable"))?,
        );
    }
    let work = std::env::temp_dir().join(format!("iwsim-episodes-{}", std::process::id()));
    let mut host = Host {
        cfg: cfg.clone(),
        z,
        prefix,
        work,
        episodes: Vec::new(),
        next: 1,
        dying: Vec::new(),
        ended: Default::default(),
    };
    agent_sdk::report!(
        "iwsim env-host: episodes served under {}/ (listening on {}{})",
        host.prefix,
        if cfg.listen.is_empty() { "nothing".to_owned() } else { cfg.listen.join(", ") },
        if cfg.connect.is_empty() { String::new() } else { format!("; connected to {}", cfg.connect.join(", ")) }
    );
    let result = host.run(&rx);
    host.end_all();
    drop(queryables);
    let _ = std::fs::remove_dir_all(&host.work);
    result
}

struct Host {
    cfg: HostConfig,
    z: zenoh::Session,
    prefix: String,
    work: PathBuf,
    episodes: Vec<Episode>,
    next: u64,
    /// Bridges whose hub never came up, joined once they give up.
    dying: Vec<JoinHandle<Result<Counters, BridgeError>>>,
    /// Episodes that ended by themselves (their time limit), with their summaries, until
    /// their environments end them.
    ended: std::collections::VecDeque<(String, String)>,
}

impl Host {
    fn run(&mut self, rx: &Receiver<zenoh::query::Query>) -> Result<(), BridgeError> {
        while !agent_sdk::stop_signalled() {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(q) => self.answer(&q),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            self.reap();
        }
        Ok(())
    }

    fn answer(&mut self, q: &zenoh::query::Query) {
        let payload = q.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
        let attachment = q.attachment().map(|a| a.to_bytes().into_owned());
        let result = if payload.len() + attachment.as_ref().map_or(0, Vec::len) > MAX_REQUEST_BYTES {
            Err(format!("a request of more than {MAX_REQUEST_BYTES} bytes"))
        } else if let Ok(text) = std::str::from_utf8(&payload) {
            if q.key_expr().as_str() == wire::episode_start_key(&self.prefix) {
                self.start(text, attachment.as_deref())
            } else {
                self.end(text.trim())
            }
        } else {
            Err("the request is not UTF-8 text".into())
        };
        let _ = match result {
            Ok(answer) => q.reply(q.key_expr().clone(), answer).wait(),
            Err(e) => {
                tracing::warn!("an episode request refused: {e}");
                q.reply_err(e).wait()
            }
        };
    }

    fn start(&mut self, payload: &str, lab_xml: Option<&[u8]>) -> Result<String, String> {
        self.reap();
        if self.episodes.len() >= self.cfg.max_episodes {
            return Err(format!("the host runs {} episodes, its most: end one first", self.episodes.len()));
        }
        let session = format!("env-{}-{}", std::process::id(), self.next);
        self.next += 1;
        let lab = match lab_xml {
            Some(xml) => {
                std::fs::create_dir_all(&self.work).map_err(|e| format!("make {}: {e}", self.work.display()))?;
                let path = self.work.join(format!("{session}.xml"));
                std::fs::write(&path, xml).map_err(|e| format!("write {}: {e}", path.display()))?;
                Some(path)
            }
            None => None,
        };
        let args = hub_args(payload, lab.as_deref().and_then(|p| p.to_str()))?;
        let mut cmd = Command::new(&self.cfg.iwsim);
        cmd.args(["hub", "--session", &session, "--lockstep", "--wait-agents", "1", "--json"])
            .args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        ipc_services::die_with_parent(&mut cmd);
        let mut hub = cmd.spawn().map_err(|e| format!("start a hub ({}): {e}", self.cfg.iwsim.display()))?;
        let read_all = |mut r: Box<dyn std::io::Read + Send>| {
            std::thread::spawn(move || {
                let mut s = String::new();
                let _ = r.read_to_string(&mut s);
                s
            })
        };
        let out = read_all(Box::new(hub.stdout.take().expect("piped")));
        let err = read_all(Box::new(hub.stderr.take().expect("piped")));
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<Arc<AtomicBool>, String>>(1);
        let bcfg = BridgeConfig {
            session: session.clone(),
            connect_timeout: START_TIMEOUT,
            listen: Vec::new(),
            connect: Vec::new(),
            config: None,
            prefix: None,
            observers: Observers::World,
            wait_agents: 1,
        };
        let z = self.z.clone();
        let bridge = std::thread::spawn(move || match Bridge::start_on(&bcfg, z) {
            Ok(b) => {
                let _ = ready_tx.send(Ok(b.stopper()));
                b.run()
            }
            Err(e) => {
                let _ = ready_tx.send(Err(e.to_string()));
                Err(e)
            }
        });
        // The bridge is up, or the hub failed (its options), or the time is up.
        let started = Instant::now();
        let ready = loop {
            match ready_rx.try_recv() {
                // The bridge's own flag, so that setting it ends the bridge.
                Ok(Ok(flag)) => break Ok(flag),
                Ok(Err(e)) => break Err(e),
                Err(TryRecvError::Disconnected) => break Err("the bridge stopped".into()),
                Err(TryRecvError::Empty) => {}
            }
            if let Ok(Some(status)) = hub.try_wait() {
                let said = err.join().unwrap_or_default();
                self.dying.push(bridge);
                let _ = out.join();
                return Err(format!("the hub did not start ({status}): {}", said.trim()));
            }
            if started.elapsed() > START_TIMEOUT {
                break Err(format!("no hub within {START_TIMEOUT:?}"));
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let stop = ready.as_ref().map_or_else(|_| Arc::new(AtomicBool::new(false)), Arc::clone);
        let episode = Episode { session: session.clone(), hub, out, err, bridge, stop, lab };
        match ready {
            Ok(_) => {
                tracing::info!("episode {session} started: hub {}", args.join(" "));
                self.episodes.push(episode);
                Ok(session)
            }
            Err(e) => {
                self.finish(episode, true);
                Err(e)
            }
        }
    }

    fn end(&mut self, session: &str) -> Result<String, String> {
        if let Some(k) = self.ended.iter().position(|(s, _)| s == session) {
            return Ok(self.ended.remove(k).map(|(_, summary)| summary).unwrap_or_default());
        }
        let k = self
            .episodes
            .iter()
            .position(|e| e.session == session)
            .ok_or_else(|| format!("no episode {session:?} runs here"))?;
        let e = self.episodes.swap_remove(k);
        Ok(self.finish(e, true))
    }

    /// Ends `e` (its bridge says goodbye to the hub first, so that the hub, stopped, does not
    /// wait for this process to leave; then SIGTERM to the hub unless it has ended, SIGKILL if
    /// it hangs) and returns the hub's end-of-run summary line (empty if it printed none).
    fn finish(&mut self, mut e: Episode, terminate: bool) -> String {
        e.stop.store(true, Ordering::Relaxed);
        while terminate && !e.bridge.is_finished() && matches!(e.hub.try_wait(), Ok(None)) {
            std::thread::sleep(Duration::from_millis(1));
        }
        if terminate && matches!(e.hub.try_wait(), Ok(None)) {
            // Our own child, not reaped yet.
            os::process::send(&e.hub, libc::SIGTERM);
        }
        let since = Instant::now();
        while matches!(e.hub.try_wait(), Ok(None)) {
            if since.elapsed() > END_TIMEOUT {
                let _ = e.hub.kill();
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let out = e.out.join().unwrap_or_default();
        let err = e.err.join().unwrap_or_default();
        match e.bridge.join() {
            Ok(Ok(c)) => tracing::info!("episode {} over: {c:?}", e.session),
            Ok(Err(x)) => tracing::info!("episode {}: the bridge ended: {x}", e.session),
            Err(_) => tracing::warn!("episode {}: the bridge panicked", e.session),
        }
        if let Some(lab) = &e.lab {
            let _ = std::fs::remove_file(lab);
        }
        let summary = out.lines().find(|l| l.starts_with('{')).unwrap_or("").to_owned();
        if summary.is_empty() {
            tracing::warn!("episode {}: the hub printed no summary: {}", e.session, err.trim());
        }
        summary
    }

    /// Ends the episodes whose hub has ended by itself (their time limit), and joins the
    /// bridges of hubs that never came up.
    fn reap(&mut self) {
        let mut k = 0;
        while k < self.episodes.len() {
            if matches!(self.episodes[k].hub.try_wait(), Ok(Some(_))) && self.episodes[k].bridge.is_finished() {
                let e = self.episodes.swap_remove(k);
                let session = e.session.clone();
                let summary = self.finish(e, false);
                // Kept for the environment's end, which may come long after the time limit.
                if self.ended.len() >= MAX_ENDED {
                    self.ended.pop_front();
                }
                self.ended.push_back((session, summary));
            } else {
                k += 1;
            }
        }
        let (done, running): (Vec<_>, Vec<_>) =
            std::mem::take(&mut self.dying).into_iter().partition(|b| b.is_finished());
        self.dying = running;
        for b in done {
            let _ = b.join();
        }
    }

    fn end_all(&mut self) {
        for e in std::mem::take(&mut self.episodes) {
            self.finish(e, true);
        }
        for b in std::mem::take(&mut self.dying) {
            let _ = b.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_episode_sets_the_scenario_and_nothing_else() {
        let args = hub_args("--ticks\n30\n--seed\n7\n--no-noise\n--obstacle\n1,2,3,4\n", None).expect("allowed");
        assert_eq!(args.join(" "), "--ticks 30 --seed 7 --no-noise --obstacle 1,2,3,4 --lab builtin:liacc");
        let e = hub_args("--session\nother\n", None).expect_err("the host names sessions");
        assert!(e.contains("\"--session\" is not an option an episode may set"), "{e}");
        assert!(hub_args("--record\n/etc/passwd\n", None).is_err());
        assert!(hub_args("--ticks\n", None).expect_err("no value").contains("needs a value"));
        assert!(hub_args("--ticks\n--seed\n", None).expect_err("a flag as value").contains("needs a value"));
        // Negative numbers are values (an obstacle at negative coordinates).
        assert!(hub_args("--obstacle\n-1,2,3,4\n", None).is_ok());
        let e = hub_args("--lab\n/home/me/lab.xml\n", None).expect_err("a path on the other machine");
        assert!(e.contains("attachment"), "{e}");
        assert_eq!(hub_args("", Some("/tmp/x.xml")).expect("a sent lab").join(" "), "--lab /tmp/x.xml");
        assert!(hub_args("--lab\nbuiltin:liacc\n", Some("/tmp/x.xml")).is_err());
    }
}
