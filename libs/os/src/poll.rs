//! Waiting until one of several descriptors can be read (`poll(2)`, `ppoll(2)`).
//!
//! The descriptors come as raw numbers: iceoryx2's listeners, Zenoh doorbells and pidfds are
//! handed round as `RawFd`, owned elsewhere. A wait borrows them for the call only.

use std::io;
use std::os::fd::{BorrowedFd, RawFd};
use std::time::Duration;

use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags, PollTimeout};

/// What a wait found for one descriptor.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Revents {
    /// Bytes to read (`POLLIN`).
    pub input: bool,
    /// The other end hung up (`POLLHUP`).
    pub hangup: bool,
    /// An error is pending (`POLLERR`).
    pub error: bool,
    /// The descriptor is not open (`POLLNVAL`).
    pub invalid: bool,
}

impl Revents {
    /// A read would not block: input, end of file or an error for the read to report.
    pub fn readable(self) -> bool {
        self.input || self.hangup || self.error
    }

    /// Anything at all happened to the descriptor.
    pub fn any(self) -> bool {
        self.readable() || self.invalid
    }

    fn of(p: &PollFd<'_>) -> Self {
        let r = p.revents().unwrap_or(PollFlags::empty());
        Self {
            input: r.contains(PollFlags::POLLIN),
            hangup: r.contains(PollFlags::POLLHUP),
            error: r.contains(PollFlags::POLLERR),
            invalid: r.contains(PollFlags::POLLNVAL),
        }
    }
}

/// A poll set kept between waits, so a loop that waits every tick allocates nothing once warm.
#[derive(Debug, Default)]
pub struct Poller {
    /// Used only during [`Poller::wait`] and empty between calls: the borrows it holds never
    /// outlive the call that made them.
    pfds: Vec<PollFd<'static>>,
    /// Where each of the caller's descriptors is in `pfds` (`None` for a negative one).
    slots: Vec<Option<usize>>,
    revents: Vec<Revents>,
}

impl Poller {
    /// Waits until one of `fds` is readable (or hung up, in error or not open), `timeout`
    /// passes (`None`: for ever) or a signal arrives; how many descriptors are ready (0 on a
    /// timeout or a signal). Negative numbers are skipped, as `poll(2)` skips them.
    /// [`Poller::revents`] then says what each one had.
    ///
    /// Every descriptor in `fds` must be open for the duration of the call (one that is not
    /// reads as [`Revents::invalid`], or as another file opened under its number since).
    pub fn wait(&mut self, fds: &[RawFd], timeout: Option<Duration>) -> io::Result<usize> {
        self.pfds.clear();
        self.slots.clear();
        self.revents.clear();
        for &fd in fds {
            if fd < 0 {
                self.slots.push(None);
                continue;
            }
            #[allow(unsafe_code)]
            // SAFETY: `fd` is not -1 (checked above) and the caller keeps it open for this call;
            // the borrow lives in `pfds`, which is cleared before the call returns, so it
            // never outlives the call despite its 'static type.
            let borrowed = unsafe { BorrowedFd::borrow_raw(fd) };
            self.slots.push(Some(self.pfds.len()));
            self.pfds.push(PollFd::new(borrowed, PollFlags::POLLIN));
        }
        let result = nix::poll::poll(&mut self.pfds, poll_timeout(timeout));
        let pfds = &self.pfds;
        self.revents.extend(self.slots.iter().map(|s| s.map_or(Revents::default(), |k| Revents::of(&pfds[k]))));
        self.pfds.clear();
        match result {
            Ok(n) => Ok(n.max(0) as usize),
            Err(Errno::EINTR) => {
                self.revents.iter_mut().for_each(|r| *r = Revents::default());
                Ok(0)
            }
            Err(e) => Err(crate::io(e)),
        }
    }

    /// What the last wait found for the `i`th descriptor it was given.
    pub fn revents(&self, i: usize) -> Revents {
        self.revents.get(i).copied().unwrap_or_default()
    }

    /// The indexes of the descriptors the last wait found readable (or hung up, in error or
    /// not open), into `out`.
    pub fn ready_into(&self, out: &mut Vec<usize>) {
        out.clear();
        out.extend(self.revents.iter().enumerate().filter(|(_, r)| r.any()).map(|(i, _)| i));
    }
}

/// Waits until one of `fds` (up to [`SMALL`]; more are not waited on) is readable, `timeout`
/// passes (`None`: for ever) or a signal arrives; whether one became readable. Allocates
/// nothing: for loops that wait on a descriptor or two every tick.
///
/// Every descriptor in `fds` must be open for the duration of the call.
pub fn any_readable(fds: &[RawFd], timeout: Option<Duration>) -> io::Result<bool> {
    let mut got = [Revents::default(); SMALL];
    let n = wait_small(fds, timeout, &mut got)?;
    Ok(got[..n].iter().any(|r| r.any()))
}

/// How many descriptors [`any_readable`] and [`wait_small`] wait on at most.
pub const SMALL: usize = 4;

/// [`any_readable`] saying what each descriptor had, into `out` (as many as were waited on,
/// which it returns).
pub fn wait_small(fds: &[RawFd], timeout: Option<Duration>, out: &mut [Revents; SMALL]) -> io::Result<usize> {
    let n = fds.len().min(SMALL);
    *out = [Revents::default(); SMALL];
    // The open descriptors and where each is in `fds`.
    let mut open = [(0usize, -1 as RawFd); SMALL];
    let mut k = 0;
    for (i, &fd) in fds[..n].iter().enumerate() {
        if fd >= 0 {
            open[k] = (i, fd);
            k += 1;
        }
    }
    let borrow = |fd: RawFd| {
        #[allow(unsafe_code)]
        // SAFETY: only open descriptors' numbers reach here (never -1: negative ones were
        // left out above), which the caller keeps open for this call; the borrows live in
        // `pfds`, a local of this call.
        let b = unsafe { BorrowedFd::borrow_raw(fd) };
        PollFd::new(b, PollFlags::POLLIN)
    };
    let result = if k == 0 {
        nix::poll::poll(&mut [], poll_timeout(timeout))
    } else {
        // The array's tail repeats the last open descriptor but is not passed to the kernel.
        let mut pfds: [PollFd<'_>; SMALL] = std::array::from_fn(|j| borrow(open[j.min(k - 1)].1));
        let r = nix::poll::poll(&mut pfds[..k], poll_timeout(timeout));
        for (j, p) in pfds[..k].iter().enumerate() {
            out[open[j].0] = Revents::of(p);
        }
        r
    };
    match result {
        Ok(_) => Ok(n),
        Err(Errno::EINTR) => {
            *out = [Revents::default(); SMALL];
            Ok(n)
        }
        Err(e) => Err(crate::io(e)),
    }
}

/// Like [`any_readable`] for one descriptor, with the timeout to the nanosecond (`ppoll(2)`):
/// a signal ends the wait early (false), so a caller's stop flag is seen at once.
pub fn readable_within(fd: BorrowedFd<'_>, timeout: Duration) -> io::Result<bool> {
    let mut p = [PollFd::new(fd, PollFlags::POLLIN)];
    let ts = nix::sys::time::TimeSpec::from_duration(timeout);
    match nix::poll::ppoll(&mut p, Some(ts), None) {
        // POLLHUP/POLLERR count as readable: the read that follows says what is wrong.
        Ok(n) => Ok(n > 0 && Revents::of(&p[0]).any()),
        Err(Errno::EINTR) => Ok(false),
        Err(e) => Err(crate::io(e)),
    }
}

fn poll_timeout(t: Option<Duration>) -> PollTimeout {
    match t {
        None => PollTimeout::NONE,
        // Longer than poll(2) can say (24 days): as long as it can.
        Some(d) => PollTimeout::try_from(d).unwrap_or(PollTimeout::MAX),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write as _;
    use std::os::fd::AsRawFd as _;
    use std::os::unix::net::UnixStream;

    #[test]
    fn a_poller_says_which_descriptor_has_input_and_skips_negative_ones() {
        let (mut a, b) = UnixStream::pair().expect("pair");
        let (_c, d) = UnixStream::pair().expect("pair");
        let mut p = Poller::default();
        let fds = [d.as_raw_fd(), -1, b.as_raw_fd()];
        assert_eq!(p.wait(&fds, Some(Duration::ZERO)).expect("wait"), 0);
        a.write_all(b"x").expect("write");
        assert_eq!(p.wait(&fds, Some(Duration::from_secs(5))).expect("wait"), 1);
        assert!(p.revents(2).input && !p.revents(0).any() && !p.revents(1).any());
        let mut ready = Vec::new();
        p.ready_into(&mut ready);
        assert_eq!(ready, [2]);
    }

    #[test]
    fn a_small_wait_sees_input_and_a_hang_up_and_times_out_on_nothing() {
        let (mut a, b) = UnixStream::pair().expect("pair");
        let (c, d) = UnixStream::pair().expect("pair");
        assert!(!any_readable(&[b.as_raw_fd(), d.as_raw_fd()], Some(Duration::from_millis(1))).expect("wait"));
        a.write_all(b"x").expect("write");
        drop(c);
        let mut got = [Revents::default(); SMALL];
        assert_eq!(
            wait_small(&[-1, b.as_raw_fd(), d.as_raw_fd()], Some(Duration::from_secs(5)), &mut got).expect("wait"),
            3
        );
        assert!(!got[0].any() && got[1].input && got[2].hangup);
        assert!(readable_within(std::os::fd::AsFd::as_fd(&b), Duration::from_secs(5)).expect("ppoll"));
    }
}
