//! The teleop's terminal: raw input mode (with a guard that puts the old mode back), waiting
//! on the keyboard and the hub's tick at once, and a plain read, on iwsim's OS layer (`os`).

use std::io;
use std::os::fd::{AsFd, OwnedFd, RawFd};
use std::time::Duration;

pub use os::term::is_tty;
use os::term::termios::{self, InputFlags, LocalFlags, SetArg, SpecialCharacterIndices, Termios};

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

/// The line-discipline flags of the terminal `fd`.
pub fn local_modes(fd: impl AsFd) -> io::Result<LocalModes> {
    let t = termios::tcgetattr(fd).map_err(io::Error::from)?;
    Ok(LocalModes {
        canonical: t.local_flags.contains(LocalFlags::ICANON),
        echo: t.local_flags.contains(LocalFlags::ECHO),
        signals: t.local_flags.contains(LocalFlags::ISIG),
    })
}

/// A terminal switched to key-at-a-time input; the original mode comes back when this is
/// dropped, which also happens while a panic unwinds.
#[derive(Debug)]
pub struct RawMode {
    /// Its own descriptor of the terminal, so the mode can be put back whatever the caller
    /// did with the one it passed.
    fd: OwnedFd,
    saved: Termios,
}

impl RawMode {
    /// Switches the terminal `fd` to raw input: no line editing, no echo, no signal keys (so
    /// Ctrl-C arrives as byte 3 and the teleop can stop the chair and leave cleanly), no
    /// flow control (Ctrl-S would freeze the display). Output processing stays on, so `\n`
    /// still starts a new line.
    pub fn enter(fd: impl AsFd) -> io::Result<Self> {
        let fd = fd.as_fd().try_clone_to_owned()?;
        let saved = termios::tcgetattr(&fd).map_err(io::Error::from)?;
        let mut raw = saved.clone();
        raw.local_flags &= !(LocalFlags::ICANON | LocalFlags::ECHO | LocalFlags::ISIG | LocalFlags::IEXTEN);
        raw.input_flags &= !(InputFlags::IXON | InputFlags::ICRNL);
        raw.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
        raw.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
        termios::tcsetattr(&fd, SetArg::TCSADRAIN, &raw).map_err(io::Error::from)?;
        Ok(Self { fd, saved })
    }

    /// Puts the original mode back now (dropping the guard does the same).
    pub fn restore(&self) -> io::Result<()> {
        termios::tcsetattr(&self.fd, SetArg::TCSADRAIN, &self.saved).map_err(io::Error::from)
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

/// Waits until `first` (if given) or `second` is readable, or `timeout` passes (a signal
/// ends the wait with nothing ready: the caller checks for signals).
pub fn poll_readable(first: Option<RawFd>, second: RawFd, timeout: Duration) -> io::Result<Ready> {
    let mut got = [os::poll::Revents::default(); os::poll::SMALL];
    os::poll::wait_small(&[first.unwrap_or(-1), second], Some(timeout), &mut got)?;
    Ok(Ready { first: got[0].readable(), first_invalid: got[0].invalid, second: got[1].any() })
}

/// Reads what is waiting on `fd` (one `read(2)`); `Ok(0)` is end of file.
pub fn read_some(fd: impl AsFd, buf: &mut [u8]) -> io::Result<usize> {
    os::fd::read(fd, buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use os::pty::Pty;
    use std::os::fd::AsRawFd as _;

    #[test]
    fn raw_mode_switches_line_editing_off_and_its_drop_puts_it_back() {
        let pty = Pty::open(Some(crate::view::TERMINAL_SIZE)).expect("a pseudo-terminal");
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
        let pty = Pty::open(Some(crate::view::TERMINAL_SIZE)).expect("a pseudo-terminal");
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
        let pty = Pty::open(Some(crate::view::TERMINAL_SIZE)).expect("a pseudo-terminal");
        assert!(is_tty(pty.slave()));
        let (r, _w) = std::io::pipe().expect("a pipe");
        assert!(!is_tty(&r));
    }

    #[test]
    fn poll_and_read_see_bytes_written_to_the_master() {
        use std::io::Write as _;
        let pty = Pty::open(Some(crate::view::TERMINAL_SIZE)).expect("a pseudo-terminal");
        let _raw = RawMode::enter(pty.slave()).expect("raw mode");
        let fd = pty.slave().as_raw_fd();
        let (idle, _w) = std::io::pipe().expect("a pipe");
        let nothing = poll_readable(Some(fd), idle.as_raw_fd(), Duration::ZERO).expect("poll");
        assert_eq!(nothing, Ready::default());
        pty.master().expect("master").write_all(b"\x1b[A").expect("write");
        let ready = poll_readable(Some(fd), idle.as_raw_fd(), Duration::from_secs(5)).expect("poll");
        assert!(ready.first && !ready.second, "{ready:?}");
        let mut buf = [0u8; 16];
        let n = read_some(pty.slave(), &mut buf).expect("read");
        assert_eq!(&buf[..n], b"\x1b[A", "raw mode passes the sequence through at once");
    }
}
