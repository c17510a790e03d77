//! SIGINT, SIGTERM and SIGHUP as events the runner's loop reads, so that a signal sent to
//! `iwsim run` alone (not to its whole process group) still takes the hub, the agents and the
//! viewer with it.
//!
//! Why a signalfd with the signals blocked, not a handler writing to a self-pipe: the runner's
//! own observer is an iceoryx2 node, and iceoryx2 installs its SIGINT/SIGTERM handlers when
//! its first node is created, replacing whatever handler was there. A blocked signal reaches
//! no handler at all; it waits in the signalfd until the loop reads it. The children do not
//! inherit the block: a child inherits its parent's signal mask through fork and exec, and
//! `std::process::Command` leaves it as it is, so [`unblock_in_child`] clears it in every
//! child the runner starts (without it, a child's own SIGINT/SIGTERM handlers never run).

use std::io;
use std::os::fd::{AsRawFd as _, FromRawFd as _, OwnedFd};
use std::time::Duration;

/// A termination signal the runner received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// SIGINT (Ctrl-C).
    Interrupt,
    /// SIGTERM (`kill`).
    Terminate,
    /// SIGHUP (the terminal went away).
    Hangup,
}

impl Signal {
    fn from_raw(signo: i32) -> Option<Self> {
        match signo {
            libc::SIGINT => Some(Self::Interrupt),
            libc::SIGTERM => Some(Self::Terminate),
            libc::SIGHUP => Some(Self::Hangup),
            _ => None,
        }
    }

    /// The signal's number.
    pub fn number(self) -> i32 {
        match self {
            Self::Interrupt => libc::SIGINT,
            Self::Terminate => libc::SIGTERM,
            Self::Hangup => libc::SIGHUP,
        }
    }

    /// The signal's usual name, `SIGINT`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Interrupt => "SIGINT",
            Self::Terminate => "SIGTERM",
            Self::Hangup => "SIGHUP",
        }
    }

    /// What the runner sends its children: the same signal, except SIGHUP becomes SIGTERM,
    /// since iwsim's processes stop cleanly (removing their shared memory) on SIGINT and
    /// SIGTERM only; a SIGHUP would kill them where they stand.
    pub fn forwarded(self) -> i32 {
        match self {
            Self::Interrupt => libc::SIGINT,
            Self::Terminate | Self::Hangup => libc::SIGTERM,
        }
    }

    /// The exit code of a process stopped by this signal, as shells report it (128 + number).
    pub fn exit_code(self) -> u8 {
        (128 + self.number()) as u8
    }
}

/// Why the runner could not take over its termination signals.
#[derive(Debug, thiserror::Error)]
pub enum SignalsInstallError {
    /// `pthread_sigmask` refused to block SIGINT, SIGTERM and SIGHUP.
    #[error("blocking SIGINT, SIGTERM and SIGHUP: {0}")]
    Block(io::Error),
    /// The kernel gave no signalfd.
    #[error("opening a signalfd for SIGINT, SIGTERM and SIGHUP: {0}")]
    Open(io::Error),
}

/// SIGINT, SIGTERM and SIGHUP, blocked and read from a signalfd until this is dropped.
#[derive(Debug)]
pub struct Signals {
    fd: OwnedFd,
    previous: libc::sigset_t,
}

impl Signals {
    /// Blocks the three signals in the calling thread and opens a signalfd for them.
    ///
    /// Call it before the process starts any thread: threads inherit the mask of the thread
    /// that spawns them, and a thread with the signals unblocked would take them instead.
    #[allow(unsafe_code)] // the POSIX calls that have no safe wrapper in std
    pub fn install() -> Result<Self, SignalsInstallError> {
        // SAFETY: sigset_t is plain data that sigemptyset initialises; pthread_sigmask and
        // signalfd only read the set and write `previous`, both valid for the calls.
        unsafe {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            for s in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
                libc::sigaddset(&mut set, s);
            }
            let mut previous: libc::sigset_t = std::mem::zeroed();
            let rc = libc::pthread_sigmask(libc::SIG_BLOCK, &set, &mut previous);
            if rc != 0 {
                return Err(SignalsInstallError::Block(io::Error::from_raw_os_error(rc)));
            }
            let fd = libc::signalfd(-1, &set, libc::SFD_NONBLOCK | libc::SFD_CLOEXEC);
            if fd < 0 {
                let err = io::Error::last_os_error();
                libc::pthread_sigmask(libc::SIG_SETMASK, &previous, std::ptr::null_mut());
                return Err(SignalsInstallError::Open(err));
            }
            Ok(Self { fd: OwnedFd::from_raw_fd(fd), previous })
        }
    }

    /// The first signal received and not yet taken, waiting up to `timeout` for one.
    #[allow(unsafe_code)] // the POSIX calls that have no safe wrapper in std
    pub fn wait(&self, timeout: Duration) -> Option<Signal> {
        let mut pfd = libc::pollfd { fd: self.fd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
        let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd for the duration of the call.
        let _ = unsafe { libc::poll(&mut pfd, 1, ms) };
        self.take()
    }

    /// The first signal received and not yet taken, without waiting.
    #[allow(unsafe_code)] // the POSIX calls that have no safe wrapper in std
    pub fn take(&self) -> Option<Signal> {
        loop {
            // SAFETY: signalfd_siginfo is plain data; read writes at most its size into it.
            let mut info: libc::signalfd_siginfo = unsafe { std::mem::zeroed() };
            let size = std::mem::size_of::<libc::signalfd_siginfo>();
            // SAFETY: `info` is valid for `size` bytes for the duration of the call.
            let n = unsafe { libc::read(self.fd.as_raw_fd(), (&mut info as *mut libc::signalfd_siginfo).cast(), size) };
            if n != size as isize {
                return None;
            }
            if let Some(s) = Signal::from_raw(info.ssi_signo as i32) {
                return Some(s);
            }
        }
    }
}

impl Drop for Signals {
    #[allow(unsafe_code)] // the POSIX calls that have no safe wrapper in std
    fn drop(&mut self) {
        // SAFETY: restores the mask read at install; `previous` is a valid sigset_t.
        unsafe {
            libc::pthread_sigmask(libc::SIG_SETMASK, &self.previous, std::ptr::null_mut());
        }
    }
}

/// Sends `signal` to `child`, which is not reaped yet (so its pid is still its own).
#[allow(unsafe_code)] // kill(2): std sends only SIGKILL
pub fn send(child: &std::process::Child, signal: i32) {
    let pid = child.id() as libc::pid_t;
    // SAFETY: kill touches no memory of ours; the child is not reaped yet, so its pid cannot
    // have been given to another process.
    unsafe {
        libc::kill(pid, signal);
    }
}

/// Makes `command`'s child start with no signal blocked, whatever the runner blocks.
pub fn unblock_in_child(command: &mut std::process::Command) {
    use std::os::unix::process::CommandExt as _;
    #[allow(unsafe_code)]
    // SAFETY: the closure runs in the forked child before exec and only calls sigemptyset and
    // pthread_sigmask, both async-signal-safe; it allocates nothing and takes no lock.
    unsafe {
        command.pre_exec(|| {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            if libc::pthread_sigmask(libc::SIG_SETMASK, &set, std::ptr::null_mut()) != 0 {
                return Err(io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

pub use ipc_services::die_with_parent;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(unsafe_code)] // pthread_kill, to send this thread a signal
    fn a_signal_to_the_process_is_read_not_delivered() {
        let signals = Signals::install().expect("signalfd");
        assert_eq!(signals.take(), None);
        // SAFETY: sends SIGHUP to this thread, where it is blocked.
        unsafe {
            libc::pthread_kill(libc::pthread_self(), libc::SIGHUP);
        }
        let got = signals.wait(Duration::from_secs(5));
        assert_eq!(got, Some(Signal::Hangup));
        assert_eq!(got.map(Signal::forwarded), Some(libc::SIGTERM));
        assert_eq!(got.map(Signal::exit_code), Some(129));
        assert_eq!(signals.take(), None);
    }
}
