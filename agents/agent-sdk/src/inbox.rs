//! What other threads (Zenoh's callbacks) hand a loop that also waits on the hub's tick: events
//! in arrival order, and a socket that rings the loop for each, so that one `poll(2)` waits for
//! both. The Zenoh and ROS 2 bridges are such loops.

use std::collections::VecDeque;
use std::io::{self, Read as _, Write as _};
use std::os::fd::{AsRawFd as _, RawFd};
use std::os::unix::net::UnixStream;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The threads' end: events pushed here wait for the loop.
#[derive(Debug)]
pub struct Inbox<E> {
    queue: Mutex<VecDeque<E>>,
    ring: UnixStream,
    bound: usize,
}

/// The loop's end: rings when an event came.
#[derive(Debug)]
pub struct Doorbell {
    wake: UnixStream,
}

/// An inbox that keeps at most `bound` events (a flood waits, or is dropped, in the sender's own
/// queues, not here), and the doorbell it rings.
pub fn inbox<E>(bound: usize) -> io::Result<(Arc<Inbox<E>>, Doorbell)> {
    let (wake, ring) = UnixStream::pair()?;
    for s in [&wake, &ring] {
        s.set_nonblocking(true)?;
    }
    Ok((Arc::new(Inbox { queue: Mutex::new(VecDeque::new()), ring, bound }), Doorbell { wake }))
}

impl<E> Inbox<E> {
    /// Adds `e` (dropped when the inbox is full) and rings the doorbell; whether it was kept.
    pub fn push(&self, e: E) -> bool {
        let mut q = self.queue.lock().unwrap_or_else(|p| p.into_inner());
        let kept = q.len() < self.bound;
        if kept {
            q.push_back(e);
        }
        drop(q);
        // A full socket buffer already rings: the loop drains it whole.
        let _ = (&self.ring).write(&[1]);
        kept
    }

    /// The oldest event.
    pub fn take(&self) -> Option<E> {
        self.queue.lock().unwrap_or_else(|p| p.into_inner()).pop_front()
    }
}

impl Doorbell {
    /// Waits until the inbox rang, `also` (the hub's tick) is readable, or `timeout` passes
    /// (a signal also ends the wait); then clears the rings.
    pub fn wait(&self, also: Option<RawFd>, timeout: Duration) {
        let wake = self.wake.as_raw_fd();
        match also {
            Some(fd) => crate::poll_readable(&[fd, wake], timeout),
            None => crate::poll_readable(&[wake], timeout),
        };
        let mut drained = [0u8; 256];
        while matches!((&self.wake).read(&mut drained), Ok(n) if n > 0) {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    #[test]
    fn a_push_from_another_thread_ends_a_long_wait_and_events_come_in_order() {
        let (inbox, bell) = inbox::<u32>(8).expect("an inbox");
        let sender = inbox.clone();
        let t0 = Instant::now();
        let pusher = std::thread::spawn(move || {
            for i in 0..3 {
                sender.push(i);
            }
        });
        // However late the pusher runs, the wait ends on its ring, not on the 60 s.
        while inbox.queue.lock().expect("lock").len() < 3 {
            bell.wait(None, Duration::from_secs(60));
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "{:?}", t0.elapsed());
        pusher.join().expect("the pusher");
        assert_eq!([inbox.take(), inbox.take(), inbox.take(), inbox.take()], [Some(0), Some(1), Some(2), None]);
    }

    #[test]
    fn a_full_inbox_drops_what_comes_and_says_so() {
        let (inbox, bell) = inbox::<u32>(2).expect("an inbox");
        assert_eq!([inbox.push(1), inbox.push(2), inbox.push(3)], [true, true, false]);
        // The rings are cleared: a second wait sleeps its whole (short) timeout.
        bell.wait(None, Duration::from_secs(60));
        let t0 = Instant::now();
        bell.wait(None, Duration::from_millis(20));
        assert!(t0.elapsed() >= Duration::from_millis(20));
        assert_eq!((inbox.take(), inbox.take(), inbox.take()), (Some(1), Some(2), None));
    }
}
