//! The load: 500 viewers, 50 slowloris sockets, one garbage client, and the operator whose
//! measurements are the soak's probe.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::client::Ws;
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

use crate::{LORISES, TOKEN, VIEWERS, footprint, metric};

/// A WebSocket to the server, with `token` when given; None when it is refused.
async fn ws(addr: &str, token: Option<&str>) -> Option<Ws> {
    let url = nanopush_e2e::client::ws_url(addr, token);
    tokio_tungstenite::connect_async(url).await.ok().map(|(w, _)| w)
}

/// What the load did, and what the operator measured under it.
pub struct Load {
    /// The operator's commands sent and answered.
    pub sent: u64,
    pub answered: u64,
    /// The operator's telemetry arrivals.
    pub arrivals: Vec<Instant>,
    /// From the operator's start to its end.
    pub span: (Instant, Instant),
    /// Frames the server skipped for a lagging client meanwhile.
    pub dropped: f64,
    /// The server's fds and RSS at the end of it.
    pub during: (usize, u64),
    /// Telemetry frames the viewers received, slowloris sockets the server closed, garbage
    /// messages sent.
    pub frames: u64,
    pub closed: u64,
    pub junk: u64,
}

/// Runs the load for `secs` against the server `pid` at `addr`: the clients on a runtime of one
/// worker thread (at nice 19 when `confined`), the operator on a thread and runtime of its own
/// (at SCHED_FIFO 10 when `confined` and granted); then stops them all.
pub fn run_load(addr: &str, secs: f64, confined: bool, pid: u32) -> Load {
    let addr = addr.to_string();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .on_thread_start(move || {
            if confined {
                // SAFETY: sets the calling thread's nice value.
                unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 19) };
            }
        })
        .enable_all()
        .build()
        .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let frames = Arc::new(AtomicU64::new(0));
    let closed = Arc::new(AtomicU64::new(0));
    let junk = Arc::new(AtomicU64::new(0));
    let (sent, answered, arrivals, span, dropped, during) = rt.block_on(async {
        let mut tasks = Vec::new();
        for i in 0..VIEWERS {
            tasks.push(tokio::spawn(viewer(addr.clone(), stop.clone(), frames.clone())));
            if i % 32 == 31 {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        for _ in 0..LORISES {
            tasks.push(tokio::spawn(loris(addr.clone(), stop.clone(), closed.clone())));
        }
        tasks.push(tokio::spawn(garbage(addr.clone(), stop.clone(), junk.clone())));
        tokio::time::sleep(Duration::from_secs(3)).await;
        let dropped0 = metric(&addr, "nanopush_dropped_frames_total");
        let load0 = Instant::now();
        // The operator, on a thread and runtime of its own: its measurements are not delayed by
        // the 500 viewers this process also serves.
        let (op_addr, op_secs) = (addr.clone(), secs);
        let handle = std::thread::spawn(move || {
            if confined && nanopush_rt::sched_fifo(10).is_err() {
                println!("the operator probe runs SCHED_OTHER: SCHED_FIFO was refused");
            }
            tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap()
                .block_on(operator(op_addr, op_secs))
        });
        let (sent, answered, arrivals) =
            tokio::task::spawn_blocking(move || handle.join().expect("the operator thread"))
                .await
                .unwrap();
        let span = (load0, Instant::now());
        let dropped = metric(&addr, "nanopush_dropped_frames_total") - dropped0;
        let during = footprint(pid);
        stop.store(true, Relaxed);
        for t in tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), t).await;
        }
        (sent, answered, arrivals, span, dropped, during)
    });
    drop(rt);
    Load {
        sent,
        answered,
        arrivals,
        span,
        dropped,
        during,
        frames: frames.load(Relaxed),
        closed: closed.load(Relaxed),
        junk: junk.load(Relaxed),
    }
}

/// A viewer subscribed to telemetry, counting the frames it receives, until `stop`.
async fn viewer(addr: String, stop: Arc<AtomicBool>, frames: Arc<AtomicU64>) {
    let Some(mut w) = ws(&addr, None).await else { return };
    let _ = w
        .send(Message::Text(
            json!({"type": "subscribe", "streams": ["tip"]}).to_string().into(),
        ))
        .await;
    while !stop.load(Relaxed) {
        match tokio::time::timeout(Duration::from_millis(200), w.next()).await {
            Ok(Some(Ok(_))) => {
                frames.fetch_add(1, Relaxed);
            }
            Ok(_) => return,
            Err(_) => {}
        }
    }
}

/// A slowloris socket: a request that never ends, a byte now and then; started again each
/// time the server closes it (counted in `closed`), until `stop`.
async fn loris(addr: String, stop: Arc<AtomicBool>, closed: Arc<AtomicU64>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    while !stop.load(Relaxed) {
        let Ok(mut s) = tokio::net::TcpStream::connect(&addr).await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        let _ = s
            .write_all(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
            .await;
        let mut b = [0u8; 64];
        loop {
            if stop.load(Relaxed) {
                return;
            }
            match tokio::time::timeout(Duration::from_millis(500), s.read(&mut b)).await {
                Ok(Ok(0)) | Ok(Err(_)) => {
                    closed.fetch_add(1, Relaxed);
                    break;
                }
                // A byte now and then, as a slowloris does.
                Err(_) => {
                    let _ = s.write_all(b"x").await;
                }
                Ok(Ok(_)) => {}
            }
        }
    }
}

/// A client sending garbage (random printable text, an array, unknown types, a NaN, floods past
/// the rate limit) every 5 ms, counted in `sent`, until `stop`.
async fn garbage(addr: String, stop: Arc<AtomicBool>, sent: Arc<AtomicU64>) {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    while !stop.load(Relaxed) {
        let Some(mut w) = ws(&addr, None).await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        while !stop.load(Relaxed) {
            let text = match rnd() % 5 {
                0 => (0..(rnd() % 200))
                    .map(|_| char::from(32 + (rnd() % 90) as u8))
                    .collect::<String>(),
                1 => "[\"push\",1,1,0.2,0]".to_string(),
                2 => json!({"type": "fly", "id": rnd() % 1000}).to_string(),
                3 => json!({"type": "push", "particle": 1, "distance_um": f64::NAN.to_string()}).to_string(),
                _ => "x".repeat((rnd() % 20_000) as usize),
            };
            if w.send(Message::Text(text.into())).await.is_err() {
                break;
            }
            sent.fetch_add(1, Relaxed);
            // Read whatever came back, without waiting.
            while let Ok(Some(Ok(_))) = tokio::time::timeout(Duration::from_millis(1), w.next()).await {}
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
}

/// The operator: holds the lease, subscribes to telemetry, sends a ping every 100 ms for `secs`;
/// returns the commands sent, the ones answered and the telemetry arrival times.
async fn operator(addr: String, secs: f64) -> (u64, u64, Vec<Instant>) {
    let mut op = ws(&addr, Some(TOKEN)).await.expect("the operator connects");
    let _ = op
        .send(Message::Text(json!({"type": "take_lease", "id": 1}).to_string().into()))
        .await;
    let _ = op
        .send(Message::Text(
            json!({"type": "subscribe", "id": 2, "streams": ["tip"]})
                .to_string()
                .into(),
        ))
        .await;
    let (mut sent, mut answered) = (0u64, std::collections::HashSet::new());
    let mut arrivals: Vec<Instant> = Vec::new();
    let end = Instant::now() + Duration::from_secs_f64(secs);
    let mut next = Instant::now();
    let mut id = 100u32;
    let answer = |t: &str, answered: &mut std::collections::HashSet<u64>| {
        if t.contains("\"ok\"")
            && let Ok(v) = serde_json::from_str::<serde_json::Value>(t)
            && let Some(i) = v["id"].as_u64()
            && i >= 100
        {
            answered.insert(i);
        }
    };
    while Instant::now() < end {
        if Instant::now() >= next {
            let _ = op
                .send(Message::Text(json!({"type": "ping", "id": id}).to_string().into()))
                .await;
            sent += 1;
            id += 1;
            next += Duration::from_millis(100);
        }
        let wait = next.saturating_duration_since(Instant::now());
        if let Ok(Some(Ok(Message::Text(t)))) = tokio::time::timeout(wait, op.next()).await {
            if t.contains("\"telemetry\"") {
                arrivals.push(Instant::now());
            } else {
                answer(&t, &mut answered);
            }
        }
    }
    // The last answers.
    let drain = Instant::now() + Duration::from_secs(2);
    while Instant::now() < drain {
        if let Ok(Some(Ok(Message::Text(t)))) = tokio::time::timeout(Duration::from_millis(100), op.next()).await {
            answer(&t, &mut answered);
        }
    }
    let _ = op.close(None).await;
    (sent, answered.len() as u64, arrivals)
}
