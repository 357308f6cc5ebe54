//! The audit log's writer thread: the lines queued since its last write, in one write and one
//! `fdatasync` (a group commit), into `audit.jsonl`; the refusals' summaries as they fall due
//! ([`super::refusals`]); and the log kept within its cap by rotation: `audit.jsonl` is renamed
//! `audit.jsonl.1` (`.1` to `.2`, and so on) when it would grow past a quarter of the cap, and
//! the oldest part, `audit.jsonl.3`, is deleted, so that the log's [`PARTS`] files hold at most
//! the cap in all, the newest lines kept.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use super::refusals::{Refusals, Summary};
use crate::auth::tokens::role_name;
use crate::clock::{rfc3339, unix_ms};

/// The log's files: `audit.jsonl` and `audit.jsonl.1` to `audit.jsonl.{PARTS - 1}`.
pub const PARTS: u64 = 4;

/// Lines written with one write and one sync at most.
const BATCH: usize = 1024;

/// How often the writer wakes, with nothing queued, for the summaries that fell due.
const SUMMARY_POLL: Duration = Duration::from_millis(500);

/// A line to write, and who waits for it to be on disk.
pub(super) struct Job {
    pub line: String,
    pub refused: bool,
    pub done: Option<tokio::sync::oneshot::Sender<bool>>,
}

/// What the writer and the log's handle share: the counters of `/metrics`.
#[derive(Debug, Default)]
pub struct Counters {
    /// Lines written (and synced).
    pub written: AtomicU64,
    /// Lines that could not be written.
    pub failures: AtomicU64,
    /// Refused commands' lines not logged because too many were queued.
    pub shed: AtomicU64,
    /// Refused commands' lines queued and not yet written.
    pub refused_queued: AtomicUsize,
    /// Refused commands counted in summaries instead of logged one by one.
    pub summarised: AtomicU64,
    /// The log's files' size in all (bytes).
    pub bytes: AtomicU64,
    /// The cap on it.
    pub max_bytes: AtomicU64,
    /// Times `audit.jsonl` was renamed to make room.
    pub rotations: AtomicU64,
    /// Bytes of old lines deleted to stay within the cap.
    pub deleted_bytes: AtomicU64,
}

/// The writer thread's side.
pub(super) struct Writer {
    pub path: PathBuf,
    pub counters: Arc<Counters>,
    pub refusals: Arc<Mutex<Refusals>>,
    /// Shed refusals already said in the log.
    pub shed_logged: u64,
}

/// How often a failing log says so in the server's log: a full disk fails every batch.
const ERROR_EVERY: std::time::Duration = std::time::Duration::from_secs(10);

/// Failures said at most once a period: each report counts the entries lost since the last.
#[derive(Debug, Default)]
struct Throttle {
    last: Option<Instant>,
    lost: u64,
}

impl Throttle {
    /// `lost` more entries lost at `now`: the count to report now, if a report is due.
    fn failed(&mut self, lost: u64, now: Instant) -> Option<u64> {
        self.lost += lost;
        if self.last.is_some_and(|t| now.duration_since(t) < ERROR_EVERY) {
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.lost))
    }

    /// A write succeeded: the entries lost and not yet reported, if the log was failing.
    fn recovered(&mut self) -> Option<u64> {
        self.last.take().map(|_| std::mem::take(&mut self.lost))
    }
}

/// `path` with `.N` after its name (`audit.jsonl.1`); `path` itself for 0.
fn part(path: &Path, n: u64) -> PathBuf {
    if n == 0 {
        return path.to_path_buf();
    }
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".{n}"));
    path.with_file_name(name)
}

fn size(path: &Path) -> u64 {
    std::fs::metadata(path).map_or(0, |m| m.len())
}

/// A summary as a line of the log.
fn summary_line(s: &Summary) -> String {
    let unix_ms = unix_ms();
    serde_json::json!({
        "time": rfc3339(unix_ms), "unix_ms": unix_ms, "person": s.person, "role": role_name(s.role),
        "address": s.address, "command": s.command, "outcome": "refused_summary",
        "args": {"refused": s.count, "first_unix_ms": s.first_unix_ms, "last_unix_ms": s.last_unix_ms},
        "code": s.code, "message": s.text(),
    })
    .to_string()
}

impl Writer {
    fn open(&self) -> std::io::Result<std::fs::File> {
        if let Some(dir) = self.path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::OpenOptions::new().create(true).append(true).open(&self.path)
    }

    /// Each part's size limit: a quarter of the cap.
    fn part_max(&self) -> u64 {
        self.counters.max_bytes.load(Relaxed) / PARTS
    }

    /// The files' size in all, as they are on disk.
    fn total(&self) -> u64 {
        (0..PARTS).map(|n| size(&part(&self.path, n))).sum()
    }

    /// `audit.jsonl` becomes `.1` (and each older part one older), the oldest is deleted, and a
    /// new `audit.jsonl` is begun.
    fn rotate(&self) -> std::io::Result<std::fs::File> {
        let oldest = part(&self.path, PARTS - 1);
        let gone = size(&oldest);
        match std::fs::remove_file(&oldest) {
            Ok(()) => {
                self.counters.deleted_bytes.fetch_add(gone, Relaxed);
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        for n in (0..PARTS - 1).rev() {
            match std::fs::rename(part(&self.path, n), part(&self.path, n + 1)) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
        // The renames made durable before the new lines, best effort.
        if let Some(dir) = self.path.parent() {
            let _ = std::fs::File::open(dir).and_then(|d| d.sync_all());
        }
        self.counters.rotations.fetch_add(1, Relaxed);
        tracing::info!(
            "audit: {} reached {} bytes and is now {}; {gone} bytes of the oldest lines deleted (--audit-max-bytes {})",
            self.path.display(),
            self.part_max(),
            part(&self.path, 1).display(),
            self.counters.max_bytes.load(Relaxed)
        );
        self.open()
    }

    /// Writes `text` (whole lines), rotating first whenever the next line would take
    /// `audit.jsonl` past its part of the cap: each chunk one write and one sync.
    fn write_lines(&self, file: &mut Option<std::fs::File>, text: &str) -> std::io::Result<()> {
        let part_max = self.part_max().max(1);
        let mut rest = text;
        while !rest.is_empty() {
            if file.is_none() {
                *file = Some(self.open()?);
            }
            let f = file.as_mut().expect("opened above");
            let room = part_max.saturating_sub(f.metadata()?.len());
            // The longest run of whole lines that fits, or one line alone into an empty part.
            let mut end = 0;
            for (i, _) in rest.match_indices('\n') {
                if (i + 1) as u64 > room {
                    break;
                }
                end = i + 1;
            }
            if end == 0 {
                if room < part_max {
                    *file = Some(self.rotate()?);
                    continue;
                }
                end = rest.find('\n').map_or(rest.len(), |i| i + 1);
            }
            write_whole(f, &rest.as_bytes()[..end])?;
            rest = &rest[end..];
        }
        Ok(())
    }

    /// Writes what is queued, a batch at a time, and the summaries as they fall due; when the
    /// log closes (the handle dropped), the summaries still counted.
    pub fn run(mut self, rx: &mpsc::Receiver<Job>) {
        let mut file = match self.open() {
            Ok(f) => Some(f),
            Err(e) => {
                tracing::error!("audit: cannot open {}: {e}", self.path.display());
                None
            }
        };
        self.counters.bytes.store(self.total(), Relaxed);
        let mut errors = Throttle::default();
        loop {
            let (jobs, closing) = match rx.recv_timeout(SUMMARY_POLL) {
                Ok(first) => {
                    let mut jobs = vec![first];
                    while jobs.len() < BATCH {
                        match rx.try_recv() {
                            Ok(j) => jobs.push(j),
                            Err(_) => break,
                        }
                    }
                    (jobs, false)
                }
                Err(mpsc::RecvTimeoutError::Timeout) => (Vec::new(), false),
                Err(mpsc::RecvTimeoutError::Disconnected) => (Vec::new(), true),
            };
            let refused = jobs.iter().filter(|j| j.refused).count();
            self.counters.refused_queued.fetch_sub(refused, Relaxed);
            let summaries = self
                .refusals
                .lock()
                .map(|mut r| r.due(Instant::now(), closing))
                .unwrap_or_default();
            let mut text = String::new();
            let shed = self.counters.shed.load(Relaxed);
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
            for s in &summaries {
                text.push_str(&summary_line(s));
                text.push('\n');
            }
            for j in &jobs {
                text.push_str(&j.line);
                text.push('\n');
            }
            if !text.is_empty() {
                let lines = jobs.len() + summaries.len();
                let ok = self.write_lines(&mut file, &text);
                self.counters.bytes.store(self.total(), Relaxed);
                match &ok {
                    Ok(()) => {
                        self.shed_logged = shed;
                        self.counters.written.fetch_add(lines as u64, Relaxed);
                        if let Some(lost) = errors.recovered() {
                            tracing::warn!(
                                "audit: writing {} again; {lost} more entries were lost before",
                                self.path.display()
                            );
                        }
                    }
                    Err(e) => {
                        self.counters.failures.fetch_add(lines as u64, Relaxed);
                        if let Some(lost) = errors.failed(lines as u64, Instant::now()) {
                            tracing::error!(
                                "audit: writing {}: {e}; {lost} entries lost since the last report (some may be on disk; said at most every {} s), the latest: {}",
                                self.path.display(),
                                ERROR_EVERY.as_secs(),
                                text.lines().next().unwrap_or("")
                            );
                        }
                        file = None;
                    }
                }
                for j in jobs {
                    if let Some(done) = j.done {
                        let _ = done.send(ok.is_ok());
                    }
                }
            }
            if closing {
                return;
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

    /// A log that fails on every batch says so once per period, with the count lost between.
    #[test]
    fn failures_are_reported_at_most_every_ten_seconds_with_their_count() {
        let t0 = Instant::now();
        let mut t = Throttle::default();
        assert_eq!(t.failed(3, t0), Some(3));
        assert_eq!(t.failed(5, t0 + std::time::Duration::from_secs(1)), None);
        assert_eq!(t.failed(7, t0 + std::time::Duration::from_secs(9)), None);
        assert_eq!(t.failed(1, t0 + std::time::Duration::from_secs(10)), Some(13));
        assert_eq!(t.failed(2, t0 + std::time::Duration::from_secs(11)), None);
        assert_eq!(t.recovered(), Some(2));
        assert_eq!(t.recovered(), None, "said once");
        assert_eq!(
            t.failed(4, t0 + std::time::Duration::from_secs(12)),
            Some(4),
            "a new failure is said at once"
        );
    }

    fn writer(dir: &Path, max: u64) -> Writer {
        let counters = Arc::new(Counters::default());
        counters.max_bytes.store(max, Relaxed);
        Writer {
            path: dir.join("audit.jsonl"),
            counters,
            refusals: Arc::default(),
            shed_logged: 0,
        }
    }

    /// Lines written past a part's quarter of the cap rotate the log: four files, at most the cap
    /// in all, the newest lines kept in order, the oldest deleted and counted.
    #[test]
    fn the_log_rotates_within_its_cap_keeping_the_newest_lines() {
        let dir = std::env::temp_dir().join(format!("nanopush-audit-rotate-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let w = writer(&dir, 4000);
        let mut file = None;
        // 100 lines of 100 bytes (with their newline), in batches of 7: 10,000 bytes for a cap of 4,000.
        let lines: Vec<String> = (0..100).map(|i| format!("{i:099}")).collect();
        for batch in lines.chunks(7) {
            let text: String = batch.iter().map(|l| format!("{l}\n")).collect();
            w.write_lines(&mut file, &text).unwrap();
        }
        let parts: Vec<u64> = (0..PARTS).map(|n| size(&part(&w.path, n))).collect();
        assert_eq!(parts.iter().sum::<u64>(), w.total());
        assert!(w.total() <= 4000, "{parts:?}");
        assert!(parts.iter().all(|&p| p <= 1000), "{parts:?}");
        assert!(!part(&w.path, PARTS).exists(), "no fifth part");
        let kept: Vec<String> = (0..PARTS)
            .rev()
            .flat_map(|n| {
                std::fs::read_to_string(part(&w.path, n))
                    .unwrap()
                    .lines()
                    .map(str::to_string)
                    .collect::<Vec<_>>()
            })
            .collect();
        assert_eq!(kept.last(), lines.last(), "the newest line is kept");
        let first = lines.iter().position(|l| *l == kept[0]).unwrap();
        assert_eq!(kept, lines[first..], "the newest lines, in order");
        assert_eq!(
            w.counters.deleted_bytes.load(Relaxed),
            100 * (first as u64),
            "the lines deleted are counted"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
