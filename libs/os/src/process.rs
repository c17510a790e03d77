//! Process calls `std` does not make: a pidfd, reaping with the CPU time used, signals to a
//! child, the open-file limit.

use std::io;
use std::os::fd::{FromRawFd as _, OwnedFd};
use std::process::{Child, ExitStatus};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// A Linux pidfd of `pid` (readable once the process has exited); `None` where the kernel has
/// none (before 5.3) or the process is gone.
pub fn pidfd_open(pid: u32) -> Option<OwnedFd> {
    let pid = libc::pid_t::try_from(pid).ok()?;
    #[allow(unsafe_code)]
    // SAFETY: pidfd_open takes a pid and flags and returns a new descriptor or -1; no memory is
    // passed (nix has no wrapper for it).
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid, 0) };
    let fd = i32::try_from(fd).ok().filter(|&fd| fd >= 0)?;
    #[allow(unsafe_code)]
    // SAFETY: the descriptor was just returned by pidfd_open and is owned by nothing else.
    Some(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// How a reaped child ended and the CPU time (user and system, seconds) it used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reaped {
    /// Its exit status.
    pub status: ExitStatus,
    /// Its user and system CPU time, seconds.
    pub cpu_s: f64,
}

/// Reaps `child` if it has exited (with `block`, once it has), with its CPU time (`wait4(2)`:
/// std's wait does not give a child's resource use). `Ok(None)`: still running.
/// `Err`: not ours to wait for any more (reaped elsewhere).
pub fn reap(child: &Child, block: bool) -> io::Result<Option<Reaped>> {
    use std::os::unix::process::ExitStatusExt as _;
    let pid = child.id() as libc::pid_t;
    let mut raw = 0;
    let mut usage = zeroed_rusage();
    loop {
        #[allow(unsafe_code)]
        // SAFETY: wait4 writes only into the two locals it is given (nix has no wait4).
        let got = unsafe { libc::wait4(pid, &mut raw, if block { 0 } else { libc::WNOHANG }, &mut usage) };
        if got == pid {
            let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return Ok(Some(Reaped {
                status: ExitStatus::from_raw(raw),
                cpu_s: seconds(usage.ru_utime) + seconds(usage.ru_stime),
            }));
        }
        if got == 0 {
            return Ok(None);
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

fn zeroed_rusage() -> libc::rusage {
    #[allow(unsafe_code)]
    // SAFETY: rusage is a C struct of integers (and, on some targets, padding): all zeroes is
    // a value of it.
    unsafe {
        std::mem::zeroed()
    }
}

/// Sends signal number `signal` to `child`, which must not be reaped yet (so its pid is still
/// its own). A number that is no signal is ignored.
pub fn send(child: &Child, signal: i32) {
    if let Ok(s) = Signal::try_from(signal) {
        let _ = kill(Pid::from_raw(child.id() as libc::pid_t), s);
    }
}

/// Raises the soft open-file limit to the hard one (the hub holds about 11 descriptors per
/// agent); leaves it as it is if that fails.
pub fn raise_fd_limit() {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    if let Ok((soft, hard)) = getrlimit(Resource::RLIMIT_NOFILE)
        && soft < hard
    {
        let _ = setrlimit(Resource::RLIMIT_NOFILE, hard, hard);
    }
}

/// Makes `command`'s child get SIGTERM when this process ends (`PR_SET_PDEATHSIG`). A parent
/// that died between the fork and the child's `prctl` is caught by comparing the parent's
/// pid: the child then fails to start.
pub fn die_with_parent(command: &mut std::process::Command) {
    use std::os::unix::process::CommandExt as _;
    let parent = std::process::id();
    #[allow(unsafe_code)]
    // SAFETY: the closure runs in the forked child before exec and only calls prctl and
    // getppid, both plain system calls (async-signal-safe); it allocates nothing and takes no
    // lock.
    unsafe {
        command.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong) != 0 {
                return Err(io::Error::last_os_error());
            }
            if libc::getppid() as u32 != parent {
                return Err(io::Error::other("the parent died as the process started"));
            }
            Ok(())
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reaped_child_says_how_it_ended_and_its_pidfd_was_readable() {
        let child = std::process::Command::new("sh").args(["-c", "exit 3"]).spawn().expect("sh");
        let fd = pidfd_open(child.id()).expect("a pidfd");
        let raw = std::os::fd::AsRawFd::as_raw_fd(&fd);
        assert!(crate::poll::any_readable(&[raw], Some(std::time::Duration::from_secs(10))).expect("poll"));
        let r = reap(&child, true).expect("ours").expect("exited");
        assert_eq!(r.status.code(), Some(3));
        assert!(r.cpu_s >= 0.0);
        assert!(reap(&child, false).is_err(), "reaped already");
        // std's own wait on a child reaped elsewhere fails and leaves nothing behind.
        let mut child = child;
        assert!(child.wait().is_err());
    }
}
