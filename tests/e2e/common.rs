//! Helpers shared by the end-to-end tests: unique sessions, child processes that die with
//! the test, and reading the hub's JSON summary.

use std::io::Read;
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use agent_sdk::Observer;

pub fn session(tag: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!("e2e-{tag}-{}-{}", std::process::id(), N.fetch_add(1, Ordering::Relaxed))
}

/// A child process killed if the test fails before it exits.
pub struct Proc(pub Option<Child>);

impl Proc {
    pub fn spawn(args: &[&str]) -> Self {
        let child = Command::new(env!("CARGO_BIN_EXE_iwsim"))
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("iwsim starts");
        Self(Some(child))
    }

    pub fn pid(&self) -> u32 {
        self.0.as_ref().expect("running").id()
    }

    /// Waits for the process to exit (checking every few milliseconds) and returns its
    /// output; panics with what it printed if it does not exit in time.
    pub fn wait(mut self, timeout: Duration) -> Output {
        let mut child = self.0.take().expect("running");
        let start = Instant::now();
        loop {
            if child.try_wait().expect("wait works").is_some() {
                return child.wait_with_output().expect("output");
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let out = child.wait_with_output().expect("output");
                panic!(
                    "process did not exit within {timeout:?}\nstdout: {}\nstderr: {}",
                    String::from_utf8_lossy(&out.stdout),
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
        use std::io::BufRead;
        let stderr = self.0.as_mut().and_then(|c| c.stderr.take()).expect("piped stderr");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let deadline = Instant::now() + timeout;
        loop {
            let line = rx
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
                .unwrap_or_else(|_| panic!("no line with {marker:?} within {timeout:?}"));
            if let Some(rest) = line.split(marker).nth(1) {
                return rest.trim().to_owned();
            }
        }
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
    let prefix = format!("iwsim_{s}_");
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
}

impl Proc {
    /// Takes the process's stderr: its lines, as they come, on a channel (drained on a thread
    /// until the process exits).
    pub fn stderr_lines(&mut self) -> std::sync::mpsc::Receiver<String> {
        use std::io::BufRead;
        let stderr = self.0.as_mut().and_then(|c| c.stderr.take()).expect("piped stderr");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        rx
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
