//! Signals: a set blocked and read from a signalfd (the runner, whose iceoryx2 node would
//! replace any handler), handlers that only bump an atomic (commands with no iceoryx2 node),
//! and children started with nothing blocked.

use std::io;
use std::os::fd::AsRawFd as _;
use std::time::Duration;

use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, SigmaskHow, Signal, pthread_sigmask, sigaction};
use nix::sys::signalfd::{SfdFlags, SignalFd};

fn set_of(signals: &[i32]) -> io::Result<SigSet> {
    let mut set = SigSet::empty();
    for &s in signals {
        set.add(Signal::try_from(s).map_err(crate::io)?);
    }
    Ok(set)
}

/// Signals blocked in the calling thread and read from a signalfd until this is dropped
/// (which puts the thread's mask back).
#[derive(Debug)]
pub struct Blocked {
    fd: SignalFd,
    previous: SigSet,
}

impl Blocked {
    /// Blocks `signals` (numbers) in the calling thread and opens a signalfd for them.
    /// `Err((true, e))`: the block failed; `Err((false, e))`: the signalfd did (the mask is
    /// put back).
    ///
    /// Call it before the process starts any thread: threads inherit the mask of the thread
    /// that spawns them, and a thread with the signals unblocked would take them instead.
    pub fn install(signals: &[i32]) -> Result<Self, (bool, io::Error)> {
        let set = set_of(signals).map_err(|e| (true, e))?;
        let mut previous = SigSet::empty();
        pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&set), Some(&mut previous)).map_err(|e| (true, crate::io(e)))?;
        match SignalFd::with_flags(&set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC) {
            Ok(fd) => Ok(Self { fd, previous }),
            Err(e) => {
                let _ = pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&previous), None);
                Err((false, crate::io(e)))
            }
        }
    }

    /// The first blocked signal received and not yet taken (its number), waiting up to
    /// `timeout` for one.
    pub fn wait(&self, timeout: Duration) -> Option<i32> {
        let _ = crate::poll::any_readable(&[self.fd.as_raw_fd()], Some(timeout));
        self.take()
    }

    /// The first blocked signal received and not yet taken (its number), without waiting.
    pub fn take(&self) -> Option<i32> {
        match self.fd.read_signal() {
            Ok(Some(info)) => i32::try_from(info.ssi_signo).ok(),
            _ => None,
        }
    }
}

impl Drop for Blocked {
    fn drop(&mut self) {
        let _ = pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&self.previous), None);
    }
}

/// Makes `command`'s child start with no signal blocked, whatever this thread blocks (a
/// blocked mask is inherited through fork and exec, and `std::process::Command` keeps it).
pub fn unblock_in_child(command: &mut std::process::Command) {
    use std::os::unix::process::CommandExt as _;
    #[allow(unsafe_code)]
    // SAFETY: the closure runs in the forked child before exec and only calls
    // pthread_sigmask, which is async-signal-safe; it allocates nothing and takes no lock.
    unsafe {
        command.pre_exec(|| pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&SigSet::empty()), None).map_err(crate::io));
    }
}

/// Installs `handler` for `signals` (numbers). With `restart`, interrupted reads and writes
/// go on (`SA_RESTART`); without it they, and every wait, end with `EINTR`, so a loop sees at
/// once what the handler did.
///
/// The handler runs in signal context: it must do nothing but an atomic store or add (no
/// allocation, no lock, no I/O).
pub fn on_signals(signals: &[i32], handler: extern "C" fn(libc::c_int), restart: bool) -> io::Result<()> {
    let flags = if restart { SaFlags::SA_RESTART } else { SaFlags::empty() };
    let action = SigAction::new(SigHandler::Handler(handler), flags, SigSet::empty());
    for &s in signals {
        let signal = Signal::try_from(s).map_err(crate::io)?;
        #[allow(unsafe_code)]
        // SAFETY: the handler's contract above (async-signal-safe work only) is the one
        // sigaction needs; it replaces no handler Rust code relies on.
        unsafe {
            sigaction(signal, &action).map_err(crate::io)?;
        }
    }
    Ok(())
}

/// Whether signal number `signal` is ignored (`SIG_IGN`), as `nohup` leaves SIGHUP.
pub fn is_ignored(signal: i32) -> bool {
    #[allow(unsafe_code)]
    // SAFETY: a zeroed sigaction is a valid one (integers and pointers); with a null new
    // action, sigaction only writes the current one into it. nix has no call that only reads
    // the disposition.
    let (rc, old) = unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        (libc::sigaction(signal, std::ptr::null(), &mut old), old)
    };
    rc == 0 && old.sa_sigaction == libc::SIG_IGN
}

/// Sends signal number `signal` to the calling thread (`raise(3)`).
pub fn raise(signal: i32) -> io::Result<()> {
    nix::sys::signal::raise(Signal::try_from(signal).map_err(crate::io)?).map_err(crate::io)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU32, Ordering};

    static HITS: AtomicU32 = AtomicU32::new(0);

    extern "C" fn count(_: libc::c_int) {
        HITS.fetch_add(1, Ordering::SeqCst);
    }

    #[test]
    fn a_handler_counts_each_signal_sent() {
        on_signals(&[libc::SIGUSR2], count, true).expect("handler");
        let before = HITS.load(Ordering::SeqCst);
        nix::sys::signal::raise(Signal::SIGUSR2).expect("raise");
        nix::sys::signal::raise(Signal::SIGUSR2).expect("raise");
        assert_eq!(HITS.load(Ordering::SeqCst), before + 2);
    }

    #[test]
    fn a_blocked_signal_is_read_from_the_signalfd_not_delivered() {
        // On a thread of its own: the block is the calling thread's.
        std::thread::spawn(|| {
            let blocked = Blocked::install(&[libc::SIGWINCH]).expect("blocked");
            assert_eq!(blocked.take(), None);
            nix::sys::signal::raise(Signal::SIGWINCH).expect("raise");
            assert_eq!(blocked.wait(Duration::from_secs(5)), Some(libc::SIGWINCH));
        })
        .join()
        .expect("thread");
    }
}
