//! The processes of one bench run — a hub and its helpers (bridge, agents, clients) — waited
//! for together, and stopped together when the run fails.
//!
//! A lock-step hub waits for its agents for ever: if a helper dies first (a UDP client whose
//! registration was lost under a flood, say), waiting on the hub alone would hang the bench.
//! The crew watches every helper while the hub runs, ends the run at the first failure with
//! that helper's own words, and stops whatever is still running on the way out. While it
//! watches, it reads the hub's peak resident set (`VmHWM`), the last time just before the hub
//! exits.

use std::process::Child;
use std::time::{Duration, Instant};

/// How long a process asked to stop (SIGTERM) gets before it is killed.
const STOP_GRACE: Duration = Duration::from_secs(3);
/// How often the hub and its helpers are looked at while the hub runs.
const POLL: Duration = Duration::from_millis(5);

/// A hub and its helpers; whatever is still running when the crew is dropped is stopped.
pub(crate) struct Crew {
    hub: Child,
    /// Threads reading the hub's stdout and stderr as it runs, so it never blocks on a full
    /// pipe while the crew polls it.
    hub_out: Option<(Drain, Drain)>,
    helpers: Vec<(Child, &'static str)>,
}

type Drain = std::thread::JoinHandle<Vec<u8>>;

/// Reads `pipe` to its end on a thread of its own.
fn drain(pipe: Option<impl std::io::Read + Send + 'static>) -> Drain {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut p) = pipe {
            let _ = p.read_to_end(&mut bytes);
        }
        bytes
    })
}

impl Crew {
    /// A crew led by `hub`.
    pub(crate) fn new(mut hub: Child) -> Crew {
        let hub_out = Some((drain(hub.stdout.take()), drain(hub.stderr.take())));
        Crew { hub, hub_out, helpers: Vec::new() }
    }

    /// Adds a helper, called `what` in errors.
    pub(crate) fn push(&mut self, child: Child, what: &'static str) {
        self.helpers.push((child, what));
    }

    /// Helpers so far.
    pub(crate) fn len(&self) -> usize {
        self.helpers.len()
    }

    /// The error of the helper pushed `index`-th, which is ending before its time (it closed
    /// its stdout early): its own words if it failed, else `why`. The rest of the crew is
    /// stopped.
    pub(crate) fn helper_failed(mut self, index: usize, why: &str) -> anyhow::Error {
        if index >= self.helpers.len() {
            return anyhow::anyhow!("{why}");
        }
        let (child, what) = self.helpers.remove(index);
        match crate::finish(child, what) {
            Err(e) => e,
            Ok(_) => anyhow::anyhow!("{why}"),
        }
    }

    /// Waits for the hub to end, then for every helper; what they printed and the hub's peak
    /// memory. A helper that fails while the hub runs ends the run at once with its error.
    pub(crate) fn finish(mut self) -> anyhow::Result<CrewOutput> {
        let mut hub_peak_rss_kib = 0;
        let status = loop {
            // Read before the exit check: the last value read is the peak of the whole run but
            // its last poll interval, in which the hub only tears down.
            if let Some(kib) = peak_rss_kib(self.hub.id()) {
                hub_peak_rss_kib = kib;
            }
            if let Some(status) = self.hub.try_wait()? {
                break status;
            }
            for i in 0..self.helpers.len() {
                if self.helpers[i].0.try_wait()?.is_some_and(|s| !s.success()) {
                    let (child, what) = self.helpers.swap_remove(i);
                    // Drop (on the way out) stops the hub and the other helpers.
                    crate::finish(child, what)?;
                    anyhow::bail!("the {what} failed");
                }
            }
            std::thread::sleep(POLL);
        };
        let (out, err) = self.hub_out.take().ok_or_else(|| anyhow::anyhow!("the hub was already waited for"))?;
        let join = |d: Drain| d.join().map_err(|_| anyhow::anyhow!("reading the hub's output panicked"));
        let (out, err) = (String::from_utf8_lossy(&join(out)?).into_owned(), join(err)?);
        anyhow::ensure!(status.success(), "the hub failed: {out}{}", String::from_utf8_lossy(&err));
        let mut helpers = String::new();
        while !self.helpers.is_empty() {
            let (child, what) = self.helpers.remove(0);
            helpers += &crate::finish(child, what)?;
        }
        Ok(CrewOutput { hub: out, helpers, hub_peak_rss_kib })
    }
}

/// What a crew's run printed, and the hub's memory.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct CrewOutput {
    /// The hub's stdout.
    pub(crate) hub: String,
    /// The helpers' stdout (what they had not been read of before), one after the other.
    pub(crate) helpers: String,
    /// The hub's peak resident set size, KiB (`VmHWM`; 0: never read).
    pub(crate) hub_peak_rss_kib: u64,
}

/// The peak resident set size (`VmHWM` in `/proc/PID/status`) of process `pid`, KiB; `None`
/// when it cannot be read (the process has exited, or this is not Linux).
pub(crate) fn peak_rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    line.trim().strip_suffix("kB")?.trim().parse().ok()
}

impl Drop for Crew {
    fn drop(&mut self) {
        // The hub first, by SIGTERM, so it removes its shared memory; then the helpers.
        let procs = std::iter::once(&mut self.hub).chain(self.helpers.iter_mut().map(|(c, _)| c));
        for child in procs {
            if let Ok(None) = child.try_wait() {
                let _ = std::process::Command::new("kill").arg("-TERM").arg(child.id().to_string()).status();
                let deadline = Instant::now() + STOP_GRACE;
                while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
                    std::thread::sleep(POLL);
                }
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn this_process_has_a_peak_resident_set() {
        let kib = super::peak_rss_kib(std::process::id()).expect("Linux reports VmHWM");
        // A test binary with its libraries is at least a megabyte, and not a terabyte.
        assert!((1024..1 << 30).contains(&kib), "{kib} KiB");
    }
}
