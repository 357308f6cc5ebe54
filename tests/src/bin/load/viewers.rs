//! The viewers: WebSocket clients subscribed to `tip`, each counting what it receives.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::client::Ws;
use serde_json::{Value, json};
use tokio::sync::{Semaphore, mpsc};
use tokio_tungstenite::tungstenite::Message;

/// What one viewer received (counters only grow; the window takes differences).
#[derive(Debug, Default)]
pub struct Stats {
    pub telemetry: AtomicU64,
    pub lagged: AtomicU64,
    pub skipped: AtomicU64,
    pub other: AtomicU64,
    pub shutdown: AtomicBool,
    pub close_frame: AtomicBool,
    pub closed: AtomicBool,
}

impl Stats {
    /// Counts one text message.
    fn take(&self, text: &str) {
        // The fast path: serde writes the tag first.
        if text.starts_with(r#"{"type":"telemetry""#) {
            self.telemetry.fetch_add(1, Relaxed);
            return;
        }
        let v: Value = serde_json::from_str(text).unwrap_or(Value::Null);
        match v["type"].as_str() {
            Some("telemetry") => {
                self.telemetry.fetch_add(1, Relaxed);
            }
            Some("lagged") => {
                self.lagged.fetch_add(1, Relaxed);
                self.skipped.fetch_add(v["skipped"].as_u64().unwrap_or(0), Relaxed);
            }
            Some("shutdown") => self.shutdown.store(true, Relaxed),
            _ => {
                self.other.fetch_add(1, Relaxed);
            }
        }
    }
}

/// Connects, subscribes to `tip` and waits for the `ok`.
async fn connect_and_subscribe(addr: &str, stats: &Stats) -> Result<Ws, String> {
    let url = nanopush_e2e::client::ws_url(addr, None);
    let mut attempt = 0;
    let mut ws = loop {
        match tokio::time::timeout(Duration::from_secs(10), tokio_tungstenite::connect_async(url.as_str())).await {
            Ok(Ok((ws, _))) => break ws,
            Ok(Err(e)) if attempt >= 5 => return Err(format!("connecting: {e}")),
            Ok(Err(_)) => {
                attempt += 1;
                tokio::time::sleep(Duration::from_millis(50 * attempt)).await;
            }
            Err(_) => return Err("connecting: no upgrade within 10 s".into()),
        }
    };
    let sub = json!({"type": "subscribe", "streams": ["tip"], "id": 1}).to_string();
    ws.send(Message::Text(sub.into()))
        .await
        .map_err(|e| format!("subscribing: {e}"))?;
    let wait_ok = async {
        while let Some(m) = ws.next().await {
            let Ok(Message::Text(t)) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).unwrap_or(Value::Null);
            match v["type"].as_str() {
                Some("ok") if v["id"] == 1 => return Ok(()),
                Some("error") => return Err(format!("subscribe refused: {t}")),
                _ => stats.take(t.as_str()),
            }
        }
        Err("closed before the subscription was confirmed".to_string())
    };
    tokio::time::timeout(Duration::from_secs(10), wait_ok)
        .await
        .map_err(|_| "no ok to the subscription within 10 s".to_string())??;
    Ok(ws)
}

/// One viewer: connects (at most [`crate::CONNECT_CONCURRENCY`] at once, through `gate`), says on
/// `ready` whether it subscribed, then counts what it receives until the server closes.
pub async fn viewer(
    addr: Arc<str>,
    stats: Arc<Stats>,
    gate: Arc<Semaphore>,
    ready: mpsc::UnboundedSender<Result<(), String>>,
) {
    let permit = gate.acquire_owned().await;
    let ws = connect_and_subscribe(&addr, &stats).await;
    drop(permit);
    let mut ws = match ws {
        Ok(ws) => ws,
        Err(e) => {
            stats.closed.store(true, Relaxed);
            let _ = ready.send(Err(e));
            return;
        }
    };
    let _ = ready.send(Ok(()));
    while let Some(m) = ws.next().await {
        match m {
            Ok(Message::Text(t)) => stats.take(t.as_str()),
            Ok(Message::Close(_)) => {
                stats.close_frame.store(true, Relaxed);
                break;
            }
            Err(_) => break,
            Ok(_) => {}
        }
    }
    stats.closed.store(true, Relaxed);
}

/// Per viewer: the telemetry frames and the frames skipped so far, and whether it has closed.
pub fn counters(stats: &[Arc<Stats>]) -> Vec<(u64, u64, bool)> {
    stats
        .iter()
        .map(|s| {
            (
                s.telemetry.load(Relaxed),
                s.skipped.load(Relaxed),
                s.closed.load(Relaxed),
            )
        })
        .collect()
}
