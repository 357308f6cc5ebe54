//! The records over HTTP: `/api/records` in pages, built and serialised on a blocking thread,
//! and `/api/records/NAME` streamed from the file in chunks.
//!
//! A data directory of 50,000 records listed whole was a 4.3 MB answer built on an async worker
//! (one of two on the lab's machine), and each download was read whole into memory (40 clients
//! that did not read a 20 MB trace held 860 MB). Now a page holds at most [`PAGE_MAX`] records
//! and a download holds one chunk per connection at a time.

use std::path::PathBuf;

use axum::body::{Body, Bytes};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::io::AsyncReadExt;

use crate::serve::records;

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

/// One page of the records in `dir`, newest first, as JSON (an array, as before paging), with
/// the number of records in `X-Total-Count`. Listed, sorted and serialised on a blocking thread.
pub async fn list_page(dir: PathBuf, page: Page) -> Response {
    let (offset, limit) = match page.bounds() {
        Ok(b) => b,
        Err(why) => return (StatusCode::BAD_REQUEST, why).into_response(),
    };
    let built = tokio::task::spawn_blocking(move || {
        let all = records::list(&dir)?;
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
}
