//! The emulator's system calls, on iwsim's OS layer (`os`): the monotonic clock, its
//! pseudo-terminal, raw serial modes and baud rates, waiting for bytes, fault signals.

use std::fs::File;
use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::path::PathBuf;
use std::time::Duration;

pub use os::clock::monotonic_ns;
pub use os::fd::set_nonblocking;
pub use os::term::{flush_input, make_raw};

/// A pseudo-terminal pair: the master (the emulator's end) and the slave (the end a host opens
/// by its path, as it would a serial port).
#[derive(Debug)]
pub struct PtyPair {
    /// The emulator's end, non-blocking.
    pub master: File,
    /// The slave, kept open by the emulator: while one descriptor of the slave is open, the
    /// master never reads EIO, so a host can close the port and open it again.
    pub slave: OwnedFd,
    /// The slave's path, e.g. `/dev/pts/7`.
    pub path: PathBuf,
}

/// Opens a pseudo-terminal pair with the slave in raw mode, so bytes pass untouched.
pub fn open_pty() -> io::Result<PtyPair> {
    let pty = os::pty::Pty::open(None)?;
    let path = pty.path()?;
    let (master, slave) = pty.into_parts();
    make_raw(&slave, None)?;
    set_nonblocking(&master)?;
    Ok(PtyPair { master: File::from(master), slave, path })
}

/// Waits until `fd` has bytes to read (true) or `timeout` passes (false). A signal ends the
/// wait early (false), so a caller's stop flag is seen at once.
pub fn wait_readable(fd: &impl AsFd, timeout: Duration) -> io::Result<bool> {
    os::poll::readable_within(fd.as_fd(), timeout)
}

/// Test-bench faults asked for by signal: how many SIGUSR1 (toggle a mute transmit line) and
/// SIGUSR2 (send a burst of garbage) arrived. The emulator's loop compares them with what it
/// has handled; counters, not flags, so two quick signals are two faults.
#[derive(Debug, Default)]
pub struct FaultSignals {
    /// SIGUSR1s received.
    pub mute_toggles: std::sync::atomic::AtomicU32,
    /// SIGUSR2s received.
    pub bursts: std::sync::atomic::AtomicU32,
}

/// The one set of counters the signal handlers bump.
pub static FAULTS: FaultSignals =
    FaultSignals { mute_toggles: std::sync::atomic::AtomicU32::new(0), bursts: std::sync::atomic::AtomicU32::new(0) };

extern "C" fn on_fault_signal(signo: libc::c_int) {
    // Only an atomic add: all a signal handler may safely do here.
    let counter = if signo == libc::SIGUSR1 { &FAULTS.mute_toggles } else { &FAULTS.bursts };
    counter.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
}

/// Makes SIGUSR1 and SIGUSR2 count into [`FAULTS`] instead of killing the process; they end
/// the emulator's wait for bytes (no `SA_RESTART`), so the loop sees the count at once.
pub fn install_fault_signals() -> io::Result<()> {
    os::signals::on_signals(&[libc::SIGUSR1, libc::SIGUSR2], on_fault_signal, false)
}
