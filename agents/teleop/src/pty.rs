//! A pseudo-terminal pair, for driving the teleop (or any terminal program) from a test or a
//! script as if a person sat at a terminal: the program gets the slave side as its
//! controlling terminal, the driver writes keys to and reads the screen from the master.
//!
//! ```no_run
//! use std::io::Write as _;
//! use teleop::pty::Pty;
//!
//! let pty = Pty::open().expect("a pseudo-terminal");
//! let mut cmd = std::process::Command::new("iwsim");
//! cmd.args(["agent", "teleop", "--session", "demo"]);
//! pty.attach(&mut cmd).expect("stdio on the slave");
//! let mut child = cmd.spawn().expect("started");
//! pty.master().expect("master").write_all(b"ww q").expect("keys");
//! child.wait().expect("exited");
//! ```

use std::fs::File;
use std::io;
use std::os::fd::{AsRawFd as _, FromRawFd as _, OwnedFd};
use std::process::{Command, Stdio};

/// Rows and columns the pair starts with (a classic terminal).
pub const SIZE: (u16, u16) = (24, 80);

/// Both ends of a pseudo-terminal.
#[derive(Debug)]
pub struct Pty {
    master: OwnedFd,
    slave: OwnedFd,
}

impl Pty {
    /// Opens a pair with the system's default terminal modes (line editing and echo on) and a
    /// 24 × 80 window.
    pub fn open() -> io::Result<Self> {
        let (mut master, mut slave) = (-1, -1);
        let size = libc::winsize { ws_row: SIZE.0, ws_col: SIZE.1, ws_xpixel: 0, ws_ypixel: 0 };
        #[allow(unsafe_code)]
        // SAFETY: openpty writes two descriptors into the ints passed; the name buffer is null
        // (not wanted), the termios is null (defaults) and the winsize is a live struct.
        let r = unsafe { libc::openpty(&mut master, &mut slave, std::ptr::null_mut(), std::ptr::null(), &size) };
        if r != 0 {
            return Err(io::Error::last_os_error());
        }
        #[allow(unsafe_code)]
        // SAFETY: both descriptors were just returned by openpty and are owned by nothing else.
        let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
        for fd in [&master, &slave] {
            #[allow(unsafe_code)]
            // SAFETY: sets the close-on-exec flag of a descriptor we own; no memory is passed.
            unsafe {
                libc::fcntl(fd.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
            }
        }
        Ok(Self { master, slave })
    }

    /// The master side, to write keys to and read the screen from (a new descriptor each
    /// call, so a reader thread and a writer can each own one).
    pub fn master(&self) -> io::Result<File> {
        Ok(File::from(self.master.try_clone()?))
    }

    /// The slave side: what the program sees as its terminal. Keep it to inspect the
    /// terminal's modes after the program has gone ([`crate::term::local_modes`]).
    pub fn slave(&self) -> &OwnedFd {
        &self.slave
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
        // ioctl, which are async-signal-safe; it allocates nothing and touches no lock. Stdio is
        // already in place when it runs, so fd 0 is the slave.
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
    fn bytes_written_to_the_master_are_read_on_the_slave_with_the_default_modes() {
        let pty = Pty::open().expect("a pseudo-terminal");
        let modes = crate::term::local_modes(pty.slave()).expect("termios");
        assert!(modes.canonical && modes.echo, "{modes:?}");
        pty.master().expect("master").write_all(b"hello\n").expect("write");
        let mut slave = File::from(pty.slave().try_clone().expect("dup"));
        let mut buf = [0u8; 16];
        let n = slave.read(&mut buf).expect("read");
        assert_eq!(&buf[..n], b"hello\n");
    }

    #[test]
    fn an_attached_child_has_the_slave_as_its_controlling_terminal() {
        let pty = Pty::open().expect("a pseudo-terminal");
        let mut cmd = Command::new("sh");
        // `tty` names the terminal on stdin; `ps -o tty=` would need procps, so read /proc.
        cmd.args(["-c", "test -t 0 && test -t 1 && readlink /proc/self/fd/0 && cat /proc/self/stat"]);
        pty.attach(&mut cmd).expect("attach");
        let mut child = cmd.spawn().expect("sh starts");
        let status = child.wait().expect("sh exits");
        assert!(status.success());
        // The child's output is waiting on the master.
        let mut master = pty.master().expect("master");
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        while !String::from_utf8_lossy(&out).contains(')') || !out.ends_with(b"\n") {
            let n = master.read(&mut buf).expect("read");
            out.extend_from_slice(&buf[..n]);
        }
        let text = String::from_utf8_lossy(&out);
        assert!(text.contains("/dev/pts/"), "{text}");
        // Field 7 of /proc/PID/stat is tty_nr: non-zero when the process has a controlling tty.
        let stat = text.lines().find(|l| l.contains(") ")).expect("stat line");
        let after_name = stat.rsplit(") ").next().expect("fields");
        let tty_nr: i64 = after_name.split_whitespace().nth(4).expect("tty_nr").parse().expect("number");
        assert_ne!(tty_nr, 0, "{stat}");
    }
}
