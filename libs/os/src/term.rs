//! Terminals and serial lines: whether a descriptor is one, raw modes, line speeds.
//!
//! `termios` is nix's (safe) termios, for callers with modes of their own to set.

use std::io;
use std::os::fd::AsFd;

pub use nix::sys::termios;
use termios::{BaudRate, ControlFlags, FlushArg, SetArg, SpecialCharacterIndices};

/// Whether `fd` is a terminal.
pub fn is_tty(fd: impl AsFd) -> bool {
    nix::unistd::isatty(fd).unwrap_or(false)
}

/// Puts the terminal `fd` in raw mode (`cfmakeraw`: 8 data bits, no parity, no echo, no line
/// editing, no translation of any byte), receiver on, modem lines ignored, reads returning what
/// is there; with `baud`, also sets the line speed both ways.
pub fn make_raw(fd: impl AsFd, baud: Option<u32>) -> io::Result<()> {
    let fd = fd.as_fd();
    let mut t = termios::tcgetattr(fd).map_err(crate::io)?;
    termios::cfmakeraw(&mut t);
    t.control_flags |= ControlFlags::CLOCAL | ControlFlags::CREAD;
    t.control_flags &= !(ControlFlags::CSTOPB | ControlFlags::CRTSCTS);
    t.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
    t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
    if let Some(baud) = baud {
        let speed = baud_rate(baud).ok_or_else(|| {
            io::Error::new(io::ErrorKind::InvalidInput, format!("{baud} baud is not a standard rate of this system"))
        })?;
        termios::cfsetispeed(&mut t, speed).map_err(crate::io)?;
        termios::cfsetospeed(&mut t, speed).map_err(crate::io)?;
    }
    termios::tcsetattr(fd, SetArg::TCSANOW, &t).map_err(crate::io)
}

/// The termios speed of a standard baud rate.
fn baud_rate(baud: u32) -> Option<BaudRate> {
    Some(match baud {
        1200 => BaudRate::B1200,
        2400 => BaudRate::B2400,
        4800 => BaudRate::B4800,
        9600 => BaudRate::B9600,
        19200 => BaudRate::B19200,
        38400 => BaudRate::B38400,
        57600 => BaudRate::B57600,
        115200 => BaudRate::B115200,
        230400 => BaudRate::B230400,
        460800 => BaudRate::B460800,
        921600 => BaudRate::B921600,
        1_000_000 => BaudRate::B1000000,
        2_000_000 => BaudRate::B2000000,
        _ => return None,
    })
}

/// Discards what the terminal `fd` has received but nobody has read yet.
pub fn flush_input(fd: impl AsFd) -> io::Result<()> {
    termios::tcflush(fd, FlushArg::TCIFLUSH).map_err(crate::io)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_mode_at_a_baud_rate_sticks_and_an_odd_rate_is_refused() {
        let pty = crate::pty::Pty::open(None).expect("pty");
        assert!(is_tty(pty.slave()));
        make_raw(pty.slave(), Some(115200)).expect("raw");
        let t = termios::tcgetattr(pty.slave()).expect("termios");
        assert!(!t.local_flags.contains(termios::LocalFlags::ICANON | termios::LocalFlags::ECHO));
        assert_eq!(termios::cfgetospeed(&t), BaudRate::B115200);
        let e = make_raw(pty.slave(), Some(12345)).expect_err("not a rate");
        assert!(e.to_string().contains("12345 baud"), "{e}");
        flush_input(pty.slave()).expect("flush");
        let file = tempfile_like();
        assert!(!is_tty(&file));
    }

    fn tempfile_like() -> std::fs::File {
        std::fs::File::open("/proc/self/stat").expect("a file that is no terminal")
    }
}
