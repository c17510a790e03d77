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
pub struct Signals(os::signals::Blocked);

impl Signals {
    /// Blocks the three signals in the calling thread and opens a signalfd for them.
    ///
    /// Call it before the process starts any thread: threads inherit the mask of the thread
    /// that spawns them, and a thread with the signals unblocked would take them instead.
    pub fn install() -> Result<Self, SignalsInstallError> {
        match os::signals::Blocked::install(&[libc::SIGINT, libc::SIGTERM, libc::SIGHUP]) {
            Ok(b) => Ok(Self(b)),
            Err((true, e)) => Err(SignalsInstallError::Block(e)),
            Err((false, e)) => Err(SignalsInstallError::Open(e)),
        }
    }

    /// The first signal received and not yet taken, waiting up to `timeout` for one.
    pub fn wait(&self, timeout: Duration) -> Option<Signal> {
        self.0.wait(timeout).and_then(Signal::from_raw)
    }

    /// The first signal received and not yet taken, without waiting.
    pub fn take(&self) -> Option<Signal> {
        self.0.take().and_then(Signal::from_raw)
    }
}

/// Sends `signal` to `child`, which is not reaped yet (so its pid is still its own).
pub fn send(child: &std::process::Child, signal: i32) {
    os::process::send(child, signal);
}

/// Makes `command`'s child start with no signal blocked, whatever the runner blocks.
pub fn unblock_in_child(command: &mut std::process::Command) {
    os::signals::unblock_in_child(command);
}

pub use ipc_services::die_with_parent;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signal_to_the_process_is_read_not_delivered() {
        let signals = Signals::install().expect("signalfd");
        assert_eq!(signals.take(), None);
        // To this thread, where it is blocked.
        os::signals::raise(libc::SIGHUP).expect("raise");
        let got = signals.wait(Duration::from_secs(5));
        assert_eq!(got, Some(Signal::Hangup));
        assert_eq!(got.map(Signal::forwarded), Some(libc::SIGTERM));
        assert_eq!(got.map(Signal::exit_code), Some(129));
        assert_eq!(signals.take(), None);
    }
}
