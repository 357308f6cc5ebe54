//! The telemetry frames one WebSocket session sends.
//!
//! Every frame goes into two broadcasts, numbered (`seq`, from 1): first the lease holder's
//! channel, then, after the telemetry task yields, everyone's
//! ([`crate::telemetry::telemetry_task`]). A session always reads everyone's channel, and
//! while its client holds the lease also the holder's, which is woken first. Each number is sent
//! once, in increasing order: a copy whose number was already sent is skipped. Taking or giving
//! up the lease therefore neither loses nor repeats a frame, whichever way it races the two
//! sends. A frame is lost only when the client's channels overflowed (a client that reads too
//! slowly); the numbers say how many, and the session tells the client with `lagged {skipped}`
//! before the next frame it sends.

use axum::extract::ws::Utf8Bytes;
use tokio::sync::broadcast::{self, error::RecvError};

/// A telemetry frame: its number and its text.
pub type Frame = (u64, Utf8Bytes);

/// What [`Frames::next`] gives.
#[derive(Debug, PartialEq)]
pub enum Next {
    /// A frame to send (its number was not sent before).
    Frame(u64, Utf8Bytes),
    /// The client's channel overflowed: this many frames are lost.
    Lagged(u64),
    /// The server is shutting down its telemetry.
    Closed,
}

/// One session's telemetry: everyone's channel, and the holder's while it holds the lease.
pub struct Frames {
    all: broadcast::Receiver<Frame>,
    lease: Option<broadcast::Receiver<Frame>>,
    /// The number of the last frame sent (0: none since the subscription).
    last: u64,
    /// A frame to send after the loss before it was reported.
    pending: Option<Frame>,
}

impl Frames {
    /// Reads everyone's channel from its next frame on.
    pub fn new(all: broadcast::Receiver<Frame>) -> Self {
        Self {
            all,
            lease: None,
            last: 0,
            pending: None,
        }
    }

    /// Whether the holder's channel is read.
    pub fn holds(&self) -> bool {
        self.lease.is_some()
    }

    /// Follows the lease: reads the holder's channel (`lease`) from its next frame on while
    /// `holder`, and drops it otherwise. Everyone's channel is kept as it is, so that a frame
    /// sent to it before the switch and not yet read is still sent.
    pub fn hold(&mut self, holder: bool, lease: &broadcast::Sender<Frame>) {
        if holder != self.lease.is_some() {
            self.lease = holder.then(|| lease.subscribe());
        }
    }

    /// Drops every frame queued so far: a new subscription starts from the next frame, and the
    /// frames produced before it are not counted as lost.
    pub fn renew(&mut self) {
        self.all = self.all.resubscribe();
        self.lease = self.lease.as_ref().map(broadcast::Receiver::resubscribe);
        self.last = 0;
        self.pending = None;
    }

    /// The next frame not sent yet, or first how many were lost before it (the numbers
    /// skipped). Everyone's channel is read first when both have a frame: its oldest frame is
    /// never newer than the holder's channel's, so no number is passed over. An overflow of
    /// either channel (`Lagged`) is not itself a loss: the holder reads two copies of each frame
    /// and one channel may overflow with copies the other delivered. Cancel-safe (an
    /// interrupted call consumed at most copies already sent, or left its frame pending).
    pub async fn next(&mut self) -> Next {
        if let Some((seq, text)) = self.pending.take() {
            return Next::Frame(seq, text);
        }
        loop {
            let r = match self.lease.as_mut() {
                Some(lease) => tokio::select! {
                    biased;
                    r = self.all.recv() => r,
                    r = lease.recv() => r,
                },
                None => self.all.recv().await,
            };
            match r {
                Ok((seq, text)) if seq > self.last => {
                    let lost = if self.last == 0 { 0 } else { seq - self.last - 1 };
                    self.last = seq;
                    if lost > 0 {
                        self.pending = Some((seq, text));
                        return Next::Lagged(lost);
                    }
                    return Next::Frame(seq, text);
                }
                Ok(_) | Err(RecvError::Lagged(_)) => {}
                Err(RecvError::Closed) => return Next::Closed,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seq: u64) -> Frame {
        (seq, Utf8Bytes::from(format!("f{seq}")))
    }

    /// The holder's channel, everyone's, and a session reading everyone's.
    fn channels(capacity: usize) -> (broadcast::Sender<Frame>, broadcast::Sender<Frame>, Frames) {
        let (lease, _) = broadcast::channel(capacity);
        let (all, rx) = broadcast::channel(capacity);
        (lease, all, Frames::new(rx))
    }

    /// The telemetry task's order: the holder's channel, then everyone's.
    fn send(lease: &broadcast::Sender<Frame>, all: &broadcast::Sender<Frame>, seq: u64) {
        let _ = lease.send(frame(seq));
        let _ = all.send(frame(seq));
    }

    async fn numbers(f: &mut Frames, n: usize) -> Vec<u64> {
        let mut v = Vec::new();
        for _ in 0..n {
            match f.next().await {
                Next::Frame(seq, text) => {
                    assert_eq!(text.as_str(), format!("f{seq}"));
                    v.push(seq);
                }
                other => panic!("{other:?}"),
            }
        }
        v
    }

    /// Nothing more is queued for `f`.
    async fn drained(f: &mut Frames) -> bool {
        tokio::time::timeout(std::time::Duration::from_millis(20), f.next())
            .await
            .is_err()
    }

    #[tokio::test]
    async fn a_holder_sends_each_frame_once_from_whichever_channel_has_it_first() {
        let (lease, all, mut f) = channels(16);
        f.hold(true, &lease);
        assert!(f.holds());
        // Woken by the holder's channel before the viewers' copy exists.
        let _ = lease.send(frame(1));
        assert_eq!(numbers(&mut f, 1).await, [1]);
        let _ = all.send(frame(1));
        // Both copies queued at once.
        send(&lease, &all, 2);
        send(&lease, &all, 3);
        assert_eq!(numbers(&mut f, 2).await, [2, 3]);
        assert!(drained(&mut f).await);
    }

    #[tokio::test]
    async fn giving_up_the_lease_between_the_two_sends_does_not_repeat_the_frame() {
        let (lease, all, mut f) = channels(16);
        f.hold(true, &lease);
        let _ = lease.send(frame(1));
        assert_eq!(numbers(&mut f, 1).await, [1]);
        f.hold(false, &lease);
        assert!(!f.holds());
        let _ = all.send(frame(1));
        send(&lease, &all, 2);
        assert_eq!(numbers(&mut f, 1).await, [2]);
        assert!(drained(&mut f).await);
    }

    #[tokio::test]
    async fn taking_the_lease_between_the_two_sends_does_not_lose_the_frame() {
        let (lease, all, mut f) = channels(16);
        send(&lease, &all, 1);
        // Frame 2 went to the holder's channel before this session subscribed to it, and
        // frame 3 is already there when it reads.
        let _ = lease.send(frame(2));
        f.hold(true, &lease);
        let _ = all.send(frame(2));
        send(&lease, &all, 3);
        assert_eq!(numbers(&mut f, 3).await, [1, 2, 3]);
        assert!(drained(&mut f).await);
    }

    #[tokio::test]
    async fn the_lease_passing_back_and_forth_keeps_every_number_once_in_order() {
        let (lease, all, mut f) = channels(64);
        let mut seen = Vec::new();
        for seq in 1..=40u64 {
            // The switch lands before, between or after the two sends.
            match seq % 3 {
                0 => {
                    f.hold(seq % 2 == 0, &lease);
                    send(&lease, &all, seq);
                }
                1 => {
                    let _ = lease.send(frame(seq));
                    f.hold(seq % 2 == 0, &lease);
                    let _ = all.send(frame(seq));
                }
                _ => {
                    send(&lease, &all, seq);
                    f.hold(seq % 2 == 0, &lease);
                }
            }
            while let Ok(Next::Frame(s, _)) = tokio::time::timeout(std::time::Duration::from_millis(5), f.next()).await
            {
                seen.push(s);
            }
        }
        assert_eq!(seen, (1..=40).collect::<Vec<_>>());
    }

    #[tokio::test]
    async fn an_overflow_is_reported_once_as_the_numbers_lost_and_renew_resets() {
        let (lease, all, mut f) = channels(4);
        f.hold(true, &lease);
        send(&lease, &all, 1);
        assert_eq!(numbers(&mut f, 1).await, [1]);
        for seq in 2..=11 {
            send(&lease, &all, seq);
        }
        // Both channels overflowed: 2 to 7 are lost, said once, then the frames left.
        assert_eq!(f.next().await, Next::Lagged(6));
        assert_eq!(numbers(&mut f, 4).await, [8, 9, 10, 11]);
        assert!(drained(&mut f).await);
        // Only the holder's channel overflowed (the session read everyone's copies): no loss.
        for seq in 12..=17 {
            let _ = lease.send(frame(seq));
            let _ = all.send(frame(seq));
            assert_eq!(numbers(&mut f, 1).await, [seq]);
        }
        assert!(drained(&mut f).await);
        // A viewer's overflow is reported too.
        f.hold(false, &lease);
        for seq in 18..=23 {
            send(&lease, &all, seq);
        }
        assert_eq!(f.next().await, Next::Lagged(2));
        assert_eq!(numbers(&mut f, 4).await, [20, 21, 22, 23]);
        // A new subscription drops what queued, and the frames before it are not a loss.
        send(&lease, &all, 24);
        f.renew();
        send(&lease, &all, 25);
        assert_eq!(numbers(&mut f, 1).await, [25]);
        drop(all);
        assert_eq!(f.next().await, Next::Closed);
    }
}
