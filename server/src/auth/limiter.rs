//! Failed attempts per address (an IPv6 client's /64, `client_addr::limit_key`: a host is
//! commonly given a whole /64, and counted by each address it would have 2^64 buckets): a token
//! bucket of [`BURST`] attempts refilled one every [`REFILL`]. An attempt with a token takes one
//! from its address's bucket *before* the token is checked, and gives it back when the token was
//! right: so attempts sent at once cannot all pass an almost empty bucket while their checks run.
//! An address whose bucket is empty is refused without its credential being checked, so guessing
//! tokens runs at 10 a minute at most (a token has 128 random bits), however many are sent at
//! once.

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

use crate::client_addr::limit_key;

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
    /// The bucket's level at `now`: `min(BURST, level + (now − at) / REFILL)`.
    fn level(&self, ip: IpAddr, now: Instant) -> f64 {
        self.buckets.get(&ip).map_or(BURST, |&(level, at)| {
            (level + now.saturating_duration_since(at).as_secs_f64() / REFILL.as_secs_f64()).min(BURST)
        })
    }

    fn set(&mut self, ip: IpAddr, level: f64, now: Instant) {
        if self.buckets.len() >= ADDRESSES_MAX && !self.buckets.contains_key(&ip) {
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

    /// An attempt from `ip` at `now`: taken from its bucket (counted as failed until
    /// [`Self::refund_at`] says it was not), or refused with how long to wait when the bucket
    /// holds less than one attempt.
    pub fn reserve_at(&mut self, ip: IpAddr, now: Instant) -> Result<(), Duration> {
        let ip = limit_key(ip);
        let level = self.level(ip, now);
        if level < 1.0 {
            return Err(REFILL.mul_f64(1.0 - level));
        }
        self.set(ip, level - 1.0, now);
        Ok(())
    }

    /// The attempt reserved for `ip` did not fail (the token was right, or it was never
    /// checked): it goes back into the bucket.
    pub fn refund_at(&mut self, ip: IpAddr, now: Instant) {
        let ip = limit_key(ip);
        let level = (self.level(ip, now) + 1.0).min(BURST);
        self.set(ip, level, now);
    }

    /// [`Self::reserve_at`] now.
    pub fn reserve(&mut self, ip: IpAddr) -> Result<(), Duration> {
        self.reserve_at(ip, Instant::now())
    }

    /// [`Self::refund_at`] now.
    pub fn refund(&mut self, ip: IpAddr) {
        self.refund_at(ip, Instant::now())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failures_block_one_address_until_its_bucket_refills() {
        let mut l = FailureLimiter::default();
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let t0 = Instant::now();
        for _ in 0..10 {
            assert_eq!(l.reserve_at(a, t0), Ok(()));
        }
        let wait = l.reserve_at(a, t0).expect_err("blocked after 10 failures");
        assert!(wait <= REFILL && wait > Duration::ZERO, "{wait:?}");
        assert_eq!(l.reserve_at(b, t0), Ok(()), "another address is not blocked");
        // One refill later, one more attempt.
        let t1 = t0 + REFILL;
        assert_eq!(l.reserve_at(a, t1), Ok(()));
        assert!(l.reserve_at(a, t1).is_err());
    }

    #[test]
    fn attempts_in_flight_hold_their_place_and_a_right_token_gives_it_back() {
        let mut l = FailureLimiter::default();
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let t0 = Instant::now();
        // Ten attempts at once, none answered yet: the eleventh is refused before any check.
        for _ in 0..10 {
            l.reserve_at(a, t0).unwrap();
        }
        assert!(l.reserve_at(a, t0).is_err());
        // Nine were right: nine places back, one failure stays counted.
        for _ in 0..9 {
            l.refund_at(a, t0);
        }
        for _ in 0..9 {
            l.reserve_at(a, t0).unwrap();
        }
        assert!(l.reserve_at(a, t0).is_err());
        // Refunds never fill the bucket beyond its burst.
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        for _ in 0..5 {
            l.refund_at(b, t0);
        }
        for _ in 0..10 {
            l.reserve_at(b, t0).unwrap();
        }
        assert!(l.reserve_at(b, t0).is_err());
    }

    /// An IPv6 client is counted by its /64: a host given a whole /64 has one bucket, not one for
    /// each of its 2^64 addresses; another /64 has its own.
    #[test]
    fn an_ipv6_client_has_one_bucket_for_its_64() {
        let mut l = FailureLimiter::default();
        let t0 = Instant::now();
        let ip = |s: String| s.parse::<IpAddr>().unwrap();
        for k in 1..=10 {
            assert_eq!(l.reserve_at(ip(format!("2001:db8:1:2::{k:x}")), t0), Ok(()));
        }
        assert!(
            l.reserve_at(ip("2001:db8:1:2:ffff::1".into()), t0).is_err(),
            "an eleventh address of the same /64 is refused"
        );
        assert_eq!(l.reserve_at(ip("2001:db8:1:3::1".into()), t0), Ok(()));
        // A right token from another address of the /64 gives its place back to the /64.
        l.refund_at(ip("2001:db8:1:2::77".into()), t0);
        assert_eq!(l.reserve_at(ip("2001:db8:1:2::78".into()), t0), Ok(()));
    }
}
