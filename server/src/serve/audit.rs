//! The audit trail: every command that changes the instrument (the lease taken, given back or
//! lost; push, scan, stop; haptic engage, release, re-centre and scale) and every push's end is
//! appended to `audit/audit.jsonl` in the data directory, one JSON object a line: `time` (UTC,
//! RFC 3339), `unix_ms`, `person`, `role`, `address`, `client`, `command`, its `args`, and the
//! `outcome` (`ok`, or `refused` with the error's `code` and `message`).
//!
//! A thread of its own writes each line with one `write` and `fdatasync`s it before the next:
//! a line the log holds is whole and on disk, whatever happens to the server afterwards
//! (kill -9, power loss). The log is in a directory of its own, so `/api/records` neither lists
//! nor serves it.

use std::collections::HashMap;
use std::io::Write as _;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{SystemTime, UNIX_EPOCH};

use nanopush_proto::ws::{ClientMessage, ErrorCode, Role};
use serde::Serialize;

use crate::serve::auth::Person;
use crate::serve::auth::tokens::role_name;

/// Who ran each push (by run number), for its record and its `run_done` line.
pub type RunPeople = Arc<Mutex<HashMap<u64, String>>>;

/// The log's path in a data directory.
pub fn log_path(data_dir: &Path) -> PathBuf {
    data_dir.join("audit").join("audit.jsonl")
}

/// The audit log.
pub struct Audit {
    tx: Option<Mutex<mpsc::Sender<String>>>,
    /// Who ran each push still running.
    pub runs: RunPeople,
    /// Entries that could not be written (counted in `/metrics`).
    pub failures: Arc<AtomicU64>,
    /// Entries written.
    pub written: Arc<AtomicU64>,
}

/// What the server did on an operator's behalf, for [`Audit::event`].
#[derive(Debug)]
pub struct Happened<'a> {
    /// Whose behalf.
    pub person: &'a str,
    /// From where, when a connection is concerned.
    pub address: Option<IpAddr>,
    /// Their session.
    pub client: Option<u32>,
    /// `lease_lost`, `run_done`.
    pub command: &'a str,
    /// Details (the run, the particle, the record).
    pub args: serde_json::Map<String, serde_json::Value>,
    /// What became of it.
    pub outcome: &'a str,
    /// In words.
    pub message: Option<&'a str>,
}

/// One line of the log.
#[derive(Debug, Serialize)]
struct Entry<'a> {
    time: String,
    unix_ms: u64,
    person: &'a str,
    role: &'a str,
    address: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    client: Option<u32>,
    command: &'a str,
    #[serde(skip_serializing_if = "serde_json::Map::is_empty")]
    args: serde_json::Map<String, serde_json::Value>,
    outcome: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    code: Option<ErrorCode>,
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

/// UTC time as RFC 3339 with milliseconds, from ms since the epoch (civil-from-days, H. Hinnant).
pub fn rfc3339(unix_ms: u64) -> String {
    let secs = unix_ms / 1000;
    let days = (secs / 86_400) as i64;
    let sod = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:03}Z",
        sod / 3600,
        sod / 60 % 60,
        sod % 60,
        unix_ms % 1000
    )
}

fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// A command's name and arguments, when it changes the instrument (None for `ping`,
/// `subscribe`).
pub fn describe(msg: &ClientMessage) -> Option<(&'static str, serde_json::Map<String, serde_json::Value>)> {
    let name = match msg {
        ClientMessage::Ping { .. } | ClientMessage::Subscribe { .. } => return None,
        ClientMessage::TakeLease { .. } => "take_lease",
        ClientMessage::ReleaseLease { .. } => "release_lease",
        ClientMessage::Push { .. } => "push",
        ClientMessage::Scan { .. } => "scan",
        ClientMessage::Stop { .. } => "stop",
        ClientMessage::Haptic { .. } => "haptic",
    };
    let mut args = match serde_json::to_value(msg) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => serde_json::Map::new(),
    };
    args.remove("type");
    args.retain(|_, v| !v.is_null());
    Some((name, args))
}

impl Audit {
    /// No log (tests, and a server before its data directory is known).
    pub fn off() -> Audit {
        Audit {
            tx: None,
            runs: RunPeople::default(),
            failures: Arc::default(),
            written: Arc::default(),
        }
    }

    /// The log in `data_dir` (created if missing), written by a thread of its own; `runs` is
    /// shared with the recorder (which names each push's person in its record).
    pub fn open(data_dir: &Path, runs: RunPeople) -> Audit {
        let path = log_path(data_dir);
        let (tx, rx) = mpsc::channel::<String>();
        let failures: Arc<AtomicU64> = Arc::default();
        let written: Arc<AtomicU64> = Arc::default();
        let (f2, w2) = (failures.clone(), written.clone());
        let spawned = std::thread::Builder::new()
            .name("audit".into())
            .spawn(move || writer(&path, &rx, &f2, &w2));
        if let Err(e) = spawned {
            tracing::error!("audit: cannot start its writer thread: {e}");
        }
        Audit {
            tx: Some(Mutex::new(tx)),
            runs,
            failures,
            written,
        }
    }

    fn append(&self, e: &Entry<'_>) {
        let Some(tx) = &self.tx else { return };
        match serde_json::to_string(e) {
            Ok(line) => {
                if tx.lock().map(|t| t.send(line)).is_err() {
                    self.failures.fetch_add(1, Relaxed);
                }
            }
            Err(_) => {
                self.failures.fetch_add(1, Relaxed);
            }
        }
    }

    /// A command from `person` at `address` on session `client`, and what became of it.
    pub fn command(
        &self,
        person: &Person,
        address: IpAddr,
        client: u32,
        (command, args): (&str, serde_json::Map<String, serde_json::Value>),
        refused: Option<(ErrorCode, &str)>,
    ) {
        let unix_ms = now_ms();
        self.append(&Entry {
            time: rfc3339(unix_ms),
            unix_ms,
            person: &person.name,
            role: role_name(person.role),
            address: address.to_string(),
            client: Some(client),
            command,
            args,
            outcome: if refused.is_some() { "refused" } else { "ok" },
            code: refused.map(|r| r.0),
            message: refused.map(|r| r.1),
        });
    }

    /// Something the server did on an operator's behalf (`lease_lost` when their connection
    /// closed, `run_done` when their push ended), with its `outcome`.
    pub fn event(&self, e: Happened<'_>) {
        let unix_ms = now_ms();
        self.append(&Entry {
            time: rfc3339(unix_ms),
            unix_ms,
            person: e.person,
            role: role_name(Role::Operator),
            address: e.address.map_or_else(|| "-".into(), |a| a.to_string()),
            client: e.client,
            command: e.command,
            args: e.args,
            outcome: e.outcome,
            code: None,
            message: e.message,
        });
    }

    /// The Prometheus text of the counters.
    pub fn render_metrics(&self) -> String {
        format!(
            "# HELP nanopush_audit_entries_total Audit log lines written (and fsynced).\n# TYPE nanopush_audit_entries_total counter\nnanopush_audit_entries_total {}\n# HELP nanopush_audit_failures_total Audit log lines that could not be written.\n# TYPE nanopush_audit_failures_total counter\nnanopush_audit_failures_total {}\n",
            self.written.load(Relaxed),
            self.failures.load(Relaxed)
        )
    }
}

/// Appends each line, whole, and syncs it to disk before the next.
fn writer(path: &Path, rx: &mpsc::Receiver<String>, failures: &AtomicU64, written: &AtomicU64) {
    let open = || {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::OpenOptions::new().create(true).append(true).open(path)
    };
    let mut file = match open() {
        Ok(f) => Some(f),
        Err(e) => {
            tracing::error!("audit: cannot open {}: {e}", path.display());
            None
        }
    };
    while let Ok(mut line) = rx.recv() {
        line.push('\n');
        if file.is_none() {
            file = open().ok();
        }
        let ok = file
            .as_mut()
            .ok_or_else(|| std::io::Error::other("not open"))
            .and_then(|f| f.write_all(line.as_bytes()).and_then(|()| f.sync_data()));
        match ok {
            Ok(()) => {
                written.fetch_add(1, Relaxed);
            }
            Err(e) => {
                failures.fetch_add(1, Relaxed);
                tracing::error!(
                    "audit: writing {}: {e}; the entry was: {}",
                    path.display(),
                    line.trim_end()
                );
                file = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_are_utc_rfc3339_with_milliseconds() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(rfc3339(951_782_400_123), "2000-02-29T00:00:00.123Z");
        assert_eq!(rfc3339(1_798_761_599_999), "2026-12-31T23:59:59.999Z");
    }

    #[test]
    fn commands_that_change_the_instrument_are_described_and_the_others_are_not() {
        let push: ClientMessage =
            serde_json::from_str(r#"{"type":"push","id":4,"particle":2,"distance_um":0.5,"direction_deg":90}"#)
                .unwrap();
        let (name, args) = describe(&push).unwrap();
        assert_eq!(name, "push");
        assert_eq!(
            serde_json::Value::Object(args),
            serde_json::json!({"id": 4, "particle": 2, "distance_um": 0.5, "direction_deg": 90.0})
        );
        let ping: ClientMessage = serde_json::from_str(r#"{"type":"ping"}"#).unwrap();
        assert!(describe(&ping).is_none());
    }

    #[test]
    fn each_entry_is_one_whole_json_line_on_disk() {
        let dir = std::env::temp_dir().join(format!("nanopush-audit-{}", std::process::id()));
        let a = Audit::open(&dir, RunPeople::default());
        let alice = Person {
            name: "alice".into(),
            role: Role::Operator,
            key: "k".into(),
        };
        let stop: ClientMessage = serde_json::from_str(r#"{"type":"stop"}"#).unwrap();
        a.command(&alice, "10.0.0.7".parse().unwrap(), 3, describe(&stop).unwrap(), None);
        a.command(
            &alice,
            "10.0.0.7".parse().unwrap(),
            3,
            describe(&stop).unwrap(),
            Some((ErrorCode::NoLease, "needs the lease")),
        );
        let path = log_path(&dir);
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while a.written.load(Relaxed) < 2 && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert_eq!(lines[0]["person"], "alice");
        assert_eq!(lines[0]["address"], "10.0.0.7");
        assert_eq!(lines[0]["command"], "stop");
        assert_eq!(lines[0]["outcome"], "ok");
        assert_eq!(lines[1]["outcome"], "refused");
        assert_eq!(lines[1]["code"], "no_lease");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
