//! Helpers shared by the end-to-end tests: unique sessions, child processes that die with
//! the test, and reading the hub's JSON summary.

use std::io::{BufRead as _, BufReader, Read};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use observer::Observer;

/// Waits until `ready` holds, looking every `every`, for at most `timeout`; panics with
/// `what` (and what `ready` last said) if it never does. For conditions nothing announces
/// (a file growing, processes going away), so they are waited on, not slept for.
pub fn wait_until(what: &str, timeout: Duration, every: Duration, mut ready: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !ready() {
        assert!(Instant::now() < deadline, "{what} within {timeout:?}");
        std::thread::sleep(every);
    }
}

/// A TCP port free at the time of asking (for a Zenoh endpoint).
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("0.0.0.0:0").expect("a free port");
    l.local_addr().expect("its address").port()
}

pub fn session(tag: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!("e2e-{tag}-{}-{}", std::process::id(), N.fetch_add(1, Ordering::Relaxed))
}

/// A child process killed if the test fails before it exits.
pub struct Proc(pub Option<Child>);

impl Proc {
    pub fn spawn(args: &[&str]) -> Self {
        Self::start(Self::iwsim(args))
    }

    /// Spawns as [`Proc::spawn`] does, in directory `dir`.
    pub fn spawn_at(dir: &std::path::Path, args: &[&str]) -> Self {
        let mut cmd = Self::iwsim(args);
        cmd.current_dir(dir);
        Self::start(cmd)
    }

    /// Spawns as [`Proc::spawn`] does, in network namespace `ns` (`ip netns exec`, which
    /// execs iwsim in place: the process is iwsim's own, to signal and wait for).
    pub fn spawn_in(ns: &str, args: &[&str]) -> Self {
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", ns, env!("CARGO_BIN_EXE_iwsim")]).args(args);
        Self::start(cmd)
    }

    /// Spawns as [`Proc::spawn`] does, with SIGHUP's default disposition in the child even when
    /// the tests run under `nohup` (which makes every child ignore it): as a process started
    /// from a terminal is, for the tests of what a hang-up does.
    pub fn spawn_hangup_default(args: &[&str]) -> Self {
        use std::os::unix::process::CommandExt as _;
        let mut cmd = Self::iwsim(args);
        // SAFETY: between fork and exec the child only calls signal(2), which is
        // async-signal-safe; nothing is allocated or locked.
        #[allow(unsafe_code)]
        unsafe {
            cmd.pre_exec(|| {
                libc::signal(libc::SIGHUP, libc::SIG_DFL);
                Ok(())
            });
        }
        Self::start(cmd)
    }

    /// `iwsim ARGS`, not started yet.
    fn iwsim(args: &[&str]) -> Command {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_iwsim"));
        cmd.args(args);
        cmd
    }

    /// Starts `cmd` as every test process starts: quiet logs, no stdin, its output piped.
    fn start(mut cmd: Command) -> Self {
        let what = format!("{cmd:?}");
        let child = cmd
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{what} starts: {e}"));
        Self(Some(child))
    }

    pub fn pid(&self) -> u32 {
        self.0.as_ref().expect("running").id()
    }

    /// Waits for the process to exit (checking every few milliseconds) and returns its
    /// output; panics with what it printed if it does not exit in time. Its stdout is read
    /// meanwhile, so a process that prints more than a pipe holds at its end (a hub's outcome
    /// line with hundreds of robots) is not held up writing it.
    pub fn wait(mut self, timeout: Duration) -> Output {
        let mut child = self.0.take().expect("running");
        let reader = child.stdout.take().map(|mut out| {
            std::thread::spawn(move || {
                let mut buf = Vec::new();
                let _ = std::io::Read::read_to_end(&mut out, &mut buf);
                buf
            })
        });
        let stdout = |reader: Option<std::thread::JoinHandle<Vec<u8>>>| {
            reader.map(|r| r.join().unwrap_or_default()).unwrap_or_default()
        };
        let start = Instant::now();
        loop {
            if child.try_wait().expect("wait works").is_some() {
                let mut out = child.wait_with_output().expect("output");
                out.stdout = stdout(reader);
                return out;
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let out = child.wait_with_output().expect("output");
                panic!(
                    "process did not exit within {timeout:?}\nstdout: {}\nstderr: {}",
                    String::from_utf8_lossy(&stdout(reader)),
                    String::from_utf8_lossy(&out.stderr)
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    pub fn kill9(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub fn signal(&self, sig: &str) {
        let status =
            Command::new("kill").arg(format!("-{sig}")).arg(self.pid().to_string()).status().expect("kill runs");
        assert!(status.success());
    }

    /// Waits until the process prints a stderr line containing `marker` and returns what
    /// follows it on that line; stderr keeps being drained afterwards.
    pub fn announced(&mut self, marker: &str, timeout: Duration) -> String {
        self.stderr_lines().said(marker, timeout)
    }

    pub fn stderr_now(&mut self) -> String {
        let mut s = String::new();
        if let Some(err) = self.0.as_mut().and_then(|c| c.stderr.as_mut()) {
            let _ = err.read_to_string(&mut s);
        }
        s
    }
}

impl Drop for Proc {
    /// A process still running when its test ends (or panics) is asked to stop first
    /// (SIGTERM, and SIGCONT in case a test stopped it), so a runner forwards the signal to its
    /// children and nothing of the run outlives the test; SIGKILL after 5 s.
    fn drop(&mut self) {
        let Some(mut child) = self.0.take() else { return };
        if child.try_wait().ok().flatten().is_some() {
            return;
        }
        let pid = child.id() as libc::pid_t;
        let signal = |sig| {
            #[allow(unsafe_code)]
            // SAFETY: a signal to our own child, not reaped until the waiter below has seen it
            // exit, so the pid is still its own.
            unsafe {
                libc::kill(pid, sig);
            }
        };
        signal(libc::SIGTERM);
        signal(libc::SIGCONT);
        // Wait for the exit itself (on a thread, so the wait can time out).
        let (tx, rx) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            let _ = child.wait();
            let _ = tx.send(());
        });
        if rx.recv_timeout(Duration::from_secs(5)).is_err() {
            signal(libc::SIGKILL);
        }
        let _ = waiter.join();
    }
}

pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Attaches as an observer and waits until the hub's world has reached `tick`.
/// The names of a snapshot's robots, in its order, from the robots' info (names are not in the
/// per-tick snapshot); "?" for one whose name is not UTF-8.
pub fn robot_names(observer: &mut Observer, robots: &[ipc_types::RobotState]) -> Vec<String> {
    let infos = observer.robot_infos_covering(robots).expect("robot info");
    robots
        .iter()
        .enumerate()
        .map(|(k, r)| {
            ipc_types::RobotInfo::find(infos, k, r.id).and_then(|i| i.name.as_str()).unwrap_or("?").to_owned()
        })
        .collect()
}

/// The robot called `name` in `robots`, if it is there (its name looked up in the robots' info).
pub fn robot_named(
    observer: &mut Observer,
    robots: &[ipc_types::RobotState],
    name: &str,
) -> Option<ipc_types::RobotState> {
    let names = robot_names(observer, robots);
    robots.iter().zip(&names).find(|(_, n)| *n == name).map(|(r, _)| *r)
}

pub fn wait_for_tick(session: &str, tick: u64, timeout: Duration) -> Observer {
    let mut observer = Observer::connect_within(session, "observer", timeout).expect("hub comes up");
    let start = Instant::now();
    loop {
        let (h, _) = observer.world().expect("world snapshot");
        if h.tick >= tick {
            return observer;
        }
        assert!(start.elapsed() < timeout, "hub stayed at tick {} (< {tick})", h.tick);
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Asserts that session `s` left no files in /dev/shm (the last process of a session removes
/// them, whatever way it ended).
pub fn assert_no_shared_memory_left(s: &str) {
    assert_no_dev_shm_left(s);
    let prefix = format!("iwsim_{s}_");
    let named = |dir: &str| -> Vec<String> {
        std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
            .filter(|n| n.starts_with(&prefix))
            .map(|n| format!("{dir}/{n}"))
            .collect()
    };
    // iceoryx2's files outside /dev/shm (issue 27, fault 10): nodes' monitors and details, and
    // event sockets, under its root, /tmp/iceoryx2.
    let mut files = named("/tmp/iceoryx2");
    files.extend(named("/tmp/iceoryx2/nodes"));
    for node in std::fs::read_dir("/tmp/iceoryx2/nodes").into_iter().flatten().flatten() {
        if node.path().is_dir() {
            files.extend(named(&node.path().to_string_lossy()));
        }
    }
    assert!(files.is_empty(), "left in /tmp/iceoryx2: {files:?}");
}

/// Checks that no shared-memory file of session `s` is left in /dev/shm (iceoryx2's files
/// under /tmp/iceoryx2 aside: after a SIGKILL it may leave a dead node's files there).
pub fn assert_no_dev_shm_left(s: &str) {
    let prefix = format!("iwsim_{s}_");
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
}

impl Proc {
    /// Takes the process's stderr: its lines, as they come (drained on a thread until the
    /// process closes it).
    pub fn stderr_lines(&mut self) -> Lines {
        Lines::read(self.0.as_mut().and_then(|c| c.stderr.take()).expect("piped stderr"))
    }

    /// Takes the process's stdout, as [`Proc::stderr_lines`] does its stderr.
    pub fn stdout_lines(&mut self) -> Lines {
        Lines::read(self.0.as_mut().and_then(|c| c.stdout.take()).expect("piped stdout"))
    }
}

/// What [`Lines::next_by`] got.
pub enum Next {
    Line(String),
    /// End of file: the writer closed the pipe and every line has been received.
    End,
    TimedOut,
}

/// A child's output, line by line, read on a thread as the child writes it.
///
/// Its channel closes only when the reader has reached end of file, that is when the child
/// (and whatever inherited the pipe) closed it. A process that has exited may still have
/// lines in the pipe that the reader has not forwarded yet: what it said in the end is
/// [`Lines::to_end`], never a look at what has arrived so far.
pub struct Lines(Receiver<String>);

impl Lines {
    pub fn read(from: impl Read + Send + 'static) -> Self {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            // Read to the end even when no one listens any more: a process whose stderr
            // closed would fail (or die of SIGPIPE) on its next line.
            for line in BufReader::new(from).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        Self(rx)
    }

    /// The next line, waiting at most until `deadline`.
    pub fn next_by(&self, deadline: Instant) -> Next {
        match self.0.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            Ok(line) => Next::Line(line),
            Err(RecvTimeoutError::Disconnected) => Next::End,
            Err(RecvTimeoutError::Timeout) => Next::TimedOut,
        }
    }

    /// Waits for a line containing `marker`; returns what follows it on that line.
    pub fn said(&self, marker: &str, timeout: Duration) -> String {
        let deadline = Instant::now() + timeout;
        // What came instead, for the failure's message.
        let mut other = Vec::new();
        loop {
            match self.next_by(deadline) {
                Next::Line(line) => {
                    if let Some(rest) = line.split(marker).nth(1) {
                        return rest.trim().to_owned();
                    }
                    other.push(line);
                }
                Next::End => panic!("no line with {marker:?}: the output ended after:\n{}", other.join("\n")),
                Next::TimedOut => panic!("no line with {marker:?} within {timeout:?}, after:\n{}", other.join("\n")),
            }
        }
    }

    /// Reads until every marker has been seen (in any order); returns what was read.
    pub fn wait_for_all(&self, markers: &[&str], timeout: Duration) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        let mut seen: Vec<String> = Vec::new();
        while !markers.iter().all(|m| seen.iter().any(|l| l.contains(m))) {
            match self.next_by(deadline) {
                Next::Line(line) => seen.push(line),
                end => panic!(
                    "no lines with all of {markers:?} ({}); read:\n{}",
                    if matches!(end, Next::End) {
                        "the output ended".to_owned()
                    } else {
                        format!("within {timeout:?}")
                    },
                    seen.join("\n")
                ),
            }
        }
        seen
    }

    /// Every line still to come, up to end of file: call it once the process has exited (or
    /// is about to), and it returns all it said.
    ///
    /// # Panics
    /// When the pipe is still open after `timeout` (something still holds it).
    pub fn to_end(&self, timeout: Duration) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        let mut rest = Vec::new();
        loop {
            match self.next_by(deadline) {
                Next::Line(line) => rest.push(line),
                Next::End => return rest,
                Next::TimedOut => panic!("the output did not end within {timeout:?}; read:\n{}", rest.join("\n")),
            }
        }
    }

    /// What has arrived so far, without waiting: only for a failure message about a process
    /// that is still running, never for what a finished process said (see [`Lines::to_end`]).
    pub fn so_far(&self) -> Vec<String> {
        self.0.try_iter().collect()
    }
}

/// Every process (other than this one) with an argument that starts with `prefix`, as
/// "pid: command line", from /proc.
pub fn processes_with_argument(prefix: &str) -> Vec<String> {
    let me = std::process::id().to_string();
    std::fs::read_dir("/proc")
        .expect("/proc")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().bytes().all(|b| b.is_ascii_digit()))
        .filter(|e| e.file_name().to_string_lossy() != me)
        .filter_map(|e| {
            let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
            let args: Vec<String> =
                cmdline.split(|&b| b == 0).map(|a| String::from_utf8_lossy(a).into_owned()).collect();
            args.iter()
                .any(|a| a.starts_with(prefix))
                .then(|| format!("{}: {}", e.file_name().to_string_lossy(), args.join(" ")))
        })
        .collect()
}

/// The files in /dev/shm whose names start with `prefix`.
pub fn shared_memory_files(prefix: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.starts_with(prefix))
        .collect()
}

/// Every robot's true pose at every tick of a recorded run, by name: `[tick, x, y, heading°]`
/// rows, replayed from the recording's journal (what the runner judges from).
pub fn truth(recording: &std::path::Path) -> std::collections::BTreeMap<String, Vec<[f64; 4]>> {
    let rec = recorder::Recording::open(recording).unwrap_or_else(|e| panic!("{}: {e}", recording.display()));
    let mut out: std::collections::BTreeMap<String, Vec<[f64; 4]>> = Default::default();
    hub::replay::replay_observed(&rec, true, None, |stage| {
        let tick = stage.world().tick() as f64;
        for id in stage.ids() {
            if let Some(r) = stage.robot(id) {
                out.entry(r.spec.name.clone()).or_default().push([tick, r.pose.x, r.pose.y, r.pose.heading_deg()]);
            }
        }
    })
    .expect("the recording replays");
    out
}

/// A hub (with `hub_args`) and a UDP bridge (with `bridge_args`) on a free port in session
/// `s`; returns both, the bridge's registration address and every line it prints on stderr.
pub fn hub_and_logged_bridge(
    s: &str,
    hub_args: &[&str],
    bridge_args: &[&str],
) -> (Proc, Proc, std::net::SocketAddr, Lines) {
    let mut args = vec!["hub", "--session", s];
    args.extend_from_slice(hub_args);
    let hub = Proc::spawn(&args);
    let mut bargs = vec!["udp", "--session", s, "--port", "0"];
    bargs.extend_from_slice(bridge_args);
    let mut bridge = Proc::spawn(&bargs);
    let lines = bridge.stderr_lines();
    let addr = lines.said("registrations on ", Duration::from_secs(20)).parse().expect("address");
    (hub, bridge, addr, lines)
}
