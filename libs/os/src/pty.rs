//! Pseudo-terminal pairs: the chair emulator's serial port (a host opens the slave by its
//! path), and a terminal for driving a terminal program from a test or a script.

use std::fs::File;
use std::io;
use std::os::fd::OwnedFd;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use nix::pty::{Winsize, openpty};

/// Both ends of a pseudo-terminal, closed in any program this process starts.
#[derive(Debug)]
pub struct Pty {
    master: OwnedFd,
    slave: OwnedFd,
}

impl Pty {
    /// Opens a pair with the system's default terminal modes (line editing and echo on) and a
    /// window of `size` (rows, columns), if given.
    pub fn open(size: Option<(u16, u16)>) -> io::Result<Self> {
        let ws = size.map(|(ws_row, ws_col)| Winsize { ws_row, ws_col, ws_xpixel: 0, ws_ypixel: 0 });
        let pair = openpty(ws.as_ref(), None).map_err(crate::io)?;
        crate::fd::set_cloexec(&pair.master)?;
        crate::fd::set_cloexec(&pair.slave)?;
        Ok(Self { master: pair.master, slave: pair.slave })
    }

    /// The master side (the driver's end: write keys, read the screen; or the emulator's end
    /// of its serial line), a new descriptor each call.
    pub fn master(&self) -> io::Result<File> {
        Ok(File::from(self.master.try_clone()?))
    }

    /// The slave side: what a program sees as its terminal, or a host as its serial port.
    pub fn slave(&self) -> &OwnedFd {
        &self.slave
    }

    /// Both ends, for a caller that keeps them apart.
    pub fn into_parts(self) -> (OwnedFd, OwnedFd) {
        (self.master, self.slave)
    }

    /// The slave's path, e.g. `/dev/pts/7`.
    pub fn path(&self) -> io::Result<PathBuf> {
        nix::unistd::ttyname(&self.slave).map_err(crate::io)
    }

    /// Gives `cmd` the slave as stdin, stdout and stderr, and makes it the child's
    /// controlling terminal in a session of its own (as a terminal emulator or tmux does).
    pub fn attach(&self, cmd: &mut Command) -> io::Result<()> {
        cmd.stdin(Stdio::from(self.slave.try_clone()?))
            .stdout(Stdio::from(self.slave.try_clone()?))
            .stderr(Stdio::from(self.slave.try_clone()?));
        use std::os::unix::process::CommandExt as _;
        #[allow(unsafe_code)]
        // SAFETY: the closure runs in the forked child before exec and calls only setsid and
        // ioctl, which are async-signal-safe; it allocates nothing and touches no lock. Stdio
        // is already in place when it runs, so fd 0 is the slave.
        unsafe {
            cmd.pre_exec(|| {
                if libc::setsid() < 0 || libc::ioctl(0, libc::TIOCSCTTY, 0) < 0 {
                    return Err(io::Error::last_os_error());
                }
                Ok(())
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read as _, Write as _};

    #[test]
    fn bytes_written_to_the_master_are_read_on_the_slave_whose_path_is_a_pts() {
        let pty = Pty::open(Some((24, 80))).expect("a pseudo-terminal");
        assert!(pty.path().expect("ttyname").starts_with("/dev/pts/"));
        pty.master().expect("master").write_all(b"hello\n").expect("write");
        let mut slave = File::from(pty.slave().try_clone().expect("dup"));
        let mut buf = [0u8; 16];
        let n = slave.read(&mut buf).expect("read");
        assert_eq!(&buf[..n], b"hello\n");
    }
}
