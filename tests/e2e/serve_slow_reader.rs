//! A slow reader of telemetry sees the newest state within about a second, whatever its client
//! library buffers: a client acknowledges the frames it has read (`ack`), and the server keeps no
//! more in flight to it than it reads in half a second. Two client behaviours, one server: one
//! that reads its socket only as fast as it takes messages (pongs late, with what it has not
//! read), and one whose library reads the socket at once into a queue of its own (pongs at once,
//! frames queued in memory: what Python's `websockets` and the browsers do).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

use crate::util::{Ws, ok, runtime, start, welcomed};

/// How a slow reader's library treats the socket.
#[derive(Debug, Clone, Copy)]
enum Library {
    /// Reads the socket as the program takes messages (tokio-tungstenite as it is).
    ReadsOnDemand,
    /// Reads the socket at once into an unbounded queue the program takes messages from.
    QueuesEverything,
}

/// What one slow reader saw: frames read, how many frames behind the newest each was (from the
/// end of the warm-up on), and the errors it was sent.
#[derive(Debug, Default)]
struct Seen {
    frames: u64,
    behind: Vec<u64>,
    errors: Vec<String>,
}

/// Where a slow reader's program takes its messages from.
enum Source {
    Socket(futures_util::stream::SplitStream<Ws>),
    Queue(tokio::sync::mpsc::UnboundedReceiver<Message>),
}

impl Source {
    async fn next(&mut self) -> Option<Message> {
        match self {
            Source::Socket(s) => s.next().await.and_then(Result::ok),
            Source::Queue(q) => q.recv().await,
        }
    }
}

/// Takes one message every `1/rate` s for `secs` s from `ws`, through `library`, and
/// acknowledges each frame it reads; each frame's distance from `newest` (the newest a fast
/// reader has) is kept after `warm` s.
async fn slow_reader(ws: Ws, library: Library, rate: f64, secs: f64, warm: f64, newest: Arc<AtomicU64>) -> Seen {
    let (mut tx, rx) = ws.split();
    let mut source = match library {
        Library::ReadsOnDemand => Source::Socket(rx),
        Library::QueuesEverything => {
            let (queue_tx, queue) = tokio::sync::mpsc::unbounded_channel();
            let mut rx = rx;
            tokio::spawn(async move {
                while let Some(Ok(m)) = rx.next().await {
                    if queue_tx.send(m).is_err() {
                        break;
                    }
                }
            });
            Source::Queue(queue)
        }
    };
    let t0 = Instant::now();
    let mut seen = Seen::default();
    let mut k = 0u32;
    while t0.elapsed() < Duration::from_secs_f64(secs) {
        k += 1;
        tokio::time::sleep_until(t0 + Duration::from_secs_f64(f64::from(k) / rate)).await;
        let Ok(Some(m)) = tokio::time::timeout(Duration::from_secs(5), source.next()).await else {
            seen.errors
                .push(format!("no message within 5 s at {:.1} s", t0.elapsed().as_secs_f64()));
            break;
        };
        let Message::Text(t) = m else { continue };
        let v: Value = serde_json::from_str(&t).unwrap();
        match v["type"].as_str() {
            Some("telemetry") => {
                let seq = v["seq"].as_u64().unwrap();
                seen.frames += 1;
                if t0.elapsed().as_secs_f64() > warm {
                    seen.behind.push(newest.load(Relaxed).saturating_sub(seq));
                }
                let ack = json!({"type": "ack", "seq": seq}).to_string();
                if tx.send(Message::Text(ack.into())).await.is_err() {
                    seen.errors.push("the socket closed".into());
                    break;
                }
            }
            Some("error") => seen.errors.push(v.to_string()),
            _ => {}
        }
    }
    seen
}

/// The largest and the median of `v`.
fn max_and_median(v: &[u64]) -> (u64, u64) {
    let mut s = v.to_vec();
    s.sort_unstable();
    (s.last().copied().unwrap_or(0), s.get(s.len() / 2).copied().unwrap_or(0))
}

/// Two readers taking 15 messages a second of the 60 Hz telemetry, one whose library reads the
/// socket on demand and one whose library queues everything it can read, each acknowledging each
/// frame it reads: after a 2 s warm-up, every frame each reads is at most 60 frames (1 s) behind
/// the newest a fast reader has, and each reads at least half its 15 a second
/// (`NANOPUSH_SLOW_READER_S` sets the seconds, 8 by default). Before, at most 152 and 315 frames
/// behind (2.5 s and 5.3 s, growing with the time read).
#[test]
fn a_slow_reader_that_acknowledges_sees_frames_within_a_second() {
    let secs: f64 = std::env::var("NANOPUSH_SLOW_READER_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8.0);
    let srv = start(
        "slow-ack",
        &["--telemetry-hz", "60", "--ws-ping-s", "0.5", "--ws-timeout-s", "10"],
    );
    let (warm, rate) = (2.0, 15.0);
    let results = runtime().block_on(async {
        let newest = Arc::new(AtomicU64::new(0));
        let mut clients = Vec::new();
        for _ in 0..3 {
            let (mut ws, _) = welcomed(&srv.addr, None).await;
            ok(&mut ws, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
            clients.push(ws);
        }
        let mut fast = clients.remove(0);
        let n = newest.clone();
        let fast = tokio::spawn(async move {
            let end = Instant::now() + Duration::from_secs_f64(secs + 1.0);
            while let Ok(Some(Ok(m))) = tokio::time::timeout_at(end, fast.next()).await {
                if let Message::Text(t) = m
                    && let Ok(v) = serde_json::from_str::<Value>(&t)
                    && v["type"] == "telemetry"
                {
                    n.fetch_max(v["seq"].as_u64().unwrap(), Relaxed);
                    // Acknowledged, as a client that reads everything at once does.
                    let ack = json!({"type": "ack", "seq": v["seq"]}).to_string();
                    let _ = fast.send(Message::Text(ack.into())).await;
                }
            }
        });
        let on_demand = clients.remove(0);
        let queueing = clients.remove(0);
        let a = tokio::spawn(slow_reader(
            on_demand,
            Library::ReadsOnDemand,
            rate,
            secs,
            warm,
            newest.clone(),
        ));
        let b = tokio::spawn(slow_reader(
            queueing,
            Library::QueuesEverything,
            rate,
            secs,
            warm,
            newest.clone(),
        ));
        let (a, b) = (a.await.unwrap(), b.await.unwrap());
        fast.await.unwrap();
        [(Library::ReadsOnDemand, a), (Library::QueuesEverything, b)]
    });
    for (library, seen) in &results {
        let (max, median) = max_and_median(&seen.behind);
        eprintln!(
            "{library:?}: {} frames read in {secs} s, behind the newest by at most {max} frames ({:.2} s), median {median}",
            seen.frames,
            max as f64 / 60.0
        );
    }
    for (library, seen) in results {
        let (max, median) = max_and_median(&seen.behind);
        assert!(
            max <= 60,
            "{library:?}: a frame read {max} frames ({:.1} s) behind the newest (median {median})",
            max as f64 / 60.0
        );
        assert!(
            seen.frames as f64 >= rate * secs / 2.0,
            "{library:?}: {} frames read in {secs} s at {rate} messages a second",
            seen.frames
        );
        assert!(
            seen.errors.is_empty(),
            "{library:?}: {} errors, the first: {}",
            seen.errors.len(),
            seen.errors[0]
        );
    }
}
