//! Failed attempts per address: a token bucket of [`BURST`] failures refilled one every
//! [`REFILL`]. An address whose bucket is empty is refused without its credential being checked,
//! so guessing tokens runs at 10 a minute at most (a token has 128 random bits).

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

/// Failures allowed in a row.
pub const BURST: f64 = 10.0;

/// One more failure allowed every this long.
pub const REFILL: Duration = Duration::from_secs(6);

/// Most addresses remembered: beyond it, those whose bucket is full again are forgotten.
const ADDRESSES_MAX: usize = 10_000;

/// The buckets.
#[derive(Debug, Default)]
pub struct FailureLimiter {
    buckets: HashMap<IpAddr, (f64, Instant)>,
}

impl FailureLimiter {
    fn level(&self, ip: IpAddr, now: Instant) -> f64 {
        self.buckets.get(&ip).map_or(BURST, |&(level, at)| {
            (level + now.duration_since(at).as_secs_f64() / REFILL.as_secs_f64()).min(BURST)
        })
    }

    /// How long `ip` must wait before its next attempt, or None when it may try now.
    pub fn blocked_at(&mut self, ip: IpAddr, now: Instant) -> Option<Duration> {
        let level = self.level(ip, now);
        (level < 1.0).then(|| REFILL.mul_f64(1.0 - level))
    }

    /// A failure from `ip` at `now`.
    pub fn failed_at(&mut self, ip: IpAddr, now: Instant) {
        let level = (self.level(ip, now) - 1.0).max(0.0);
        if self.buckets.len() >= ADDRESSES_MAX {
            let full: Vec<IpAddr> = self
                .buckets
                .keys()
                .copied()
                .filter(|&a| self.level(a, now) >= BURST)
                .collect();
            for a in full {
                self.buckets.remove(&a);
            }
        }
        self.buckets.insert(ip, (level, now));
    }

    /// [`Self::blocked_at`] now.
    pub fn blocked(&mut self, ip: IpAddr) -> Option<Duration> {
        self.blocked_at(ip, Instant::now())
    }

    /// [`Self::failed_at`] now.
    pub fn failed(&mut self, ip: IpAddr) {
        self.failed_at(ip, Instant::now())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_failures_block_an_address_until_the_bucket_refills_and_others_are_unaffected() {
        let mut l = FailureLimiter::default();
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let t0 = Instant::now();
        for _ in 0..10 {
            assert_eq!(l.blocked_at(a, t0), None);
            l.failed_at(a, t0);
        }
        let wait = l.blocked_at(a, t0).expect("blocked after 10 failures");
        assert!(wait <= REFILL && wait > Duration::ZERO, "{wait:?}");
        assert_eq!(l.blocked_at(b, t0), None, "another address is not blocked");
        // One refill later, one more attempt.
        let t1 = t0 + REFILL;
        assert_eq!(l.blocked_at(a, t1), None);
        l.failed_at(a, t1);
        assert!(l.blocked_at(a, t1).is_some());
    }
}
