//! Telemetry to the browsers at its own rate, and the loop's events forwarded to everyone.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

use nanopush_proto::ws::{ServerMessage, Telemetry};
use tokio::sync::mpsc;

use crate::app_state::{AppState, to_text};
use crate::control_loop::{LoopEvent, PUSHED};
use crate::haptic::api::haptic_telemetry;
use crate::push::judge;
use crate::records;

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
    let mut shutdown = st.channels.shutdown.subscribe();
    // The frames' numbers, from 1.
    let mut seq = 0;
    loop {
        tokio::select! {
            _ = tick.tick() => {
                // A real controller's tip that could not be withdrawn: everyone is told.
                if let Some(words) = st.cfg.instrument.as_ref().and_then(|r| r.take_fault()) {
                    st.broadcast_event(&ServerMessage::Error { id: None, code: nanopush_proto::ws::ErrorCode::Unavailable, message: words });
                }
                if st.clients.tip_subscribers.load(Relaxed) == 0 {
                    continue;
                }
                let s = match st.shared.snapshot.lock() {
                    Ok(s) => Telemetry { t: s.t, seq: seq + 1, stage: s.stage, volts: s.volts, phase: if st.activity.scanning.load(Relaxed) && s.phase == "idle" { "scanning".into() } else { s.phase.into() }, estimate: s.estimate, tip_force_n: st.shared.metrics.haptic.tip_force_n(), haptic: haptic_telemetry(&st.shared.metrics.haptic) },
                    Err(_) => continue,
                };
                // The operator's frame first, so that the lease holder's gaps do not grow with
                // the number of viewers woken before it (docs/benchmarks.md, "Soak"). Its
                // session is woken first and, with this task yielding, normally sends before
                // the viewers' are woken. Each frame goes into both channels; the holder's
                // session reads both and sends each number once (`frames::Frames`).
                seq = s.seq;
                let frame = (seq, to_text(&ServerMessage::Telemetry(s)));
                if st.channels.lease_telemetry.send(frame.clone()).is_ok() {
                    tokio::task::yield_now().await;
                }
                let _ = st.channels.telemetry.send(frame);
            }
            e = events.recv() => {
                let Some((LoopEvent::RunDone { run, particle, outcome, failure, estimate, .. }, record)) = e else { break };
                // A push that read its particle as lost with a push left to make is judged as a
                // push that ran its legs (the reading can drift off a particle still in front of
                // the tip): the scan after finds it and corrects, as `nanopush push` does.
                let lost = outcome == "particle_lost"
                    && st.activity.judging.lock().is_ok_and(|mut j| match j.get_mut(&run) {
                        Some(p) if p.attempt < nanopush_instrument::control::DEFAULT_ATTEMPTS => {
                            p.lost = failure.clone();
                            true
                        }
                        _ => false,
                    });
                if outcome == PUSHED || lost {
                    // The legs ran: the scan after the push decides (`push/judge.rs`).
                    judge::on_pushed(&st, run, particle, estimate, record);
                    continue;
                }
                if let Ok(mut j) = st.activity.judging.lock() {
                    j.remove(&run);
                }
                st.remember(particle, estimate);
                st.push_ended(true);
                let (record, record_error) = split(record);
                st.audit.run_done(run, particle, outcome, failure.as_deref(), record.as_deref());
                st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error, judged: None });
            }
            _ = shutdown.changed() => {
                // Forward what the recorder still finishes (the aborted run's record).
                while let Some((LoopEvent::RunDone { run, particle, outcome, mut failure, estimate, .. }, record)) = events.recv().await {
                    if outcome == PUSHED {
                        failure = Some("the server shut down before the scan after the push could judge it".into());
                    }
                    let (record, record_error) = split(record);
                    st.audit.run_done(run, particle, outcome, failure.as_deref(), record.as_deref());
                    st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error, judged: None });
                }
                break;
            }
        }
    }
}
