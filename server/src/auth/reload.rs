//! The token file watched: looked at every [`FILE_POLL`], and a change applied only once the
//! file has stayed the same (stamp and content) for [`SETTLE`]. A file being edited in place
//! (`echo >`, an editor saving over it: truncated, then written a moment later) is never taken
//! for its empty or half-written self, so nobody's session is closed by an edit in progress; a
//! revocation takes effect within `SETTLE + 2 × FILE_POLL` (about 1.5 s).
//!
//! A file that cannot be used (missing, unreadable, not parsing) leaves the tokens read before
//! in force: deleting the file revokes nobody (`nanopush token revoke` does). The problem is
//! logged once, counted in `nanopush_auth_token_file_errors_total`, and
//! `nanopush_auth_token_file_ok` is 0 until the file can be used again; it is looked at again on
//! every poll meanwhile, so a fix that changes neither the file's time, size nor inode (a
//! `chown`, a `chmod`) takes effect too.
//!
//! Only a regular file is read ([`super::tokens::read_text`]): a FIFO put in its place would block
//! its reader until someone writes to it, and a device might never end. And the file is read
//! without holding anything another task waits for: `/metrics` reads the file's state from an
//! atomic, so a read that hangs (a network file system gone) keeps only the watcher waiting.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant, SystemTime};

use super::tokens::TokenTable;
use super::{Auth, Person, digest};

/// How often the token file is looked at for a change.
pub const FILE_POLL: Duration = Duration::from_millis(250);

/// How long the file must stay the same before what it says is applied.
pub const SETTLE: Duration = Duration::from_secs(1);

/// The identity of a file's content: re-read when it changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Stamp {
    modified: Option<SystemTime>,
    len: u64,
    inode: u64,
}

impl Stamp {
    fn of(m: &std::fs::Metadata) -> Stamp {
        use std::os::unix::fs::MetadataExt as _;
        Stamp {
            modified: m.modified().ok(),
            len: m.len(),
            inode: m.ino(),
        }
    }

    /// The stamp of the file at `path`, None when it cannot be looked at.
    pub(super) fn at(path: &Path) -> Option<Stamp> {
        std::fs::metadata(path).ok().map(|m| Stamp::of(&m))
    }
}

/// What one look at the file found: its stamp and the digest of its text, or why it could not
/// be read.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Look {
    Read { stamp: Stamp, digest: [u8; 32] },
    Failed(String),
}

/// Reads `path` (a regular file only): the stamp of the file read (the open file's, not the
/// path's) and its text, or why it could not be read.
fn read(path: &Path) -> Result<(Stamp, String), String> {
    use super::tokens::{TokenFileError, read_text};
    match read_text(path) {
        Ok((meta, text)) => Ok((Stamp::of(&meta), text)),
        Err(TokenFileError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => Err(format!(
            "{} is missing (deleting it revokes nobody: `nanopush token revoke NAME` does)",
            path.display()
        )),
        Err(e) => Err(e.to_string()),
    }
}

/// The watcher's memory.
#[derive(Debug)]
pub(super) struct FileWatch {
    /// The stamp and content digest of the text in force (no digest for the one read at start).
    applied: (Option<Stamp>, Option<[u8; 32]>),
    /// The latest look differing from what is in force, and since when it has been the same.
    seen: Option<(Look, Instant)>,
    /// The problem reported (once), while the file cannot be used.
    failing: Option<String>,
}

impl FileWatch {
    /// Watching a file read at start with `stamp`.
    pub(super) fn new(stamp: Option<Stamp>) -> FileWatch {
        FileWatch {
            applied: (stamp, None),
            seen: None,
            failing: None,
        }
    }
}

impl Auth {
    /// [`Self::reload_if_changed_at`] now.
    pub fn reload_if_changed(&self) -> bool {
        self.reload_if_changed_at(Instant::now())
    }

    /// Looks at the token file at `now` (every [`FILE_POLL`]); once a change has stayed the
    /// same for [`SETTLE`], applies it: closes the sessions of tokens no longer in it (or whose
    /// role changed), whose cookies are refused from then on. Returns whether it applied a new
    /// table.
    pub fn reload_if_changed_at(&self, now: Instant) -> bool {
        let Some(named) = &self.named else { return false };
        // Looked at and read without the watcher's lock held (only this watcher takes it).
        let stamp = Stamp::at(&named.path);
        let quiet = named.watch.lock().map_or(true, |w| {
            w.seen.is_none() && w.failing.is_none() && stamp == w.applied.0
        });
        // Nothing new and nothing wrong: the file is not read.
        if quiet {
            return false;
        }
        let read = read(&named.path);
        let Ok(mut w) = named.watch.lock() else { return false };
        let look = match &read {
            Ok((stamp, text)) => Look::Read {
                stamp: *stamp,
                digest: digest(text),
            },
            Err(why) => Look::Failed(why.clone()),
        };
        let since = match &w.seen {
            Some((seen, since)) if *seen == look => *since,
            _ => {
                w.seen = Some((look, now));
                now
            }
        };
        if now.saturating_duration_since(since) < SETTLE {
            return false;
        }
        let (stamp, text) = match read {
            Ok(r) => r,
            Err(why) => {
                self.file_failing(&mut w, why);
                return false;
            }
        };
        let digest = digest(&text);
        if w.applied.1 == Some(digest) {
            // The same text (touched, or readable again): nothing to apply.
            w.applied.0 = Some(stamp);
            w.seen = None;
            self.file_ok(&mut w);
            return false;
        }
        let table = match TokenTable::parse(&text, &named.path) {
            Ok(t) => t,
            Err(e) => {
                self.file_failing(&mut w, e.to_string());
                return false;
            }
        };
        w.applied = (Some(stamp), Some(digest));
        w.seen = None;
        self.file_ok(&mut w);
        drop(w);
        self.apply(table);
        true
    }

    /// The file cannot be used: said once (each new problem), counted, and the tokens read
    /// before stay in force.
    fn file_failing(&self, w: &mut FileWatch, why: String) {
        if let Some(named) = &self.named {
            named.file_ok.store(false, Relaxed);
        }
        if w.failing.as_deref() != Some(why.as_str()) {
            tracing::error!(
                "token file: {why}; the tokens read before stay in force, and revocations wait until it can be read"
            );
            self.counters.file_errors.fetch_add(1, Relaxed);
            w.failing = Some(why);
        }
    }

    /// The file can be used again.
    fn file_ok(&self, w: &mut FileWatch) {
        if let Some(named) = &self.named {
            named.file_ok.store(true, Relaxed);
        }
        if w.failing.take().is_some() {
            tracing::info!("token file: readable again");
        }
    }

    /// `table` in force: the verified tokens forgotten, the sessions it no longer names closed.
    fn apply(&self, table: TokenTable) {
        let Some(named) = &self.named else { return };
        self.counters.reloads.fetch_add(1, Relaxed);
        let valid = |p: &Person| table.entries.iter().any(|e| e.id == p.key && e.role == p.role);
        if let Ok(mut t) = named.table.lock() {
            *t = Arc::new(table.clone());
        }
        if let Ok(mut v) = named.verified.lock() {
            v.clear();
        }
        if let Ok(l) = self.live.lock() {
            for (id, live) in l.iter().filter(|(_, l)| !valid(&l.person)) {
                tracing::info!("client {id} ({}): token revoked; closing its session", live.person.name);
                self.counters.revoked_sessions.fetch_add(1, Relaxed);
                let _ = live.kick.send(Some(format!(
                    "the token of {} was revoked (or its role changed); this session is closed",
                    live.person.name
                )));
            }
        }
        tracing::info!("token file re-read: {} token(s)", table.entries.len());
    }
}
