//! The audit trail: every command the table of commands audits (`session/commands`: those that
//! change the instrument), the lease lost with its holder's connection, and every push's end are
//! appended to `audit/audit.jsonl` in the data directory, one JSON object a line: `time` (UTC,
//! RFC 3339), `unix_ms`, `person`, `role`, `address`, `client`, `command`, its `args`, and the
//! `outcome` (`ok`, or `refused` with the error's `code` and `message`).
//!
//! A thread of its own (`writer.rs`) writes the lines queued since its last write with one
//! `write` and one `fdatasync` (a group commit): a line the log holds is whole and on disk,
//! whatever happens to the server afterwards (kill -9, power loss), and a line is queued before
//! its command's answer is sent and on disk after one commit (one write and one sync). The answer
//! does not wait for the disk: a command's events (a lease change, a `run_done`) must not overtake
//! its `ok`, and a stop waits for nothing; a kill -9 before that commit can lose the line of a
//! command whose `ok` was sent. A write that fails part way (a full disk) is cut back to the last
//! whole line. The log is in a directory of its own, so `/api/records` neither lists nor serves it.
//!
//! What a hostile client can make it write is bounded twice. Refused commands are logged one by
//! one up to a budget per client (a named person, or an anonymous viewer's address), and counted
//! beyond it in summary lines (`refusals.rs`): a viewer's script asking for the lease 45 times a
//! second on 30 sockets adds a few lines a minute. And the log's files hold at most
//! `--audit-max-bytes` in all: `audit.jsonl` is rotated to `audit.jsonl.1` … `.3` and the oldest
//! part deleted (`writer.rs`), counted in `/metrics`. Refused commands' lines are also queued at
//! most [`REFUSED_IN_FLIGHT`] at once, so
//! that many clients' refusals at once cannot queue ahead of the operator's lines (what is shed
//! is counted in a line of its own, `refusals_not_logged`, and in `/metrics`).

pub mod refusals;
mod writer;

use std::collections::HashMap;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex, mpsc};
use std::time::Instant;

use nanopush_proto::ws::{ErrorCode, Role};
use serde::Serialize;

use self::refusals::Refusals;
use self::writer::{Job, Writer};
use crate::auth::Person;
use crate::auth::tokens::role_name;
use crate::clock::{rfc3339, unix_ms};

pub use self::writer::{Counters, PARTS};

/// Who ran each push (by run number), for its record and its `run_done` line.
pub type RunPeople = Arc<Mutex<HashMap<u64, String>>>;

/// The log's path in a data directory.
pub fn log_path(data_dir: &Path) -> PathBuf {
    data_dir.join("audit").join("audit.jsonl")
}

/// Refused commands' lines queued at most, not yet written.
pub const REFUSED_IN_FLIGHT: usize = 256;

/// The cap on the log's files by default (bytes): 1 GiB, years of a lab's commands.
pub const MAX_BYTES_DEFAULT: u64 = 1 << 30;

/// The smallest cap allowed (bytes).
pub const MAX_BYTES_MIN: u64 = 64 * 1024;

/// A line's durability: resolves `true` once it is on disk, `false` if it could not be written.
pub type Durable = tokio::sync::oneshot::Receiver<bool>;

/// The audit log.
pub struct Audit {
    tx: Option<Mutex<mpsc::Sender<Job>>>,
    /// Refusals per client, for the budget and the summaries (shared with the writer).
    refusals: Arc<Mutex<Refusals>>,
    /// Who ran each push still running.
    pub runs: RunPeople,
    /// What `/metrics` shows.
    pub counters: Arc<Counters>,
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
            refusals: Arc::default(),
            runs: RunPeople::default(),
            counters: Arc::default(),
        }
    }

    /// The log in `data_dir` (created if missing), its files at most `max_bytes` in all, written
    /// by a thread of its own; `runs` is shared with the recorder (which names each push's person
    /// in its record).
    pub fn open(data_dir: &Path, runs: RunPeople, max_bytes: u64) -> Audit {
        let (tx, rx) = mpsc::channel::<Job>();
        let counters = Arc::new(Counters::default());
        counters.max_bytes.store(max_bytes, Relaxed);
        let refusals: Arc<Mutex<Refusals>> = Arc::default();
        let w = Writer {
            path: log_path(data_dir),
            counters: counters.clone(),
            refusals: refusals.clone(),
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
            refusals,
            runs,
            counters,
        }
    }

    /// Queues a line; an accepted command's line comes with its [`Durable`]. A refused one is
    /// shed (counted) when [`REFUSED_IN_FLIGHT`] are already queued.
    fn append(&self, e: &Entry<'_>, refused: bool) -> Option<Durable> {
        let tx = self.tx.as_ref()?;
        let c = &self.counters;
        let Ok(line) = serde_json::to_string(e) else {
            c.failures.fetch_add(1, Relaxed);
            return None;
        };
        if refused && c.refused_queued.fetch_add(1, Relaxed) >= REFUSED_IN_FLIGHT {
            c.refused_queued.fetch_sub(1, Relaxed);
            c.shed.fetch_add(1, Relaxed);
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
            c.failures.fetch_add(1, Relaxed);
            if refused {
                c.refused_queued.fetch_sub(1, Relaxed);
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
        self.tx.as_ref()?;
        let unix_ms = unix_ms();
        if let Some(r) = refused {
            // Beyond its client's budget, a refusal is counted for a summary instead.
            let who = (person.name.as_str(), person.role, person.is_anonymous());
            let one_by_one = self.refusals.lock().map_or(true, |mut all| {
                all.refused(who, address, command, r, (Instant::now(), unix_ms))
            });
            if !one_by_one {
                self.counters.summarised.fetch_add(1, Relaxed);
                return None;
            }
        }
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
        let c = &self.counters;
        let mut s = String::new();
        for (name, kind, help, v) in [
            (
                "nanopush_audit_entries_total",
                "counter",
                "Audit log lines written (and fsynced).",
                &c.written,
            ),
            (
                "nanopush_audit_failures_total",
                "counter",
                "Audit log lines that could not be written.",
                &c.failures,
            ),
            (
                "nanopush_audit_refusals_shed_total",
                "counter",
                "Refused commands not logged because too many were queued (a flood).",
                &c.shed,
            ),
            (
                "nanopush_audit_refusals_summarised_total",
                "counter",
                "Refused commands beyond their client's budget, counted in summary lines instead of logged one by one.",
                &c.summarised,
            ),
            (
                "nanopush_audit_log_bytes",
                "gauge",
                "Size of the audit log's files in all (audit.jsonl and its older parts).",
                &c.bytes,
            ),
            (
                "nanopush_audit_log_max_bytes",
                "gauge",
                "The cap on the audit log's files (--audit-max-bytes).",
                &c.max_bytes,
            ),
            (
                "nanopush_audit_rotations_total",
                "counter",
                "Times audit.jsonl was renamed to audit.jsonl.1 to stay within the cap.",
                &c.rotations,
            ),
            (
                "nanopush_audit_deleted_bytes_total",
                "counter",
                "Bytes of the oldest audit lines deleted to stay within the cap.",
                &c.deleted_bytes,
            ),
        ] {
            s.push_str(&format!(
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {}\n",
                v.load(Relaxed)
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_entry_is_one_whole_json_line_on_disk() {
        let dir = std::env::temp_dir().join(format!("nanopush-audit-{}", std::process::id()));
        let a = Audit::open(&dir, RunPeople::default(), MAX_BYTES_DEFAULT);
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
        while a.counters.written.load(Relaxed) < 2 && std::time::Instant::now() < deadline {
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
