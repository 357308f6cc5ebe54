//! One move of an assembly, made as the operator's `push` is: a local scan finds the particle
//! where the map says it is, its legs go around every other particle of the map
//! (`legs_on_map`), the push is handed to the loop (`push::launch`) and judged by the scan
//! after it, with its corrections (`push::judge`), which ends the move in its `run_done`. A local
//! scan around where it ended then tells the map where the particle and its neighbours are now.

use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

use nanopush_instrument::assembly::routing::legs_on_map;
use nanopush_instrument::assembly::{MoveDone, PlannedMove, Seen};
use nanopush_instrument::control::moves::locate::locate_near;
use nanopush_instrument::control::{MoveRoute, Verdict};
use nanopush_proto::ws::{Judged, ServerMessage};
use tokio::sync::broadcast::error::TryRecvError;

use super::Assembly;
use super::kinds::{Kind, lend};
use crate::app_state::Move;
use crate::push::launch::{launch, run_done_failed};

/// A move made: what the book is told, and what the record keeps.
pub(super) struct Made {
    /// For the book.
    pub done: MoveDone,
    /// Local scans taken.
    pub scans: usize,
    /// The runs of its pushes.
    pub runs: Vec<u64>,
    /// The record of its last push.
    pub record: Option<String>,
}

/// How a move's pushes ended, as its `run_done` said.
#[derive(Debug, Default)]
struct Ended {
    outcome: String,
    failure: Option<String>,
    estimate: Option<[f64; 2]>,
    judged: Option<Judged>,
    record: Option<String>,
    runs: Vec<u64>,
    /// The loop's time from the first push to the end (s).
    push_time: f64,
}

/// Makes move `mv` of `a`'s plan with particle `id` of kind `kind`.
pub(super) fn make(a: &Assembly<'_>, mv: &PlannedMove, id: u32, kind: &Kind) -> Made {
    let st = a.st;
    let range = st.scene.file.stage.range_um * 1e-6;
    let radius = a.book.map()[mv.particle].radius;
    let tolerance = a.book.tolerance_of(mv.purpose);
    let mut made = Made {
        done: MoveDone::begun(mv, id),
        scans: 0,
        runs: Vec::new(),
        record: None,
    };
    let scan = |near: (f64, f64), made: &mut Made| {
        let (img, found) = locate_near(&st.surface_now(), a.tip, a.base, near, radius, range);
        made.scans += 1;
        made.done.images.push(img.clone());
        (img, found)
    };
    let (local, located) = scan(mv.from, &mut made);
    let located = match located {
        Ok(l) => l,
        Err(cause) => {
            made.done.record.outcome = format!(
                "not_found: no particle near ({:.3}, {:.3}) µm: {cause}",
                mv.from.0 * 1e6,
                mv.from.1 * 1e6
            );
            made.done.failed = true;
            made.done.absent = true;
            return made;
        }
    };
    made.done.path.push((located.x, located.y));
    let legs = match legs_on_map(
        a.book.map(),
        mv.particle,
        &a.settings,
        (located.x, located.y, located.radius),
        radius,
        mv.to,
    ) {
        Ok(legs) => legs,
        Err(e) => {
            made.done.record.outcome = format!("refused: {e}");
            made.done.failed = true;
            return made;
        }
    };
    if legs.is_empty() {
        // Already there, within the planner's reach: judged where the scan found it.
        let verdict = Verdict::judge((located.x, located.y), mv.to, tolerance);
        made.done.record.outcome = verdict.code().into();
        made.done.record.error = error_of(&verdict);
        made.done.ended = Some(Seen {
            x: located.x,
            y: located.y,
            radius: located.radius,
        });
        return made;
    }
    for l in &legs {
        made.done.path.push(l.to);
    }
    let route = MoveRoute {
        local,
        located,
        target: mv.to,
        legs,
    };
    let ended = push(a, id, tolerance, kind, route);
    made.done.record.outcome = ended.outcome.clone();
    made.done.record.pushes = ended.runs.len() as u32;
    made.done.record.push_time = ended.push_time;
    made.done.record.error = ended.judged.as_ref().map(|j| j.error_m);
    made.runs = ended.runs.clone();
    made.record = ended.record.clone();
    let at = ended.judged.as_ref().map(|j| j.measured).or(ended.estimate);
    made.done.failed = !matches!(ended.outcome.as_str(), "ok" | "missed");
    if let Some(at) = at {
        // Where the move left it, and around it its neighbours now.
        made.done.path.push((at[0], at[1]));
        let (_, found) = scan((at[0], at[1]), &mut made);
        made.done.ended = Some(match (found, ended.judged.is_some()) {
            // The judging scan's measure is the move's.
            (_, true) | (Err(_), _) => Seen {
                x: at[0],
                y: at[1],
                radius,
            },
            (Ok(l), false) => Seen {
                x: l.x,
                y: l.y,
                radius: l.radius,
            },
        });
    }
    if let Some(f) = ended
        .failure
        .filter(|_| ended.outcome != "ok" && ended.outcome != "missed")
    {
        made.done.record.outcome = format!("{}: {f}", ended.outcome);
    }
    made
}

fn error_of(v: &Verdict) -> Option<f64> {
    match *v {
        Verdict::Ok { error } | Verdict::Missed { error } => Some(error),
        _ => None,
    }
}

/// The move's pushes through the loop, from `route`'s first, until its `run_done`.
fn push(a: &Assembly<'_>, id: u32, tolerance: f64, kind: &Kind, route: MoveRoute) -> Ended {
    let st = a.st;
    lend(st, id, tolerance, &kind.derived);
    let mut events = st.channels.events.subscribe();
    let t0 = loop_time(st);
    let mv = Move {
        particle: id,
        tolerance,
        generation: a.job.generation,
        by: a.job.by,
        person: a.job.person.as_str().into(),
    };
    st.shared.busy.store(true, Relaxed);
    if let Err((outcome, failure)) = launch(st, mv.clone(), &kind.scene, route, 1) {
        run_done_failed(st, &mv, id, outcome, failure.clone());
        return Ended {
            outcome: outcome.into(),
            failure: Some(failure),
            ..Ended::default()
        };
    }
    let mut ended = wait(a, id, &mut events);
    ended.push_time = (loop_time(st) - t0).max(0.0);
    ended
}

/// The loop's time now (s).
fn loop_time(st: &crate::app_state::AppState) -> f64 {
    st.shared.snapshot.lock().map(|s| s.t).unwrap_or(f64::NAN)
}

/// Waits for particle `id`'s `run_done`, counting its pushes (`push_started`). Every move ends in
/// one (`push::judge`, `push::launch`); should it be missed (the events' queue overran, the loop
/// ended), the move ends `error` once the instrument is free.
fn wait(
    a: &Assembly<'_>,
    id: u32,
    events: &mut tokio::sync::broadcast::Receiver<axum::extract::ws::Utf8Bytes>,
) -> Ended {
    let st = a.st;
    let mut ended = Ended::default();
    let mut lost = false;
    let mut free_since: Option<std::time::Instant> = None;
    loop {
        match events.try_recv() {
            Ok(text) => match serde_json::from_str::<ServerMessage>(text.as_str()) {
                Ok(ServerMessage::PushStarted(p)) if p.particle == id => ended.runs.push(p.run),
                Ok(ServerMessage::RunDone {
                    particle,
                    outcome,
                    failure,
                    estimate,
                    record,
                    judged,
                    ..
                }) if particle == id => {
                    return Ended {
                        outcome,
                        failure,
                        estimate,
                        judged,
                        record,
                        runs: ended.runs,
                        push_time: 0.0,
                    };
                }
                _ => {}
            },
            Err(TryRecvError::Lagged(_)) => lost = true,
            Err(TryRecvError::Empty) => {
                let free = !st.shared.busy.load(Relaxed) || st.shared.finished.load(Relaxed);
                // The end is said right after the instrument is freed: a moment's grace.
                free_since = if free {
                    free_since.or(Some(std::time::Instant::now()))
                } else {
                    None
                };
                if free_since.is_some_and(|t| t.elapsed() > LOST_AFTER) {
                    ended.outcome = "error".into();
                    ended.failure = Some(if lost {
                        "the end of the move's push was not heard (the server's events overran)".into()
                    } else {
                        "the instrument is free but the move's push never said its end".into()
                    });
                    return ended;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(TryRecvError::Closed) => {
                ended.outcome = "error".into();
                ended.failure = Some("the server's events ended".into());
                return ended;
            }
        }
    }
}

/// How long after the instrument is free a move's end may still come.
const LOST_AFTER: Duration = Duration::from_millis(500);
