//! A scan on its own thread: lines streamed at the scan line rate, then the GSF record.

use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::ws::Message;
use nanopush_proto::ws::{ScanLineHeader, ScanNow, ServerMessage};

use crate::app_state::{AppState, to_text};
use crate::clock::unix_now;
use crate::records::write_atomic;
use nanopush_instrument::scan::{HeightImage, ScanParams, Scanner, Tip, find_particles, write_gsf};

/// A scan on its own thread: lines at the scan line rate to the `scan` stream, then the GSF
/// record (naming `person`, who ran it). Tapping never moves particles: it images a snapshot of
/// the sample.
pub(crate) fn run_scan(st: &AppState, params: ScanParams, person: &str) {
    let scan_id = st.activity.next_scan.fetch_add(1, Relaxed);
    let surface = st.surface_now();
    let tip = Tip::from_scene(&st.scene);
    let img0 = params.empty_image();
    let send_text = |m: &ServerMessage| {
        if st.clients.scan_subscribers.load(Relaxed) > 0 {
            let _ = st.channels.scans.send(Message::Text(to_text(m)));
        }
    };
    let previous = st.activity.latest_scan.lock().ok().and_then(|s| s.clone());
    let now = scan_now(scan_id, &img0);
    if let Ok(mut s) = st.activity.latest_scan.lock() {
        *s = Some(now.clone());
    }
    keep_lines(st, None);
    send_text(&scan_start(&now));
    let mut img = img0;
    let mut scanner = Scanner::new(&surface, tip, params);
    let line_period = Duration::from_secs_f64(1.0 / params.line_rate);
    let mut next = Instant::now();
    let mut cancelled = false;
    while let Some(line) = scanner.next_line() {
        img.data.extend_from_slice(&line.heights);
        if st.activity.scan_cancel.load(Relaxed) || st.activity.stopping.load(Relaxed) {
            cancelled = true;
            break;
        }
        send_line(st, scan_id, line.index, params.pixels, line.y, &line.heights);
        next += line_period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
    }
    let (record, record_error) = if cancelled {
        (None, None)
    } else {
        write_record(st, scan_id, &img, &tip, person)
    };
    // A cancelled scan is not the latest picture of the sample: the one before stays.
    let latest = if cancelled {
        previous
    } else {
        Some(ScanNow {
            done: true,
            record: record.clone(),
            ..now
        })
    };
    finish_scan(st, scan_id, latest, record, record_error);
}

/// Scan `scan_id` of `img`'s geometry, running, with no record yet.
fn scan_now(scan_id: u32, img: &HeightImage) -> ScanNow {
    ScanNow {
        scan: scan_id,
        xres: img.xres as u32,
        yres: img.yres as u32,
        x_offset: img.x_offset,
        y_offset: img.y_offset,
        x_real: img.x_real,
        y_real: img.y_real,
        done: false,
        record: None,
        stale: false,
    }
}

/// The `scan_start` of scan `now`.
fn scan_start(now: &ScanNow) -> ServerMessage {
    ServerMessage::ScanStart {
        scan: now.scan,
        xres: now.xres,
        yres: now.yres,
        x_offset: now.x_offset,
        y_offset: now.y_offset,
        x_real: now.x_real,
        y_real: now.y_real,
    }
}

/// Line `line` of scan `scan_id` (of `lines` lines, at `y`, m) as its binary frame: kept before
/// it is sent, so a client subscribing now gets it from one or the other.
fn send_line(st: &AppState, scan_id: u32, line: usize, lines: usize, y: f64, heights: &[f64]) {
    let heights: Vec<f32> = heights.iter().map(|&h| h as f32).collect();
    let h = ScanLineHeader {
        scan: scan_id,
        line: line as u32,
        xres: heights.len() as u32,
        yres: lines as u32,
        y,
    };
    let frame = Bytes::from(h.encode(&heights));
    keep_lines(st, Some(frame.clone()));
    if st.clients.scan_subscribers.load(Relaxed) > 0 {
        let _ = st.channels.scans.send(Message::Binary(frame));
    }
}

/// The end of a scan: `latest` the picture of the sample now, the lines kept for late
/// subscribers dropped, the instrument free, then `scan_done`. Free before it is announced: a
/// client that starts the next scan on hearing `scan_done` must not be told the last one is
/// still running.
fn finish_scan(
    st: &AppState,
    scan_id: u32,
    latest: Option<ScanNow>,
    record: Option<String>,
    record_error: Option<String>,
) {
    if let Ok(mut s) = st.activity.latest_scan.lock() {
        *s = latest;
    }
    keep_lines(st, None);
    st.activity.scanning.store(false, Relaxed);
    if st.clients.scan_subscribers.load(Relaxed) > 0 {
        let m = ServerMessage::ScanDone {
            scan: scan_id,
            record,
            record_error,
        };
        let _ = st.channels.scans.send(Message::Text(to_text(&m)));
    }
}

/// A frame taken at once (an assembly's full frames), not streamed: its scan record written, and
/// it made the latest scan, so that a client that joins later is shown it. Returns its record's
/// name, or why there is none.
/// A scan on a real controller: the image from its scan engine (through the instrument loop's
/// thread), then sent and recorded as a simulated scan's is, its lines at once.
pub(crate) fn run_real_scan(
    st: &AppState,
    real: &crate::instrument_loop::RealInstrument,
    frame: Option<nanopush_instrument::afm::ScanFrame>,
    person: &str,
) {
    let scan_id = st.activity.next_scan.fetch_add(1, Relaxed);
    let send_text = |m: &ServerMessage| {
        if st.clients.scan_subscribers.load(Relaxed) > 0 {
            let _ = st.channels.scans.send(Message::Text(to_text(m)));
        }
    };
    let img = match real.scan(frame) {
        Ok(img) => img,
        Err(e) => {
            st.activity.scanning.store(false, Relaxed);
            // A stop, or a shutdown, ended it: no failure.
            let cancelled = st.activity.scan_cancel.load(Relaxed)
                || st.activity.stopping.load(Relaxed)
                || real.cancel.load(Relaxed);
            send_text(&ServerMessage::ScanDone {
                scan: scan_id,
                record: None,
                record_error: (!cancelled).then(|| format!("the controller's scan failed: {e}")),
            });
            return;
        }
    };
    let now = scan_now(scan_id, &img);
    keep_lines(st, None);
    send_text(&scan_start(&now));
    for (row, heights) in img.data.chunks(img.xres).enumerate() {
        let y = img.y_offset + (row as f64 + 0.5) * img.dy();
        send_line(st, scan_id, row, img.yres, y, heights);
    }
    // The heights are recorded with no tip model of the controller's: the scene's stands in.
    let tip = Tip::from_scene(&st.scene);
    let (record, record_error) = write_record(st, scan_id, &img, &tip, person);
    let latest = Some(ScanNow {
        done: true,
        record: record.clone(),
        ..now
    });
    finish_scan(st, scan_id, latest, record, record_error);
}

pub(crate) fn record_frame(st: &AppState, img: &HeightImage, person: &str) -> Result<String, String> {
    let scan_id = st.activity.next_scan.fetch_add(1, Relaxed);
    let tip = Tip::from_scene(&st.scene);
    let (record, record_error) = write_record(st, scan_id, img, &tip, person);
    if let Ok(mut s) = st.activity.latest_scan.lock() {
        *s = Some(ScanNow {
            done: true,
            record: record.clone(),
            ..scan_now(scan_id, img)
        });
    }
    record.ok_or_else(|| record_error.unwrap_or_else(|| "no record was written".into()))
}

/// The running scan's lines for clients that subscribe mid-scan ([`crate::app_state::Activity::scan_lines`]):
/// one more line, or `None`: none (a scan starts, or ended).
fn keep_lines(st: &AppState, frame: Option<Bytes>) {
    if let Ok(mut lines) = st.activity.scan_lines.lock() {
        match frame {
            Some(f) => lines.push(f),
            None => lines.clear(),
        }
    }
}

/// Writes scan `scan_id`'s record (`scan-T-INSTANCE-N.gsf` and its `.json` summary with the particles
/// found, and `person`, who ran it); returns the GSF's name, or the reason it is missing.
fn write_record(
    st: &AppState,
    scan_id: u32,
    img: &HeightImage,
    tip: &Tip,
    person: &str,
) -> (Option<String>, Option<String>) {
    let (mut record, mut record_error) = (None, None);
    // The server run in the name: two runs' scans of the same second never share one.
    let stem = format!("scan-{}-{}-{scan_id}", unix_now(), st.instance.id);
    let mut gsf = Vec::new();
    let prepared = write_gsf(&mut gsf, img, &stem)
        .map_err(|e| e.to_string())
        .and_then(|()| std::fs::create_dir_all(&st.cfg.data_dir).map_err(|e| e.to_string()))
        .map_err(|e| format!("preparing the record in {}: {e}", st.cfg.data_dir.display()));
    if let Err(e) = &prepared {
        tracing::error!("records: scan {scan_id}: {e}");
        st.shared.metrics.record_failures.fetch_add(1, Relaxed);
        record_error = Some(e.clone());
    }
    if prepared.is_ok() {
        let gsf_name = format!("{stem}.gsf");
        let summary = serde_json::json!({
            "schema": "scan-record",
            "scan": scan_id,
            "person": person,
            "gsf": gsf_name,
            "xres": img.xres, "yres": img.yres,
            "x_offset": img.x_offset, "y_offset": img.y_offset,
            "x_real": img.x_real, "y_real": img.y_real,
            "z_range": img.z_range(),
            "particles": find_particles(img, tip).iter().map(|l| serde_json::json!({"x": l.x, "y": l.y, "radius": l.radius})).collect::<Vec<_>>(),
        });
        let json_name = format!("{stem}.json");
        let ok = write_atomic(&st.cfg.data_dir.join(&gsf_name), &gsf)
            .and_then(|()| write_atomic(&st.cfg.data_dir.join(&json_name), summary.to_string().as_bytes()));
        match ok {
            Ok(()) => record = Some(gsf_name),
            Err(e) => {
                tracing::error!("records: scan {scan_id}: {e}");
                st.shared.metrics.record_failures.fetch_add(1, Relaxed);
                record_error = Some(format!("writing {stem} in {}: {e}", st.cfg.data_dir.display()));
            }
        }
    }
    (record, record_error)
}
