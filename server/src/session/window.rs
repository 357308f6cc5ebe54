//! What is in flight to a client that acknowledges the telemetry it has read (`ack`).
//!
//! Pongs say how far a client's *library* has read its socket, not what its program has taken:
//! a library that reads the socket into a queue of its own (Python's `websockets`, a browser)
//! answers every ping at once while frames wait in its memory, seconds old. A client's `ack` says
//! what its program has read. From its first `ack` on, the frames sent and not yet acknowledged
//! are at most what the client acknowledged in the last [`TARGET`] (its reading rate over the
//! last [`RATE_SPAN`], times [`TARGET`]), and at least [`MIN_IN_FLIGHT`]: a frame waits about
//! [`TARGET`] behind the others before it is read, whatever the client's library buffers, and a
//! frame that finds the window full is skipped, so the next one sent is the newest.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// About how long a frame waits, behind the frames in flight, before the client reads it.
pub const TARGET: Duration = Duration::from_millis(500);

/// Frames in flight at least, whatever the reading rate (so that a client that has read nothing
/// lately is sent the newest frames to read).
pub const MIN_IN_FLIGHT: usize = 2;

/// The span the client's reading rate is measured over.
pub const RATE_SPAN: Duration = Duration::from_secs(1);

/// Most frames remembered in flight: the frames sent before a client's first `ack` are
/// remembered too (it reads them before the newer ones), the newest this many.
const IN_FLIGHT_MAX: usize = 512;

/// What the receive loop and the send loop share of one client's acknowledgements.
#[derive(Debug, Default)]
pub(crate) struct Acks {
    /// The newest frame the client acknowledged (0: none yet, and no window).
    pub acked: AtomicU64,
    /// The newest frame sent to it (0: none): an `ack` beyond it is refused.
    pub newest_sent: AtomicU64,
}

/// The frames in flight to one client, and its reading rate.
#[derive(Debug)]
pub(super) struct Window {
    /// The newest acknowledgement taken into account.
    acked: u64,
    /// The numbers of the frames sent and not yet acknowledged, oldest first.
    in_flight: VecDeque<u64>,
    /// When each frame acknowledged in the last [`RATE_SPAN`] was acknowledged.
    reads: VecDeque<Instant>,
}

impl Window {
    /// Nothing sent or acknowledged.
    pub fn new() -> Window {
        Window {
            acked: 0,
            in_flight: VecDeque::new(),
            reads: VecDeque::new(),
        }
    }

    /// Whether the client acknowledges (it has sent an `ack`): only then does the window hold.
    pub fn on(&self, acks: &Acks) -> bool {
        acks.acked.load(Relaxed) > 0
    }

    /// Takes the newest acknowledgement into account at `now`.
    fn update(&mut self, acks: &Acks, now: Instant) {
        let acked = acks.acked.load(Relaxed);
        if acked > self.acked {
            self.acked = acked;
            while self.in_flight.front().is_some_and(|&seq| seq <= acked) {
                self.in_flight.pop_front();
                self.reads.push_back(now);
            }
        }
        while self
            .reads
            .front()
            .is_some_and(|&t| now.saturating_duration_since(t) > RATE_SPAN)
        {
            self.reads.pop_front();
        }
    }

    /// How many frames may be in flight at `now`: what the client read in the last
    /// [`RATE_SPAN`], scaled to [`TARGET`], at least [`MIN_IN_FLIGHT`].
    pub fn limit(&mut self, acks: &Acks, now: Instant) -> usize {
        self.update(acks, now);
        let rate = self.reads.len() as f64 / RATE_SPAN.as_secs_f64();
        ((rate * TARGET.as_secs_f64()).ceil() as usize).max(MIN_IN_FLIGHT)
    }

    /// Whether a frame may be sent at `now`: always to a client that does not acknowledge, else
    /// while fewer than [`Self::limit`] are in flight.
    pub fn open(&mut self, acks: &Acks, now: Instant) -> bool {
        !self.on(acks) || self.in_flight.len() < self.limit(acks, now)
    }

    /// Frame `seq` was sent (remembered before the client's first `ack` too: what it reads
    /// first).
    pub fn sent(&mut self, acks: &Acks, seq: u64) {
        acks.newest_sent.fetch_max(seq, Relaxed);
        if self.in_flight.len() >= IN_FLIGHT_MAX {
            self.in_flight.pop_front();
        }
        self.in_flight.push_back(seq);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A client reading `rate` frames a second of 60 Hz telemetry, acknowledging every 100 ms:
    /// the largest number of frames between the newest produced and each one it reads, over
    /// `secs` s after a 5 s warm-up (in which it reads what was sent before its first `ack`),
    /// and the frames it read in all.
    fn staleness(rate: f64, secs: f64) -> (u64, usize) {
        let acks = Acks::default();
        let mut w = Window::new();
        let t0 = Instant::now();
        let mut queue: VecDeque<u64> = VecDeque::new(); // sent, not read
        let (mut read, mut worst, mut frames_read) = (0u64, 0u64, 0usize);
        let mut next_read = 0.0;
        let mut next_ack = 0.1;
        // Time in steps of 1 ms; a frame every 1/60 s.
        for ms in 0..((secs + 5.0) * 1000.0) as u64 {
            let t = ms as f64 / 1000.0;
            let now = t0 + Duration::from_millis(ms);
            if ms * 60 % 1000 < 60 {
                let seq = ms * 60 / 1000 + 1;
                if w.open(&acks, now) {
                    w.sent(&acks, seq);
                    queue.push_back(seq);
                }
            }
            if t >= next_read {
                next_read += 1.0 / rate;
                if let Some(seq) = queue.pop_front() {
                    read = seq;
                    frames_read += 1;
                    let newest = ms * 60 / 1000 + 1;
                    if t > 5.0 {
                        worst = worst.max(newest - seq);
                    }
                }
            }
            if t >= next_ack {
                next_ack += 0.1;
                if read > 0 {
                    acks.acked.store(read, Relaxed);
                }
            }
        }
        (worst, frames_read)
    }

    /// Whatever the reading rate, a frame read is at most about 0.6 s (36 frames at 60 Hz)
    /// behind the newest (a reader of 2 a second, whose window is the minimum of 2 frames, about
    /// 1 s: 60), and every reader reads as fast as it reads; a reader of 60 a second is never
    /// held back.
    #[test]
    fn a_reader_at_any_rate_reads_frames_about_half_a_second_old() {
        for (rate, behind) in [(2.0, 60), (5.0, 40), (15.0, 40), (30.0, 40), (60.0, 8)] {
            let (worst, read) = staleness(rate, 10.0);
            eprintln!("{rate} a second: at most {worst} frames behind, {read} read in 15 s");
            assert!(worst <= behind, "{rate} a second: {worst} frames behind");
            assert!(
                read as f64 >= rate * 14.5,
                "{rate} a second: {read} frames read in 15 s"
            );
        }
    }

    /// Without an `ack` the window is open (the pong rule alone applies); a client that stops
    /// acknowledging gets at most the window (what it read in the last second, halved), then
    /// nothing more until it reads.
    #[test]
    fn a_client_that_stops_acknowledging_gets_the_window_then_nothing() {
        let acks = Acks::default();
        let mut w = Window::new();
        let t0 = Instant::now();
        for seq in 1..=100 {
            assert!(w.open(&acks, t0));
            w.sent(&acks, seq);
        }
        assert_eq!(acks.newest_sent.load(Relaxed), 100);
        acks.acked.store(100, Relaxed);
        let mut sent = 0;
        for seq in 101..=400 {
            let now = t0 + Duration::from_millis(seq * 16);
            if w.open(&acks, now) {
                w.sent(&acks, seq);
                sent += 1;
            }
        }
        // Its 100 frames read at once count for a second: half of them more, then nothing.
        assert_eq!(sent, 50);
    }
}
