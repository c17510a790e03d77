//! Bad datagrams (malformed, foreign, refused) are counted always but logged at a bounded
//! rate: the first from a peer at once, then at most one summary a second per peer. A flood
//! otherwise turns into megabytes of stderr a second, which costs more than the flood itself.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// The shortest time between two lines about one peer.
pub const SUMMARY_INTERVAL: Duration = Duration::from_secs(1);
/// Peers tracked one by one; beyond them (a flood from many source ports) every other peer
/// shares one summary, so the log stays bounded whatever the number of sources.
pub const MAX_TRACKED_PEERS: usize = 64;

#[derive(Debug)]
struct Window {
    opened: Instant,
    /// Bad datagrams since the last line, not logged.
    held: u64,
    /// What was wrong with the last one held.
    last: String,
}

/// Rate-limited reports of bad datagrams, by source address.
#[derive(Debug, Default)]
pub struct NoiseLog {
    peers: HashMap<SocketAddr, Window>,
    others: Option<Window>,
}

impl NoiseLog {
    /// An empty log.
    pub fn new() -> Self {
        Self::default()
    }

    /// Notes a bad datagram from `peer` at `now`; returns the line to log now, if any (the
    /// first from a peer in a while). `what` says what was wrong, e.g. "actions from X
    /// dropped: bad number".
    pub fn note(&mut self, peer: SocketAddr, now: Instant, what: impl FnOnce() -> String) -> Option<String> {
        if let Some(w) = self.peers.get_mut(&peer) {
            w.held += 1;
            w.last = what();
            return None;
        }
        if self.peers.len() >= MAX_TRACKED_PEERS {
            let w = self.others.get_or_insert_with(|| Window { opened: now, held: 0, last: String::new() });
            w.held += 1;
            w.last = what();
            return None;
        }
        self.peers.insert(peer, Window { opened: now, held: 0, last: String::new() });
        Some(what())
    }

    /// The summaries due at `now`: one per peer whose window of [`SUMMARY_INTERVAL`] closed
    /// with datagrams held. Peers quiet for a whole window are forgotten (their next bad
    /// datagram is logged at once).
    pub fn due(&mut self, now: Instant) -> Vec<String> {
        let mut lines = Vec::new();
        self.peers.retain(|peer, w| {
            let span = now.saturating_duration_since(w.opened);
            if span < SUMMARY_INTERVAL {
                return true;
            }
            if w.held == 0 {
                return false;
            }
            lines.push(format!(
                "{} more bad datagrams from {peer} in {:.1} s, the last: {}",
                w.held,
                span.as_secs_f64(),
                w.last
            ));
            *w = Window { opened: now, held: 0, last: String::new() };
            true
        });
        if let Some(w) = &self.others
            && now.saturating_duration_since(w.opened) >= SUMMARY_INTERVAL
        {
            lines.push(format!(
                "{} more bad datagrams from other peers in {:.1} s, the last: {}",
                w.held,
                now.saturating_duration_since(w.opened).as_secs_f64(),
                w.last
            ));
            self.others = None;
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    #[test]
    fn a_flood_from_one_peer_gives_one_line_then_one_summary_a_second_counting_all() {
        let mut log = NoiseLog::new();
        let t0 = Instant::now();
        let mut lines = Vec::new();
        // 10,000 bad datagrams over 2.5 s.
        for k in 0..10_000u64 {
            let now = t0 + Duration::from_micros(k * 250);
            lines.extend(log.note(peer(9), now, || format!("junk {k}")));
            lines.extend(log.due(now));
        }
        lines.extend(log.due(t0 + Duration::from_secs(4)));
        assert_eq!(lines[0], "junk 0");
        assert_eq!(lines.len(), 4, "{lines:?}");
        let held: u64 =
            lines[1..].iter().map(|l| l.split(' ').next().and_then(|n| n.parse::<u64>().ok()).unwrap_or(0)).sum();
        assert_eq!(held, 9_999, "{lines:?}");
        assert!(lines[3].ends_with("the last: junk 9999"), "{lines:?}");
    }

    #[test]
    fn a_peer_quiet_for_a_second_is_logged_at_once_again() {
        let mut log = NoiseLog::new();
        let t0 = Instant::now();
        assert!(log.note(peer(1), t0, || "a".into()).is_some());
        assert!(log.due(t0 + Duration::from_millis(1500)).is_empty());
        assert_eq!(log.note(peer(1), t0 + Duration::from_millis(1600), || "b".into()).as_deref(), Some("b"));
    }

    #[test]
    fn many_peers_share_one_summary_beyond_the_tracked_ones() {
        let mut log = NoiseLog::new();
        let t0 = Instant::now();
        let at_once = (0..1000u16).filter(|&p| log.note(peer(p + 1), t0, || format!("p{p}")).is_some()).count();
        assert_eq!(at_once, MAX_TRACKED_PEERS);
        let later = log.due(t0 + SUMMARY_INTERVAL);
        assert_eq!(
            later,
            vec![format!("{} more bad datagrams from other peers in 1.0 s, the last: p999", 1000 - MAX_TRACKED_PEERS)]
        );
    }
}
