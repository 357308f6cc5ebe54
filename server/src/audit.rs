//! The audit trail: every command the table of commands audits (`session/commands`: those that
//! change the instrument), the lease lost with its holder's connection, and every push's end are
//! appended to `audit/audit.jsonl` in the data directory, one JSON object a line: `time` (UTC,
//! RFC 3339), `unix_ms`, `person`, `role`, `address`, `client`, `command`, its `args`, and the
//! `outcome` (`ok`, or `refused` with the error's `code` and `message`).
//!
//! A thread of its own writes the lines queued since its last write with one `write` and one
//! `fdatasync` (a group commit): a line the log holds is whole and on disk, whatever happens to
//! the server afterwards (kill -9, power loss), and a line is queued before its command's answer
//! is sent and on disk after one commit (one write and one sync). The answer does not wait for
//! the disk:
//! a command's events (a lease change, a `run_done`) must not overtake its `ok`, and a stop
//! waits for nothing; a kill -9 before that commit can lose the line of a command whose `ok`
//! was sent. A write that fails part way (a full disk) is cut back to the last whole line.
//! Refused commands are logged at most [`REFUSED_IN_FLIGHT`] queued at once: a flood of refused
//! commands (a viewer's script) cannot queue ahead of the operator's lines or grow without
//! bound (12,000 queued refusals would keep an operator's `ok`ed commands off the disk for ~40 s);
//! what it sheds is counted in a line of its own (`refusals_not_logged`) and in `/metrics`. The
//! log is in a directory of its own, so `/api/records` neither lists nor serves it.

use std::collections::HashMap;
use std::io::Write as _;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, mpsc};

use nanopush_proto::ws::{ErrorCode, Role};
use serde::Serialize;

use crate::auth::Person;
use crate::auth::tokens::role_name;
use crate::clock::{rfc3339, unix_ms};

/// Who ran each push (by run number), for its record and its `run_done` line.
pub type RunPeople = Arc<Mutex<HashMap<u64, String>>>;

/// The log's path in a data directory.
pub fn log_path(data_dir: &Path) -> PathBuf {
    data_dir.join("audit").join("audit.jsonl")
}

/// Refused commands' lines queued at most, not yet written.
pub const REFUSED_IN_FLIGHT: usize = 256;
/// Lines written with one write and one sync at most.
const BATCH: usize = 1024;

/// A line to write, and who waits for it to be on disk.
struct Job {
    line: String,
    refused: bool,
    done: Option<tokio::sync::oneshot::Sender<bool>>,
}

/// A line's durability: resolves `true` once it is on disk, `false` if it could not be written.
pub type Durable = tokio::sync::oneshot::Receiver<bool>;

/// The audit log.
pub struct Audit {
    tx: Option<Mutex<mpsc::Sender<Job>>>,
    /// Refused commands' lines queued and not yet written.
    refused_queued: Arc<AtomicUsize>,
    /// Refused commands' lines not logged (the queue was full).
    pub shed: Arc<AtomicU64>,
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

impl Audit {
    /// No log (tests, and a server before its data directory is known).
    pub fn off() -> Audit {
        Audit {
            tx: None,
            refused_queued: Arc::default(),
            shed: Arc::default(),
            runs: RunPeople::default(),
            failures: Arc::default(),
            written: Arc::default(),
        }
    }

    /// The log in `data_dir` (created if missing), written by a thread of its own; `runs` is
    /// shared with the recorder (which names each push's person in its record).
    pub fn open(data_dir: &Path, runs: RunPeople) -> Audit {
        let path = log_path(data_dir);
        let (tx, rx) = mpsc::channel::<Job>();
        let failures: Arc<AtomicU64> = Arc::default();
        let written: Arc<AtomicU64> = Arc::default();
        let refused_queued: Arc<AtomicUsize> = Arc::default();
        let shed: Arc<AtomicU64> = Arc::default();
        let w = Writer {
            path,
            failures: failures.clone(),
            written: written.clone(),
            refused_queued: refused_queued.clone(),
            shed: shed.clone(),
            shed_logged: 0,
        };
        let spawned = std::thread::Builder::new()
            .name("audit".into())
            .spawn(move || w.run(&rx));
        if let Err(e) = spawned {
            tracing::error!("audit: cannot start its writer thread: {e}");
        }
        Audit {
            tx: Some(Mutex::new(tx)),
            refused_queued,
            shed,
            runs,
            failures,
            written,
        }
    }

    /// Queues a line; an accepted command's line comes with its [`Durable`]. A refused one is
    /// shed (counted) when [`REFUSED_IN_FLIGHT`] are already queued.
    fn append(&self, e: &Entry<'_>, refused: bool) -> Option<Durable> {
        let tx = self.tx.as_ref()?;
        let Ok(line) = serde_json::to_string(e) else {
            self.failures.fetch_add(1, Relaxed);
            return None;
        };
        if refused && self.refused_queued.fetch_add(1, Relaxed) >= REFUSED_IN_FLIGHT {
            self.refused_queued.fetch_sub(1, Relaxed);
            self.shed.fetch_add(1, Relaxed);
            return None;
        }
        let (done, durable) = if refused {
            (None, None)
        } else {
            let (t, r) = tokio::sync::oneshot::channel();
            (Some(t), Some(r))
        };
        let job = Job { line, refused, done };
        if tx.lock().map(|t| t.send(job)).map_or(true, |r| r.is_err()) {
            self.failures.fetch_add(1, Relaxed);
            if refused {
                self.refused_queued.fetch_sub(1, Relaxed);
            }
            return None;
        }
        durable
    }

    /// A command from `person` at `address` on session `client`, and what became of it. An
    /// accepted command's line comes with its [`Durable`]: its `ok` waits for it.
    pub fn command(
        &self,
        person: &Person,
        address: IpAddr,
        client: u32,
        (command, args): (&str, serde_json::Map<String, serde_json::Value>),
        refused: Option<(ErrorCode, &str)>,
    ) -> Option<Durable> {
        let unix_ms = unix_ms();
        self.append(
            &Entry {
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
            },
            refused.is_some(),
        )
    }

    /// Something the server did on an operator's behalf (`lease_lost` when their connection
    /// closed, `run_done` when their push ended), with its `outcome`.
    pub fn event(&self, e: Happened<'_>) {
        let unix_ms = unix_ms();
        let _ = self.append(
            &Entry {
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
            },
            false,
        );
    }

    /// A push's end (`run_done`), under the person who ran it ([`Audit::runs`], forgotten now),
    /// with its record.
    pub fn run_done(&self, run: u64, particle: u32, outcome: &str, failure: Option<&str>, record: Option<&str>) {
        let person = self.runs.lock().ok().and_then(|mut p| p.remove(&run));
        let mut args = serde_json::Map::new();
        args.insert("run".into(), run.into());
        args.insert("particle".into(), particle.into());
        if let Some(r) = record {
            args.insert("record".into(), r.into());
        }
        self.event(Happened {
            person: person.as_deref().unwrap_or("unknown"),
            address: None,
            client: None,
            command: "run_done",
            args,
            outcome,
            message: failure,
        });
    }

    /// The Prometheus text of the counters.
    pub fn render_metrics(&self) -> String {
        format!(
            "# HELP nanopush_audit_entries_total Audit log lines written (and fsynced).\n# TYPE nanopush_audit_entries_total counter\nnanopush_audit_entries_total {}\n# HELP nanopush_audit_failures_total Audit log lines that could not be written.\n# TYPE nanopush_audit_failures_total counter\nnanopush_audit_failures_total {}\n# HELP nanopush_audit_refusals_shed_total Refused commands not logged because too many were queued (a flood).\n# TYPE nanopush_audit_refusals_shed_total counter\nnanopush_audit_refusals_shed_total {}\n",
            self.written.load(Relaxed),
            self.failures.load(Relaxed),
            self.shed.load(Relaxed)
        )
    }
}

/// The writer thread's side.
struct Writer {
    path: PathBuf,
    failures: Arc<AtomicU64>,
    written: Arc<AtomicU64>,
    refused_queued: Arc<AtomicUsize>,
    shed: Arc<AtomicU64>,
    /// Shed refusals already said in the log.
    shed_logged: u64,
}

impl Writer {
    fn open(&self) -> std::io::Result<std::fs::File> {
        if let Some(dir) = self.path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::OpenOptions::new().create(true).append(true).open(&self.path)
    }

    /// Writes what is queued, a batch at a time: one write, one sync, then the waiting told.
    fn run(mut self, rx: &mpsc::Receiver<Job>) {
        let mut file = match self.open() {
            Ok(f) => Some(f),
            Err(e) => {
                tracing::error!("audit: cannot open {}: {e}", self.path.display());
                None
            }
        };
        while let Ok(first) = rx.recv() {
            let mut jobs = vec![first];
            while jobs.len() < BATCH {
                match rx.try_recv() {
                    Ok(j) => jobs.push(j),
                    Err(_) => break,
                }
            }
            let refused = jobs.iter().filter(|j| j.refused).count();
            self.refused_queued.fetch_sub(refused, Relaxed);
            let mut text = String::new();
            let shed = self.shed.load(Relaxed);
            if shed > self.shed_logged {
                let unix_ms = unix_ms();
                let said = serde_json::json!({
                    "time": rfc3339(unix_ms), "unix_ms": unix_ms, "person": "-", "role": "-",
                    "address": "-", "command": "refusals_not_logged", "outcome": "shed",
                    "message": format!("{} refused commands were not logged: too many queued at once", shed - self.shed_logged),
                });
                text.push_str(&said.to_string());
                text.push('\n');
            }
            for j in &jobs {
                text.push_str(&j.line);
                text.push('\n');
            }
            if file.is_none() {
                file = self.open().ok();
            }
            let ok = match file.as_mut() {
                Some(f) => write_whole(f, text.as_bytes()),
                None => Err(std::io::Error::other("not open")),
            };
            let on_disk = ok.is_ok();
            match ok {
                Ok(()) => {
                    self.shed_logged = shed;
                    self.written.fetch_add(jobs.len() as u64, Relaxed);
                }
                Err(e) => {
                    self.failures.fetch_add(jobs.len() as u64, Relaxed);
                    tracing::error!(
                        "audit: writing {}: {e}; {} entries lost, the first: {}",
                        self.path.display(),
                        jobs.len(),
                        jobs[0].line
                    );
                    file = None;
                }
            }
            for j in jobs {
                if let Some(done) = j.done {
                    let _ = done.send(on_disk);
                }
            }
        }
    }
}

/// Appends `bytes` and syncs them; a write that fails part way is cut back to where it began,
/// so the file holds whole lines only.
fn write_whole(f: &mut std::fs::File, bytes: &[u8]) -> std::io::Result<()> {
    let before = f.metadata()?.len();
    let r = f.write_all(bytes).and_then(|()| f.sync_data());
    if r.is_err() {
        let _ = f.set_len(before).and_then(|()| f.sync_data());
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_entry_is_one_whole_json_line_on_disk() {
        let dir = std::env::temp_dir().join(format!("nanopush-audit-{}", std::process::id()));
        let a = Audit::open(&dir, RunPeople::default());
        let alice = Person {
            name: "alice".into(),
            role: Role::Operator,
            key: "k".into(),
        };
        let stop = || ("stop", serde_json::Map::new());
        a.command(&alice, "10.0.0.7".parse().unwrap(), 3, stop(), None);
        a.command(
            &alice,
            "10.0.0.7".parse().unwrap(),
            3,
            stop(),
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
