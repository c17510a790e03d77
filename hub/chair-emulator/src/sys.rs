//! The few system calls the emulator needs: the monotonic clock, pseudo-terminals, raw serial
//! modes and baud rates, `ppoll(2)`. Every `unsafe` block of the crate is here.

use std::fs::File;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd as _, OwnedFd, RawFd};
use std::path::PathBuf;
use std::time::Duration;

/// CLOCK_MONOTONIC in nanoseconds: comparable across processes on one machine (a test reading
/// the truth log compares it with its own clock).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    #[allow(unsafe_code)]
    // SAFETY: `ts` is a live timespec on our stack for the duration of the call.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if r != 0 {
        // CLOCK_MONOTONIC exists on every Linux; were the call to fail, 0 keeps time standing
        // rather than panicking.
        return 0;
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64)
}

fn check(r: libc::c_int) -> io::Result<()> {
    if r < 0 { Err(io::Error::last_os_error()) } else { Ok(()) }
}

fn set_cloexec(fd: RawFd) -> io::Result<()> {
    #[allow(unsafe_code)]
    // SAFETY: sets a flag of a descriptor we own; no memory is passed.
    check(unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) })
}

/// Makes reads and writes of `fd` return `WouldBlock` instead of waiting.
pub fn set_nonblocking(fd: &impl AsRawFd) -> io::Result<()> {
    let fd = fd.as_raw_fd();
    #[allow(unsafe_code)]
    // SAFETY: reads a descriptor's flags; no memory is passed.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    check(flags)?;
    #[allow(unsafe_code)]
    // SAFETY: sets a descriptor's flags; no memory is passed.
    check(unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) })
}

fn zeroed_termios() -> libc::termios {
    #[allow(unsafe_code)]
    // SAFETY: termios is a C struct of integers and integer arrays: all zeroes is a valid value.
    unsafe {
        std::mem::zeroed()
    }
}

/// Puts the terminal `fd` in raw mode (`cfmakeraw`: 8 data bits, no parity, no echo, no line
/// editing, no translation of any byte), receiver on, modem lines ignored, reads returning what
/// is there; with `baud`, also sets the line speed both ways.
pub fn make_raw(fd: &impl AsRawFd, baud: Option<u32>) -> io::Result<()> {
    let fd = fd.as_raw_fd();
    let mut t = zeroed_termios();
    #[allow(unsafe_code)]
    // SAFETY: `t` is a live termios for the duration of the call.
    check(unsafe { libc::tcgetattr(fd, &mut t) })?;
    #[allow(unsafe_code)]
    // SAFETY: cfmakeraw only edits the termios it is given.
    unsafe {
        libc::cfmakeraw(&mut t);
    }
    t.c_cflag |= libc::CLOCAL | libc::CREAD;
    t.c_cflag &= !(libc::CSTOPB | libc::CRTSCTS);
    t.c_cc[libc::VMIN] = 1;
    t.c_cc[libc::VTIME] = 0;
    if let Some(baud) = baud {
        let speed = speed_constant(baud).ok_or_else(|| {
            io::Error::new(io::ErrorKind::InvalidInput, format!("{baud} baud is not a standard rate of this system"))
        })?;
        #[allow(unsafe_code)]
        // SAFETY: cfsetispeed/cfsetospeed only edit the termios they are given.
        unsafe {
            check(libc::cfsetispeed(&mut t, speed))?;
            check(libc::cfsetospeed(&mut t, speed))?;
        }
    }
    #[allow(unsafe_code)]
    // SAFETY: `t` is a valid termios for the duration of the call.
    check(unsafe { libc::tcsetattr(fd, libc::TCSANOW, &t) })
}

/// The termios speed constant of a standard baud rate.
fn speed_constant(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        1200 => libc::B1200,
        2400 => libc::B2400,
        4800 => libc::B4800,
        9600 => libc::B9600,
        19200 => libc::B19200,
        38400 => libc::B38400,
        57600 => libc::B57600,
        115200 => libc::B115200,
        230400 => libc::B230400,
        460800 => libc::B460800,
        921600 => libc::B921600,
        1_000_000 => libc::B1000000,
        2_000_000 => libc::B2000000,
        _ => return None,
    })
}

/// Discards what the terminal `fd` has received but nobody has read yet.
pub fn flush_input(fd: &impl AsRawFd) -> io::Result<()> {
    #[allow(unsafe_code)]
    // SAFETY: tcflush takes a descriptor and a constant; no memory is passed.
    check(unsafe { libc::tcflush(fd.as_raw_fd(), libc::TCIFLUSH) })
}

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
    let (mut master, mut slave) = (-1, -1);
    #[allow(unsafe_code)]
    // SAFETY: openpty writes two descriptors into the ints passed; the name buffer, termios and
    // window size are null (not wanted; the name comes from ttyname_r below, which is bounded).
    let r = unsafe { libc::openpty(&mut master, &mut slave, std::ptr::null_mut(), std::ptr::null(), std::ptr::null()) };
    check(r)?;
    #[allow(unsafe_code)]
    // SAFETY: both descriptors were just returned by openpty and are owned by nothing else.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    set_cloexec(master.as_raw_fd())?;
    set_cloexec(slave.as_raw_fd())?;
    make_raw(&slave, None)?;
    set_nonblocking(&master)?;
    let mut name = [0 as libc::c_char; 128];
    #[allow(unsafe_code)]
    // SAFETY: ttyname_r writes at most `name.len()` bytes, NUL included, into `name`.
    let r = unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) };
    if r != 0 {
        return Err(io::Error::from_raw_os_error(r));
    }
    let bytes: Vec<u8> = name.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    let path = PathBuf::from(String::from_utf8_lossy(&bytes).into_owned());
    Ok(PtyPair { master: File::from(master), slave, path })
}

/// Waits until `fd` has bytes to read (true) or `timeout` passes (false). A signal ends the
/// wait early (false), so a caller's stop flag is seen at once.
pub fn wait_readable(fd: &impl AsRawFd, timeout: Duration) -> io::Result<bool> {
    let mut pfd = libc::pollfd { fd: fd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
    let ts =
        libc::timespec { tv_sec: timeout.as_secs() as libc::time_t, tv_nsec: timeout.subsec_nanos() as libc::c_long };
    #[allow(unsafe_code)]
    // SAFETY: one live pollfd and a live timespec for the duration of the call; no signal mask.
    let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if r < 0 {
        let e = io::Error::last_os_error();
        return if e.kind() == io::ErrorKind::Interrupted { Ok(false) } else { Err(e) };
    }
    // POLLHUP/POLLERR count as readable: the read that follows says what is wrong.
    Ok(r > 0 && pfd.revents != 0)
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

/// Makes SIGUSR1 and SIGUSR2 count into [`FAULTS`] instead of killing the process.
pub fn install_fault_signals() -> io::Result<()> {
    for signo in [libc::SIGUSR1, libc::SIGUSR2] {
        #[allow(unsafe_code)]
        // SAFETY: a zeroed sigaction whose handler only does an atomic add; the emulator's
        // ppoll returns EINTR on the signal, so the loop sees the count at once.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_fault_signal as *const () as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(signo, &sa, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    Ok(())
}
