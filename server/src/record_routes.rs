//! The records over HTTP: `/api/records` in pages, built and serialised on a blocking thread
//! from a listing reused while the directory is unchanged, and `/api/records/NAME` streamed from
//! the file in chunks.
//!
//! A data directory of 50,000 records listed whole would be a 4.3 MB answer built on an async
//! worker (one of two on the lab's machine), and a download read whole into memory would let 40
//! clients that do not read a 20 MB trace hold 860 MB. So a page holds at most [`PAGE_MAX`]
//! records and a download holds one chunk per connection at a time.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use axum::body::{Body, Bytes};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::io::AsyncReadExt;

use crate::records;

/// Records per page when `limit` is not given, and at most.
pub const PAGE_MAX: usize = 1000;

/// Bytes read from a record per chunk of its download.
const CHUNK: usize = 64 * 1024;

/// `/api/records`' query.
#[derive(Debug, Default, serde::Deserialize)]
pub struct Page {
    /// Records in this page, in [1, [`PAGE_MAX`]].
    limit: Option<String>,
    /// Records skipped (newest first).
    offset: Option<String>,
}

impl Page {
    /// The page's `(offset, limit)`, or why not, naming the field and the allowed range.
    fn bounds(&self) -> Result<(usize, usize), String> {
        let limit = match self.limit.as_deref() {
            None => PAGE_MAX,
            Some(v) => match v.parse::<usize>() {
                Ok(n) if (1..=PAGE_MAX).contains(&n) => n,
                _ => {
                    return Err(format!(
                        "limit = {v:?} is out of range; allowed: [1, {PAGE_MAX}] records"
                    ));
                }
            },
        };
        let offset = match self.offset.as_deref() {
            None => 0,
            Some(v) => v
                .parse::<usize>()
                .map_err(|_| format!("offset = {v:?} is not a record count; allowed: a whole number ≥ 0"))?,
        };
        Ok((offset, limit))
    }
}

/// One page of the records in `dir`, newest first, as a JSON array, with
/// the number of records in `X-Total-Count`. Listed, sorted and serialised on a blocking thread.
pub async fn list_page(dir: PathBuf, page: Page) -> Response {
    let (offset, limit) = match page.bounds() {
        Ok(b) => b,
        Err(why) => return (StatusCode::BAD_REQUEST, why).into_response(),
    };
    let built = tokio::task::spawn_blocking(move || {
        let all = listing(&dir)?;
        let total = all.len();
        let end = offset.saturating_add(limit).min(total);
        let body = serde_json::to_vec(&all[offset.min(total)..end]).map_err(std::io::Error::other)?;
        Ok::<_, std::io::Error>((total, body))
    })
    .await;
    match built {
        Ok(Ok((total, body))) => (
            [
                (header::CONTENT_TYPE, "application/json".to_string()),
                (header::HeaderName::from_static("x-total-count"), total.to_string()),
            ],
            body,
        )
            .into_response(),
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("listing records: {e}")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("listing records: {e}")).into_response(),
    }
}

/// How long a listing is reused at most while the directory looks unchanged.
const LISTING_MAX_AGE: Duration = Duration::from_secs(5);

/// A directory changed less than this long before it was listed may change again with the same
/// modification time (file times are coarse: a clock tick of the kernel, a second on some file
/// systems): such a listing is not reused.
const SETTLED: Duration = Duration::from_secs(1);

/// The last listing: its directory, the directory's modification time then, when it was made.
struct Listed {
    dir: PathBuf,
    dir_modified: SystemTime,
    /// The directory had not changed for [`SETTLED`] when it was listed.
    settled: bool,
    at: Instant,
    entries: Arc<Vec<records::RecordEntry>>,
}

/// The last listing, and (its lock) one listing at a time: a client polling the list of a large
/// directory makes it once per change of the directory (a record added or removed changes its
/// modification time) or per [`LISTING_MAX_AGE`], not once per request, and several pollers
/// never hold several blocking threads (each 145 ms of CPU at 50,000 records, on the cores the
/// sessions' worker shares).
static LISTED: Mutex<Option<Listed>> = Mutex::new(None);

/// Listings made (not reused), for the tests.
static LISTINGS: AtomicU64 = AtomicU64::new(0);

/// The finished records in `dir`, newest first ([`records::list`]), reused while `dir` is
/// unchanged (for at most [`LISTING_MAX_AGE`]).
fn listing(dir: &Path) -> std::io::Result<Arc<Vec<records::RecordEntry>>> {
    let mut last = LISTED.lock().unwrap_or_else(|e| e.into_inner());
    let dir_modified = match std::fs::metadata(dir).and_then(|m| m.modified()) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Arc::default()),
        Err(e) => return Err(e),
    };
    if let Some(l) = last.as_ref()
        && l.settled
        && l.dir == dir
        && l.dir_modified == dir_modified
        && l.at.elapsed() < LISTING_MAX_AGE
    {
        return Ok(l.entries.clone());
    }
    LISTINGS.fetch_add(1, Relaxed);
    let settled = SystemTime::now()
        .duration_since(dir_modified)
        .is_ok_and(|d| d > SETTLED);
    let entries = Arc::new(records::list(dir)?);
    *last = Some(Listed {
        dir: dir.to_path_buf(),
        dir_modified,
        settled,
        at: Instant::now(),
        entries: entries.clone(),
    });
    Ok(entries)
}

/// The pushes recorded in `dir`, newest first, at most [`records::RUNS_MAX`]
/// ([`records::run_history`]), from the listing `/api/records` reuses: the monitors ask every 5 s.
pub fn run_history(dir: &Path) -> std::io::Result<Vec<records::RunEntry>> {
    Ok(records::runs_in(dir, &listing(dir)?, records::RUNS_MAX))
}

/// The record `name` of `dir`, streamed: a plain file only (opened without following a
/// symlink, so none is served, to anywhere), read a chunk at a time as the client takes it.
pub async fn download(dir: PathBuf, name: String) -> Response {
    if !records::valid_name(&name) {
        return (
            StatusCode::BAD_REQUEST,
            "a record name is letters, digits, '-', '_' and '.', with no path",
        )
            .into_response();
    }
    let not_found = || (StatusCode::NOT_FOUND, format!("no record named {name}")).into_response();
    let opened = tokio::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(dir.join(&name))
        .await;
    let Ok(file) = opened else {
        return not_found();
    };
    let Ok(meta) = file.metadata().await else {
        return not_found();
    };
    if !meta.file_type().is_file() {
        return not_found();
    }
    let chunks = futures_util::stream::try_unfold(file, |mut file| async move {
        let mut buf = vec![0u8; CHUNK];
        let n = file.read(&mut buf).await?;
        if n == 0 {
            return Ok::<_, std::io::Error>(None);
        }
        buf.truncate(n);
        Ok(Some((Bytes::from(buf), file)))
    });
    let ctype = match name.rsplit('.').next() {
        Some("json") => "application/json",
        Some("csv") => "text/csv",
        _ => "application/octet-stream",
    };
    (
        [
            (header::CONTENT_TYPE, ctype.to_string()),
            (header::CONTENT_LENGTH, meta.len().to_string()),
            (header::CONTENT_DISPOSITION, format!("attachment; filename=\"{name}\"")),
        ],
        Body::from_stream(chunks),
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_page_is_checked_naming_the_field_and_the_range() {
        let p = |limit: Option<&str>, offset: Option<&str>| Page {
            limit: limit.map(str::to_string),
            offset: offset.map(str::to_string),
        };
        assert_eq!(Page::default().bounds(), Ok((0, PAGE_MAX)));
        assert_eq!(p(Some("10"), Some("20")).bounds(), Ok((20, 10)));
        for bad in ["0", "1001", "-1", "x"] {
            let e = p(Some(bad), None).bounds().unwrap_err();
            assert!(e.contains("limit") && e.contains("[1, 1000]"), "{e}");
        }
        let e = p(None, Some("-3")).bounds().unwrap_err();
        assert!(e.contains("offset") && e.contains("≥ 0"), "{e}");
    }

    /// The listing of a settled directory is reused while it is unchanged, and made again when
    /// a record is added or removed; one that changed a moment ago is listed each time.
    #[test]
    fn a_listing_is_reused_until_the_directory_changes() {
        let dir = std::env::temp_dir().join(format!("nanopush-listing-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("scan-1-a-1.json"), b"{}").unwrap();
        let before = LISTINGS.load(Relaxed);
        assert_eq!(listing(&dir).unwrap().len(), 1);
        assert_eq!(listing(&dir).unwrap().len(), 1);
        assert_eq!(LISTINGS.load(Relaxed) - before, 2, "just changed: listed each time");
        let long_ago = SystemTime::now() - Duration::from_secs(60);
        std::fs::File::open(&dir).unwrap().set_modified(long_ago).unwrap();
        let before = LISTINGS.load(Relaxed);
        assert_eq!(listing(&dir).unwrap().len(), 1);
        assert_eq!(listing(&dir).unwrap().len(), 1);
        assert_eq!(
            LISTINGS.load(Relaxed) - before,
            1,
            "settled: listed once for two requests"
        );
        std::fs::write(dir.join("scan-2-a-2.json"), b"{}").unwrap();
        assert_eq!(listing(&dir).unwrap().len(), 2, "a new record is listed at once");
        std::fs::remove_file(dir.join("scan-1-a-1.json")).unwrap();
        assert_eq!(listing(&dir).unwrap().len(), 1);
        assert!(listing(&dir.join("missing")).unwrap().is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
