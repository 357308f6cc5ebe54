//! An assembly in the server: particles pushed into a pattern through the control loop, as
//! `nanopush assemble` does it against the simulated AFM (`nanopush_instrument::assembly::run`),
//! the instrument's [`Book`] keeping what the assembly knows and has done and planning again
//! after every move:
//!
//! 1. a full frame (the scene's `[scan]`) finds every particle, and the book makes the first
//!    plan (`assembly_planned`), or refuses before anything moves;
//! 2. each move of the plan is a `push` as the operator would send it ([`moves`]): a local scan
//!    finds the particle where the map says it is, its legs go around every other particle of
//!    the map, the loop pushes them at live speed, the scan after judges the move and corrects
//!    it (`push::judge`), ending in the move's `run_done`;
//! 3. a local scan around where the move ended tells the map where the particle and its
//!    neighbours are now, and the book plans the rest again (`assembly_replanned`); a site tried
//!    too often is given up, a particle whose pushes failed twice is not sent again;
//! 4. a last full frame judges every site, and the assembly is written as a record
//!    ([`record`]): `assembly_done`.
//!
//! The whole runs on a thread of its own, never on the loop's or the async workers' (a plan of a
//! crowded scene takes a few tenths of a second). A `stop`, the lease holder leaving or the
//! server shutting down ends it `stopped` at once, the running push retracted by the loop; the
//! last full frame and the record are still made. The strategy is derived once per kind of
//! particle (size and material) and reused for every particle of that kind.

mod kinds;
mod moves;
pub mod record;
#[cfg(test)]
mod tests;
pub mod wire;

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use nanopush_instrument::assembly::{AssemblyOptions, Book, Pattern, PlanSettings, Seen, TrueParticle, summary};
use nanopush_instrument::scan::{HeightImage, ScanParams, Tip, scan};
use nanopush_proto::assembly::AssemblySummary;
use nanopush_proto::ws::{AssemblyNow, ServerMessage};

use crate::app_state::AppState;
use crate::records::Recorded;
use kinds::Kinds;
use record::Ending;

/// An assembly as its command asked for it.
#[derive(Debug, Clone)]
pub struct AssemblyJob {
    /// Its number (per server run).
    pub number: u64,
    /// The pattern.
    pub pattern: Pattern,
    /// Tolerances and tries.
    pub options: AssemblyOptions,
    /// Plan only: nothing moves.
    pub plan_only: bool,
    /// The client that commanded it.
    pub by: u32,
    /// Its person's name, for the records and the audit log.
    pub person: String,
    /// The `stop` generation it began in: a `stop` changes it.
    pub generation: u64,
}

/// Runs `job` on this thread (the instrument marked busy by the command); whatever happens, the
/// instrument is free and `assembly_done` said at the end, even after a panic.
pub fn run_assembly(st: &Arc<AppState>, job: AssemblyJob) {
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Assembly::new(st, &job).run()));
    if ran.is_err() {
        tracing::error!("assembly {} failed (internal error)", job.number);
        record::finish(
            st,
            &job,
            Ending {
                outcome: "error",
                reason: Some("the assembly failed (internal error); the server lives on".into()),
                summary: None,
                record: None,
            },
        );
    }
}

/// One assembly running.
struct Assembly<'a> {
    st: &'a Arc<AppState>,
    job: &'a AssemblyJob,
    book: Book,
    settings: PlanSettings,
    tip: Tip,
    base: ScanParams,
    kinds: Kinds,
    started: Instant,
    scan_time: f64,
    push_time: f64,
    /// The runs of its pushes, and the records of its moves' last pushes.
    runs: Vec<u64>,
    push_records: Vec<String>,
    /// Its record from the first plan on.
    opened: Option<record::Opened>,
    /// Hidden: particles the simulation has overlapping after a move (each pair once).
    violations: Vec<String>,
    overlapping: std::collections::BTreeSet<(u32, u32)>,
}

impl<'a> Assembly<'a> {
    fn new(st: &'a Arc<AppState>, job: &'a AssemblyJob) -> Assembly<'a> {
        let settings = PlanSettings::from_scene(&st.scene, job.options.tolerance);
        let tip = Tip::from_scene(&st.scene);
        let base = ScanParams::from_scene(&st.scene);
        Assembly {
            st,
            job,
            book: Book::new(&job.pattern, job.options, settings, tip, base.noise_rms),
            settings,
            tip,
            base,
            kinds: Kinds::default(),
            started: Instant::now(),
            scan_time: 0.0,
            push_time: 0.0,
            runs: Vec::new(),
            push_records: Vec::new(),
            opened: None,
            violations: Vec::new(),
            overlapping: Default::default(),
        }
    }

    /// Writes the record as it stands, with `summary` and the last full frame's record.
    fn write_record(&self, summary: &AssemblySummary, last_frame: &Option<Recorded>) -> Option<Recorded> {
        let opened = self.opened.as_ref()?;
        Some(record::write(
            self.st,
            self.job,
            opened,
            summary,
            last_frame,
            (&self.runs, &self.push_records),
        ))
    }

    /// The record, `running`, with the moves made so far.
    fn write_running(&self) {
        self.write_record(&self.summary("running", None, &[]), &None);
    }

    /// Why the assembly must stop now, in the words of a stopped push, or `None`.
    fn stopped(&self) -> Option<&'static str> {
        stop_reason(self.st, self.job)
    }

    /// Changes what a client joining now is told.
    fn show(&self, f: impl FnOnce(&mut AssemblyNow)) {
        if let Ok(mut now) = self.st.activity.assembly_now.lock()
            && let Some(a) = now.as_mut()
        {
            f(a);
        }
    }

    /// A full frame of the scene's `[scan]` of the sample as it is now, and the particles in it.
    fn full_frame(&mut self) -> (HeightImage, Vec<Seen>) {
        let img = scan(&self.st.surface_now(), self.tip, self.base);
        self.scan_time += self.base.frame_time();
        let seen = Seen::found_in(&img, &self.tip);
        (img, seen)
    }

    fn run(mut self) {
        let st = self.st;
        let n = self.job.number;
        let (first_img, map) = self.full_frame();
        let refusal = self.book.start(map).err();
        let first_plan = wire::plan(self.book.plan(), self.book.map());
        let first_frame = (!self.job.plan_only).then(|| record::frame(st, &first_img, &self.job.person));
        self.opened = Some(record::Opened {
            name: record::name(st, self.job),
            first_plan: first_plan.clone(),
            first_frame,
        });
        if let Some(why) = refusal {
            let summary = self.summary("refused", Some(why.clone()), &[]);
            let rec = self.write_record(&summary, &None);
            return record::finish(
                st,
                self.job,
                Ending {
                    outcome: "refused",
                    reason: Some(why),
                    summary: Some(summary),
                    record: rec,
                },
            );
        }
        self.show(|a| {
            a.plan = Some(first_plan.clone());
            a.phase = if self.job.plan_only { "planned" } else { "moving" }.into();
        });
        st.broadcast_event(&ServerMessage::AssemblyPlanned {
            assembly: n,
            by: self.job.by,
            plan_only: self.job.plan_only,
            pattern: self.job.pattern.name.clone(),
            sites: wire::sites(&self.job.pattern, self.job.options.tolerance),
            plan: first_plan.clone(),
            frame: self
                .opened
                .as_ref()
                .and_then(|o| o.first_frame.as_ref())
                .and_then(|r| r.as_ref().ok().cloned()),
        });
        if self.job.plan_only {
            return record::finish(
                st,
                self.job,
                Ending {
                    outcome: "planned",
                    reason: None,
                    summary: None,
                    record: None,
                },
            );
        }
        self.write_running();
        let stopped = self.moves();
        self.show(|a| {
            a.phase = "judging".into();
            a.moving = None;
        });
        let (last_img, last_map) = self.full_frame();
        let last_record = Some(record::frame(st, &last_img, &self.job.person));
        let truth = self.truth();
        let sites = self.book.judge(&last_map, &|m| nearest_true(&truth, m));
        remember_found(st, &truth, &last_map);
        let outcome = match stopped {
            Some(_) => "stopped",
            None if sites.iter().all(|s| s.status == "filled") => "filled",
            None => "incomplete",
        };
        let reason = stopped.map(|why| format!("stopped: {why}"));
        let summary = self.summary(outcome, None, &sites);
        let rec = self.write_record(&summary, &last_record);
        record::finish(
            st,
            self.job,
            Ending {
                outcome,
                reason,
                summary: Some(summary),
                record: rec,
            },
        );
    }

    /// The moves of the plan, each followed by the plan made again, until none is left, its
    /// budget is spent or it is stopped (then why).
    fn moves(&mut self) -> Option<&'static str> {
        let st = self.st;
        let n = self.job.number;
        let mut number = 0;
        while let Some(mv) = self.book.next_move().cloned() {
            if let Some(why) = self.stopped() {
                return Some(why);
            }
            let truth = self.truth();
            let p = self.book.map()[mv.particle];
            let Some(id) = nearest_true(&truth, (p.x, p.y)).map(|t| t.id) else {
                self.book
                    .exclude(&[mv.particle], "the instrument does not know this particle");
                continue;
            };
            let kind = match self.kinds.strategy(st, id, self.least_tolerance()) {
                Ok(kind) => kind,
                Err(why) => {
                    // Every particle of its kind is refused alike.
                    let same: Vec<usize> = (0..self.book.map().len())
                        .filter(|&k| {
                            let q = self.book.map()[k];
                            nearest_true(&truth, (q.x, q.y)).is_some_and(|t| self.kinds.same_kind(st, t.id, id))
                        })
                        .collect();
                    self.book.exclude(&same, &why);
                    continue;
                }
            };
            number += 1;
            let of = number + self.book.plan().moves.len() - 1;
            self.show(|a| {
                a.phase = "moving".into();
                a.moving = Some([number, of]);
            });
            st.broadcast_event(&ServerMessage::AssemblyMoveStarted {
                assembly: n,
                number,
                of,
                planned: wire::planned_move(&mv),
                particle_id: id,
            });
            let made = moves::make(self, &mv, id, &kind);
            self.check_overlaps(number);
            self.scan_time += made.scans as f64 * local_frame_time(&self.base);
            self.push_time += made.done.record.push_time;
            self.runs.extend(&made.runs);
            self.push_records.extend(made.record.clone());
            let summary = summary::made(&made.done.record);
            st.broadcast_event(&ServerMessage::AssemblyMoveEnded {
                assembly: n,
                number,
                made: summary.clone(),
            });
            self.show(|a| {
                a.phase = "replanning".into();
                a.moves.push(summary);
            });
            if let Some(site) = self.book.moved(&mv, made.done) {
                self.show(|a| a.filled.push(site));
                st.broadcast_event(&ServerMessage::AssemblySiteFilled { assembly: n, site });
            }
            // The record first: a client told of the new plan finds the move in it.
            self.write_running();
            let plan = wire::plan(self.book.plan(), self.book.map());
            self.show(|a| a.plan = Some(plan.clone()));
            st.broadcast_event(&ServerMessage::AssemblyReplanned { assembly: n, plan });
        }
        None
    }

    /// Hidden: after move `number`, any two particles the simulation has overlapping (the
    /// simulated instrument lets a particle pass into another, so a plan must never send one
    /// there), each pair reported once.
    fn check_overlaps(&mut self, number: usize) {
        let truth = truth_now(self.st);
        for (i, (a, ra)) in truth.iter().enumerate() {
            for (b, rb) in &truth[i + 1..] {
                let gap = (a.at.0 - b.at.0).hypot(a.at.1 - b.at.1) - (ra + rb);
                if gap < -1e-9 && self.overlapping.insert((a.id.min(b.id), a.id.max(b.id))) {
                    self.violations.push(format!(
                        "after move {number}, particles {} and {} overlap ({:.0} nm deep) at ({:.3}, {:.3}) µm",
                        a.id,
                        b.id,
                        -gap * 1e9,
                        a.at.0 * 1e6,
                        a.at.1 * 1e6
                    ));
                }
            }
        }
    }

    /// The tolerance the strategy is derived for: the least a site asks.
    fn least_tolerance(&self) -> f64 {
        self.job
            .pattern
            .sites
            .iter()
            .filter_map(|s| s.tolerance)
            .fold(self.settings.tolerance, f64::min)
    }

    /// Where the simulation has each particle now (the loop's snapshot): the report's hidden
    /// columns, and the scene id of a particle found (the model of its material comes from it,
    /// as a lab knows its sample's particles).
    fn truth(&self) -> Vec<(TrueParticle, f64)> {
        truth_now(self.st)
    }

    fn summary(
        &self,
        outcome: &str,
        refusal: Option<String>,
        sites: &[nanopush_instrument::assembly::SiteReport],
    ) -> nanopush_proto::assembly::AssemblySummary {
        summary::summary(
            &self.job.pattern,
            outcome,
            refusal,
            sites,
            self.book.moves(),
            summary::Totals {
                wall_time: self.started.elapsed().as_secs_f64(),
                push_time: self.push_time,
                scan_time: self.scan_time,
                // The server's loop keeps no trace here to follow a push through: the
                // simulation's particles are checked for overlaps after each move instead.
                violations: self.violations.clone(),
            },
        )
    }
}

/// Why the assembly `job` must stop now (the server shutting down, the lease holder gone, a
/// `stop`), in a stopped push's words, or `None`.
fn stop_reason(st: &AppState, job: &AssemblyJob) -> Option<&'static str> {
    use crate::control_loop::StopReason;
    if st.activity.stopping.load(Relaxed) {
        return Some("server shutting down");
    }
    if st.activity.generation.load(Relaxed) == job.generation {
        return None;
    }
    Some(if st.lease_holder() == Some(job.by) {
        StopReason::Operator.words()
    } else {
        StopReason::HolderDisconnected.words()
    })
}

/// The particles as the simulation has them now, each with its radius (m).
fn truth_now(st: &AppState) -> Vec<(TrueParticle, f64)> {
    st.shared
        .snapshot
        .lock()
        .map(|s| {
            s.particles
                .iter()
                .map(|&(id, x, y, r)| (TrueParticle { id, at: (x, y) }, r))
                .collect()
        })
        .unwrap_or_default()
}

/// The particle of `truth` nearest `m`, if `m` lies within two of its radii (a particle found
/// is placed within a fraction of its radius).
fn nearest_true(truth: &[(TrueParticle, f64)], m: (f64, f64)) -> Option<TrueParticle> {
    let d = |t: &TrueParticle| (t.at.0 - m.0).hypot(t.at.1 - m.1);
    truth
        .iter()
        .min_by(|a, b| d(&a.0).total_cmp(&d(&b.0)))
        .filter(|(t, r)| d(t) < 2.0 * r)
        .map(|(t, _)| *t)
}

/// Where the last full frame found each particle: what the server believes from now on (`state`).
fn remember_found(st: &AppState, truth: &[(TrueParticle, f64)], found: &[Seen]) {
    for (t, r) in truth {
        let d = |p: &Seen| (p.x - t.at.0).hypot(p.y - t.at.1);
        if let Some(p) = found
            .iter()
            .min_by(|a, b| d(a).total_cmp(&d(b)))
            .filter(|p| d(p) < 2.0 * r)
        {
            st.remember(t.id, [p.x, p.y]);
        }
    }
}

/// Time of a local scan (s): its lines at the scene's line rate.
fn local_frame_time(base: &ScanParams) -> f64 {
    nanopush_instrument::control::moves::locate::LOCAL_PIXELS as f64 / base.line_rate
}
