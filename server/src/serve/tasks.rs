//! The work beside the sessions: a push prepared off the loop (local scan, plan, model
//! prediction), a scan streamed line by line, and telemetry at its rate with the loop's events.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::ws::Message;
use nanopush_proto::ws::{ErrorCode, PushPath, ScanLineHeader, ScanNow, ServerMessage, Telemetry};
use tokio::sync::mpsc;

use crate::control::{MoveTarget, Prepared, plan_move};
use crate::scan::{ScanParams, Scanner, Sphere, Surface, Tip, find_particles, write_gsf};
use crate::serve::control_loop::{LoopCommand, LoopEvent, PushJob};
use crate::serve::haptic_api::haptic_telemetry;
use crate::serve::records::{self, write_atomic};
use crate::serve::state::{AppState, to_text};
use crate::serve::validate::Refusal;

/// The sample as it is now (the loop's snapshot of the particles).
fn surface_now(st: &AppState) -> Surface {
    let particles = st
        .shared
        .snapshot
        .lock()
        .map(|s| s.particles.clone())
        .unwrap_or_default();
    Surface {
        topography: st.scene.topography(),
        spheres: particles.iter().map(|&(_, x, y, r)| Sphere { x, y, r }).collect(),
    }
}

/// Whether a particle of radius `r` (m) can be pushed to `p` (m): its centre at least a radius
/// inside the stage's `[0, range]` square, so the particle stays on the stage and the tip, which
/// stays inside it, can reach behind it.
pub(crate) fn on_stage(p: (f64, f64), r: f64, range: f64) -> Result<(), Refusal> {
    let inside = |v: f64| v >= r && v <= range - r;
    if inside(p.0) && inside(p.1) {
        return Ok(());
    }
    Err(Refusal::new(
        ErrorCode::OutOfRange,
        format!(
            "target ({:.3}, {:.3}) µm is out of range for a particle {:.3} µm in radius; allowed: [{:.3}, {:.3}] µm in x and y",
            p.0 * 1e6,
            p.1 * 1e6,
            r * 1e6,
            r * 1e6,
            (range - r) * 1e6
        ),
    ))
}

pub(crate) fn run_done_failed(st: &AppState, particle: u32, outcome: &str, failure: String) {
    st.push_ended(false);
    st.shared.busy.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::RunDone {
        particle,
        outcome: outcome.into(),
        failure: Some(failure),
        estimate: None,
        record: None,
        record_error: None,
    });
}

/// Off the loop: locate the particle in a quick local scan, plan, predict; then hand the job
/// to the loop.
pub(crate) fn prepare_push(st: &AppState, particle: u32, target: MoveTarget, generation: u64, by: u32) {
    let f = &st.scene.file;
    let Some(part) = f.particles.iter().find(|p| p.id == particle) else {
        return;
    };
    let nominal = st
        .estimates
        .lock()
        .ok()
        .and_then(|e| e.get(&particle).copied())
        .unwrap_or((part.x_um * 1e-6, part.y_um * 1e-6));
    let plan = match plan_move(&st.scene, &surface_now(st), nominal, part.radius_nm * 1e-9, target) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, particle, "plan", format!("particle {particle}: {e}")),
    };
    // A target the particle cannot reach whole, with the tip behind it, fails now, not after a
    // push that runs into the stage's edge until its time-out.
    if let Err(r) = on_stage(plan.target, plan.located.radius, f.stage.range_um * 1e-6) {
        return run_done_failed(st, particle, "plan", format!("particle {particle}: {}", r.message));
    }
    let (located, legs) = (plan.located, plan.legs);
    if legs.is_empty() {
        // Already there (within 10 nm): nothing to push.
        st.remember(particle, [located.x, located.y]);
        st.push_ended(false);
        st.shared.busy.store(false, Relaxed);
        st.broadcast_event(&ServerMessage::RunDone {
            particle,
            outcome: "ok".into(),
            failure: None,
            estimate: Some([located.x, located.y]),
            record: None,
            record_error: None,
        });
        return;
    }
    let prepared = match Prepared::new(&st.scene, particle, located.radius, &st.params) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, particle, "error", e.to_string()),
    };
    if st.generation.load(Relaxed) != generation || st.stopping.load(Relaxed) {
        return run_done_failed(st, particle, "stopped", "stopped before the push began".into());
    }
    let run = st.shared.runs.fetch_add(1, Relaxed) + 1;
    let mut path = vec![[located.x, located.y]];
    path.extend(legs.iter().map(|l| [l.to.0, l.to.1]));
    let started = PushPath { particle, path, by };
    let job = PushJob {
        run,
        particle,
        legs,
        prepared,
    };
    // Said after the job is queued: a `stop` sent on hearing `push_started` reaches the loop
    // after the push, and stops it.
    if let Ok(mut p) = st.push_now.lock() {
        *p = Some(started.clone());
    }
    if st.shared.commands.push(LoopCommand::Push(Box::new(job))).is_err() {
        st.shared.metrics.dropped_commands.fetch_add(1, Relaxed);
        run_done_failed(st, particle, "error", "the control loop's command queue is full".into());
        return;
    }
    st.broadcast_event(&ServerMessage::PushStarted(started));
}

/// A scan on its own thread: lines at the scan line rate to the `scan` stream, then the GSF
/// record. Tapping never moves particles: it images a snapshot of the sample.
pub(crate) fn run_scan(st: &AppState, params: ScanParams) {
    let scan_id = st.next_scan.fetch_add(1, Relaxed);
    let surface = surface_now(st);
    let tip = Tip::from_scene(&st.scene);
    let img0 = params.empty_image();
    let send_text = |m: &ServerMessage| {
        if st.scan_subscribers.load(Relaxed) > 0 {
            let _ = st.scans.send(Message::Text(to_text(m)));
        }
    };
    let previous = st.latest_scan.lock().ok().and_then(|s| s.clone());
    let now = ScanNow {
        scan: scan_id,
        xres: img0.xres as u32,
        yres: img0.yres as u32,
        x_offset: img0.x_offset,
        y_offset: img0.y_offset,
        x_real: img0.x_real,
        y_real: img0.y_real,
        done: false,
        record: None,
        stale: false,
    };
    if let Ok(mut s) = st.latest_scan.lock() {
        *s = Some(now.clone());
    }
    send_text(&ServerMessage::ScanStart {
        scan: scan_id,
        xres: img0.xres as u32,
        yres: img0.yres as u32,
        x_offset: img0.x_offset,
        y_offset: img0.y_offset,
        x_real: img0.x_real,
        y_real: img0.y_real,
    });
    let mut img = img0;
    let mut scanner = Scanner::new(&surface, tip, params);
    let line_period = Duration::from_secs_f64(1.0 / params.line_rate);
    let mut next = Instant::now();
    let mut cancelled = false;
    while let Some(line) = scanner.next_line() {
        img.data.extend_from_slice(&line.heights);
        if st.scan_cancel.load(Relaxed) || st.stopping.load(Relaxed) {
            cancelled = true;
            break;
        }
        if st.scan_subscribers.load(Relaxed) > 0 {
            let heights: Vec<f32> = line.heights.iter().map(|&h| h as f32).collect();
            let h = ScanLineHeader {
                scan: scan_id,
                line: line.index as u32,
                xres: heights.len() as u32,
                yres: params.pixels as u32,
                y: line.y,
            };
            let _ = st.scans.send(Message::Binary(Bytes::from(h.encode(&heights))));
        }
        next += line_period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
    }
    let (mut record, mut record_error) = (None, None);
    if !cancelled {
        let stem = format!("scan-{}-{scan_id}", records::unix_now());
        let mut gsf = Vec::new();
        let prepared = write_gsf(&mut gsf, &img, &stem)
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
                "gsf": gsf_name,
                "xres": img.xres, "yres": img.yres,
                "x_offset": img.x_offset, "y_offset": img.y_offset,
                "x_real": img.x_real, "y_real": img.y_real,
                "z_range": img.z_range(),
                "particles": find_particles(&img, &tip).iter().map(|l| serde_json::json!({"x": l.x, "y": l.y, "radius": l.radius})).collect::<Vec<_>>(),
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
    }
    if let Ok(mut s) = st.latest_scan.lock() {
        // A cancelled scan is not the latest picture of the sample: the one before stays.
        *s = if cancelled {
            previous
        } else {
            Some(ScanNow {
                done: true,
                record: record.clone(),
                ..now
            })
        };
    }
    // Free before it is announced: a client that starts the next scan on hearing `scan_done`
    // must not be told the last one is still running.
    st.scanning.store(false, Relaxed);
    send_text(&ServerMessage::ScanDone {
        scan: scan_id,
        record,
        record_error,
    });
}

/// A record's name, or the reason it is missing, as the two fields of a message.
fn split(r: records::Recorded) -> (Option<String>, Option<String>) {
    match r {
        Ok(name) => (Some(name), None),
        Err(why) => (None, Some(why)),
    }
}

/// Telemetry at `telemetry_hz`, produced only while someone subscribes to `tip`, to the lease
/// holder first, then to everyone else; and loop events forwarded to everyone.
pub async fn telemetry_task(st: Arc<AppState>, mut events: mpsc::UnboundedReceiver<(LoopEvent, records::Recorded)>) {
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / st.cfg.telemetry_hz));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut shutdown = st.shutdown.subscribe();
    // The frames' numbers, from 1.
    let mut seq = 0;
    loop {
        tokio::select! {
            _ = tick.tick() => {
                if st.tip_subscribers.load(Relaxed) == 0 {
                    continue;
                }
                let s = match st.shared.snapshot.lock() {
                    Ok(s) => Telemetry { t: s.t, seq: seq + 1, stage: s.stage, volts: s.volts, phase: if st.scanning.load(Relaxed) && s.phase == "idle" { "scanning".into() } else { s.phase.into() }, estimate: s.estimate, tip_force_n: st.shared.metrics.haptic.tip_force_n(), haptic: haptic_telemetry(&st.shared.metrics.haptic) },
                    Err(_) => continue,
                };
                // The operator's frame first: woken anywhere among 500 viewers on one core, the
                // lease holder's gaps had a p99 of +6 ms beyond the period in a soak. Its session
                // is woken first and, with this task yielding, normally sends before the viewers'
                // are woken. Each frame goes into both channels; the holder's session reads both
                // and sends each number once (`frames::Frames`).
                seq = s.seq;
                let frame = (seq, to_text(&ServerMessage::Telemetry(s)));
                if st.lease_telemetry.send(frame.clone()).is_ok() {
                    tokio::task::yield_now().await;
                }
                let _ = st.telemetry.send(frame);
            }
            e = events.recv() => {
                let Some((LoopEvent::RunDone { particle, outcome, failure, estimate, .. }, record)) = e else { break };
                st.remember(particle, estimate);
                st.push_ended(true);
                let (record, record_error) = split(record);
                st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error });
            }
            _ = shutdown.changed() => {
                // Forward what the recorder still finishes (the aborted run's record).
                while let Some((LoopEvent::RunDone { particle, outcome, failure, estimate, .. }, record)) = events.recv().await {
                    let (record, record_error) = split(record);
                    st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error });
                }
                break;
            }
        }
    }
}
