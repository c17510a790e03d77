//! The few terminal system calls the teleop needs: whether a descriptor is a terminal, raw
//! input mode (with a guard that puts the old mode back), `poll(2)` and a plain `read(2)`.
//! Every `unsafe` call of the crate outside [`crate::pty`] is here.

use std::io;
use std::os::fd::{AsRawFd, RawFd};
use std::time::Duration;

/// Whether `fd` is a terminal.
pub fn is_tty(fd: &impl AsRawFd) -> bool {
    #[allow(unsafe_code)]
    // SAFETY: isatty takes a descriptor number and touches no memory of ours.
    let r = unsafe { libc::isatty(fd.as_raw_fd()) };
    r == 1
}

/// The line-discipline flags a test cares about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LocalModes {
    /// Line editing (`ICANON`): input arrives a line at a time.
    pub canonical: bool,
    /// Typed characters are echoed (`ECHO`).
    pub echo: bool,
    /// Ctrl-C and friends raise signals (`ISIG`).
    pub signals: bool,
}

fn get_termios(fd: RawFd) -> io::Result<libc::termios> {
    let mut t: libc::termios = zeroed_termios();
    #[allow(unsafe_code)]
    // SAFETY: `t` is a live termios on our stack for the duration of the call.
    let r = unsafe { libc::tcgetattr(fd, &mut t) };
    if r != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(t)
}

fn set_termios(fd: RawFd, t: &libc::termios) -> io::Result<()> {
    #[allow(unsafe_code)]
    // SAFETY: `t` points to a valid termios for the duration of the call.
    let r = unsafe { libc::tcsetattr(fd, libc::TCSADRAIN, t) };
    if r != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

fn zeroed_termios() -> libc::termios {
    #[allow(unsafe_code)]
    // SAFETY: termios is a C struct of integers and integer arrays: all zeroes is a valid value.
    unsafe {
        std::mem::zeroed()
    }
}

/// The line-discipline flags of the terminal `fd`.
pub fn local_modes(fd: &impl AsRawFd) -> io::Result<LocalModes> {
    let t = get_termios(fd.as_raw_fd())?;
    Ok(LocalModes {
        canonical: t.c_lflag & libc::ICANON != 0,
        echo: t.c_lflag & libc::ECHO != 0,
        signals: t.c_lflag & libc::ISIG != 0,
    })
}

/// A terminal switched to key-at-a-time input; the original mode comes back when this is
/// dropped, which also happens while a panic unwinds.
#[derive(Debug)]
pub struct RawMode {
    fd: RawFd,
    saved: libc::termios,
}

impl RawMode {
    /// Switches the terminal `fd` to raw input: no line editing, no echo, no signal keys (so
    /// Ctrl-C arrives as byte 3 and the teleop can stop the chair and leave cleanly), no
    /// flow control (Ctrl-S would freeze the display). Output processing stays on, so `\n`
    /// still starts a new line.
    ///
    /// The descriptor must stay open for as long as the guard lives.
    pub fn enter(fd: &impl AsRawFd) -> io::Result<Self> {
        let fd = fd.as_raw_fd();
        let saved = get_termios(fd)?;
        let mut raw = saved;
        raw.c_lflag &= !(libc::ICANON | libc::ECHO | libc::ISIG | libc::IEXTEN);
        raw.c_iflag &= !(libc::IXON | libc::ICRNL);
        raw.c_cc[libc::VMIN] = 1;
        raw.c_cc[libc::VTIME] = 0;
        set_termios(fd, &raw)?;
        Ok(Self { fd, saved })
    }

    /// Puts the original mode back now (dropping the guard does the same).
    pub fn restore(&self) -> io::Result<()> {
        set_termios(self.fd, &self.saved)
    }
}

impl Drop for RawMode {
    fn drop(&mut self) {
        // Nothing better to do on failure: the terminal is likely gone.
        let _ = self.restore();
    }
}

/// What [`poll_readable`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ready {
    /// The first descriptor has input (or reached end of file / hung up).
    pub first: bool,
    /// The first descriptor is not open.
    pub first_invalid: bool,
    /// The second descriptor has input.
    pub second: bool,
}

/// Waits until `first` (if given) or `second` is readable, or `timeout` passes.
pub fn poll_readable(first: Option<RawFd>, second: RawFd, timeout: Duration) -> io::Result<Ready> {
    let mut fds = [
        libc::pollfd { fd: first.unwrap_or(-1), events: libc::POLLIN, revents: 0 },
        libc::pollfd { fd: second, events: libc::POLLIN, revents: 0 },
    ];
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    #[allow(unsafe_code)]
    // SAFETY: `fds` is a live array of two pollfd for the duration of the call (a negative fd
    // is ignored by poll).
    let n = unsafe { libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, ms) };
    if n < 0 {
        let e = io::Error::last_os_error();
        // A signal cut the wait short: report nothing ready, the caller checks for signals.
        return if e.kind() == io::ErrorKind::Interrupted { Ok(Ready::default()) } else { Err(e) };
    }
    let r0 = fds[0].revents;
    Ok(Ready {
        first: r0 & (libc::POLLIN | libc::POLLHUP | libc::POLLERR) != 0,
        first_invalid: r0 & libc::POLLNVAL != 0,
        second: fds[1].revents != 0,
    })
}

/// Reads what is waiting on `fd` (one `read(2)`); `Ok(0)` is end of file.
pub fn read_some(fd: RawFd, buf: &mut [u8]) -> io::Result<usize> {
    #[allow(unsafe_code)]
    // SAFETY: `buf` is a live, writable buffer of `buf.len()` bytes for the duration of the call.
    let n = unsafe { libc::read(fd, buf.as_mut_ptr().cast(), buf.len()) };
    if n < 0 { Err(io::Error::last_os_error()) } else { Ok(n as usize) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pty::Pty;

    #[test]
    fn raw_mode_switches_line_editing_off_and_its_drop_puts_it_back() {
        let pty = Pty::open().expect("a pseudo-terminal");
        let before = local_modes(pty.slave()).expect("termios");
        assert!(before.canonical && before.echo && before.signals, "{before:?}");
        let guard = RawMode::enter(pty.slave()).expect("raw mode");
        assert_eq!(
            local_modes(pty.slave()).expect("termios"),
            LocalModes { canonical: false, echo: false, signals: false }
        );
        drop(guard);
        assert_eq!(local_modes(pty.slave()).expect("termios"), before);
    }

    #[test]
    fn raw_mode_is_restored_when_a_panic_unwinds() {
        let pty = Pty::open().expect("a pseudo-terminal");
        let slave = pty.slave();
        let result = std::panic::catch_unwind(|| {
            let _guard = RawMode::enter(slave).expect("raw mode");
            assert!(!local_modes(slave).expect("termios").canonical);
            panic!("the driver loop failed");
        });
        assert!(result.is_err());
        let after = local_modes(pty.slave()).expect("termios");
        assert!(after.canonical && after.echo, "{after:?}");
    }

    #[test]
    fn a_pipe_is_not_a_tty_and_a_pty_is() {
        let pty = Pty::open().expect("a pseudo-terminal");
        assert!(is_tty(pty.slave()));
        let (r, _w) = std::io::pipe().expect("a pipe");
        assert!(!is_tty(&r));
    }

    #[test]
    fn poll_and_read_see_bytes_written_to_the_master() {
        use std::io::Write as _;
        let pty = Pty::open().expect("a pseudo-terminal");
        let _raw = RawMode::enter(pty.slave()).expect("raw mode");
        let fd = pty.slave().as_raw_fd();
        let (idle, _w) = std::io::pipe().expect("a pipe");
        let nothing = poll_readable(Some(fd), idle.as_raw_fd(), Duration::ZERO).expect("poll");
        assert_eq!(nothing, Ready::default());
        pty.master().expect("master").write_all(b"\x1b[A").expect("write");
        let ready = poll_readable(Some(fd), idle.as_raw_fd(), Duration::from_secs(5)).expect("poll");
        assert!(ready.first && !ready.second, "{ready:?}");
        let mut buf = [0u8; 16];
        let n = read_some(fd, &mut buf).expect("read");
        assert_eq!(&buf[..n], b"\x1b[A", "raw mode passes the sequence through at once");
    }
}
