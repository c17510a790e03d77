//! The monotonic clock as a number.

use nix::time::{ClockId, clock_gettime};

/// CLOCK_MONOTONIC in nanoseconds: comparable across processes on one machine (a test reading
/// the chair emulator's truth log compares it with its own clock), which `std::time::Instant`
/// does not expose.
pub fn monotonic_ns() -> u64 {
    match clock_gettime(ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec() as u64),
        // CLOCK_MONOTONIC exists on every Linux; were the call to fail, 0 keeps time standing
        // rather than panicking.
        Err(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_monotonic_clock_moves_on_with_the_standard_one() {
        let (a, t) = (super::monotonic_ns(), std::time::Instant::now());
        std::thread::sleep(std::time::Duration::from_millis(20));
        let (b, e) = (super::monotonic_ns(), t.elapsed());
        assert!(a > 0 && b >= a + 20_000_000, "{a} then {b}");
        assert!(b - a <= e.as_nanos() as u64 + 1_000_000, "{} ns by ours, {e:?} by std", b - a);
    }
}
