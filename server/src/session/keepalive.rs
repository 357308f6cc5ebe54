//! The pings of one session: numbered, and judged by their pongs.
//!
//! Each ping carries `np` and its number (10 bytes: the number big-endian); a pong echoes it, and the receive loop
//! records the newest number answered. A WebSocket peer answers a ping when it *reads* it, after
//! everything sent before it, so an answered ping says how far the client has read. Two rules
//! follow from the oldest ping still unanswered, sent `u` ago:
//!
//! - **Dead peer**: `u` > `--ws-timeout-s` — the peer answered no ping for that long: closed.
//!   Only the pongs count, not other frames read from the peer: a slow reader, whose pongs come
//!   late behind 45 s of queued frames, answers every ping and is not dead.
//! - **Lagging reader**: `u` > [`LAG_LIMIT`] — the client has not read what was sent half a
//!   second ago: telemetry frames are skipped (not queued in the socket to be read tens of
//!   seconds late), and the number skipped is told with `lagged` before the next frame sent.
//!   This is for a client that reads, late: one that answered a ping within the last
//!   [`READING`]. A client that has answered none for that long (or never) has stopped reading
//!   rather than slowed down: its frames go on, its socket fills, and the send budget (a frame
//!   that waits 5 s) drops it; the others never wait for it.
//!
//! While a client takes telemetry it is pinged every [`PROBE`] (so the rule sees how far it has
//! read within a fraction of a second), otherwise every `--ws-ping-s`. A frame queued for a
//! client that reads a quarter of the frames is then at most a few seconds old, instead of
//! growing older without bound.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

use axum::body::Bytes;

/// How long a ping may wait for its pong before the client counts as lagging and telemetry is
/// skipped for it.
pub const LAG_LIMIT: Duration = Duration::from_millis(500);

/// The ping period while a client takes telemetry.
pub const PROBE: Duration = Duration::from_millis(250);

/// A client that answered a ping within this long is reading (late, maybe); one that answered
/// none for longer has stopped (the send budget's 5 s).
pub const READING: Duration = super::SEND_BUDGET;

/// The newest ping number a pong answered (written by the receive loop, read by the sender).
pub(super) type Answered = Arc<AtomicU64>;

/// What a ping's payload begins with, before its number.
const TAG: &[u8; 2] = b"np";

/// Records pong `payload` in `answered` when it echoes one of our pings (`np`, its number).
pub(super) fn pong(answered: &AtomicU64, payload: &[u8]) {
    if let Some(n) = payload.strip_prefix(TAG).and_then(|n| <[u8; 8]>::try_from(n).ok()) {
        answered.fetch_max(u64::from_be_bytes(n), Relaxed);
    }
}

/// The pings sent to one client and not yet answered.
pub(super) struct KeepAlive {
    answered: Answered,
    /// The newest ping known answered.
    acked: u64,
    /// When an answer was last seen (None: never).
    answered_at: Option<Instant>,
    /// Pings sent and not known answered: number and when, oldest first.
    waiting: VecDeque<(u64, Instant)>,
    /// The last ping's number (0: none yet).
    last: u64,
    /// When the last ping was sent.
    last_at: Instant,
}

impl KeepAlive {
    /// No ping sent yet, at `now`.
    pub fn new(answered: Answered, now: Instant) -> KeepAlive {
        KeepAlive {
            answered,
            acked: 0,
            answered_at: None,
            waiting: VecDeque::new(),
            last: 0,
            last_at: now,
        }
    }

    /// How long the oldest unanswered ping has waited at `now` (zero when none waits).
    pub fn unanswered_for(&mut self, now: Instant) -> Duration {
        // Taken (reset to 0), so that a number above the last sent (a forged pong) answers only
        // the pings sent so far, not the next ones.
        let answered = self.answered.swap(0, Relaxed).min(self.last);
        if answered > self.acked {
            self.acked = answered;
            self.answered_at = Some(now);
        }
        while self.waiting.front().is_some_and(|&(n, _)| n <= self.acked) {
            self.waiting.pop_front();
        }
        self.waiting
            .front()
            .map_or(Duration::ZERO, |&(_, at)| now.saturating_duration_since(at))
    }

    /// Whether the client reads but is behind: a ping waited more than [`LAG_LIMIT`] for its
    /// pong, and one was answered within [`READING`].
    pub fn behind(&mut self, now: Instant) -> bool {
        self.unanswered_for(now) > LAG_LIMIT
            && self
                .answered_at
                .is_some_and(|t| now.saturating_duration_since(t) < READING)
    }

    /// The next ping's payload when one is due at `now`: every [`PROBE`] while `probing` (the
    /// client takes telemetry), else every `period`.
    pub fn due(&mut self, now: Instant, probing: bool, period: Duration) -> Option<Bytes> {
        let every = if probing { PROBE.min(period) } else { period };
        if now.saturating_duration_since(self.last_at) < every {
            return None;
        }
        self.last += 1;
        self.last_at = now;
        self.waiting.push_back((self.last, now));
        let mut payload = TAG.to_vec();
        payload.extend_from_slice(&self.last.to_be_bytes());
        Some(Bytes::from(payload))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// Pongs answer their ping and every one before; the oldest unanswered one is judged.
    #[test]
    fn the_oldest_unanswered_ping_is_judged() {
        let t0 = Instant::now();
        let answered = Answered::default();
        let mut k = KeepAlive::new(answered.clone(), t0);
        assert_eq!(k.due(t0 + ms(100), true, ms(10_000)), None, "not yet");
        let p1 = k.due(t0 + ms(250), true, ms(10_000)).unwrap();
        let p2 = k.due(t0 + ms(500), true, ms(10_000)).unwrap();
        assert_eq!(k.unanswered_for(t0 + ms(600)), ms(350));
        assert!(!k.behind(t0 + ms(800)), "never answered: not reading, not behind");
        pong(&answered, &p1);
        assert_eq!(k.unanswered_for(t0 + ms(800)), ms(300), "the second ping waits");
        assert!(!k.behind(t0 + ms(1000)));
        assert!(k.behind(t0 + ms(1100)), "reading, and behind");
        assert!(
            !k.behind(t0 + ms(5900)),
            "answered nothing for 5 s: stopped, not behind"
        );
        pong(&answered, &p2);
        assert_eq!(k.unanswered_for(t0 + ms(5000)), Duration::ZERO);
        // Another payload (a client's own heartbeat) answers nothing.
        let _p3 = k.due(t0 + ms(750), true, ms(10_000)).unwrap();
        pong(&answered, b"nanopush");
        assert_eq!(k.unanswered_for(t0 + ms(1750)), ms(1000));
    }

    /// A forged pong beyond the last ping answers only the pings sent; without telemetry, pings
    /// go at the keep-alive period.
    #[test]
    fn a_forged_pong_answers_nothing_and_idle_clients_are_pinged_less() {
        let t0 = Instant::now();
        let answered = Answered::default();
        let mut k = KeepAlive::new(answered.clone(), t0);
        assert_eq!(k.due(t0 + ms(300), false, ms(10_000)), None);
        let _p1 = k.due(t0 + ms(10_000), false, ms(10_000)).unwrap();
        pong(&answered, &[&TAG[..], &u64::MAX.to_be_bytes()].concat());
        assert_eq!(k.unanswered_for(t0 + ms(10_500)), Duration::ZERO);
        let _p2 = k.due(t0 + ms(20_000), false, ms(10_000)).unwrap();
        assert_eq!(k.unanswered_for(t0 + ms(21_000)), ms(1000));
    }
}
