//! An assembly against the simulated AFM, as an operator would run it:
//!
//! 1. a full frame (the scene's `[scan]`) finds every particle: the map;
//! 2. the plan ([`super::plan`]) assigns, orders and routes the moves;
//! 3. the first move is made as `nanopush push` makes one (the derived strategy, corrections,
//!    the scan after judging it), with local scans only ([`MapRouting`]);
//! 4. the map learns from the move's local scans where the moved particle and its neighbours are
//!    now (a nudged neighbour, drift), and the rest is planned again;
//! 5. a site tried [`AssemblyOptions::tries_per_site`] times is given up (`missed`), a particle
//!    whose pushes failed twice is not sent again, and another is sent instead;
//! 6. a last full frame judges every site.
//!
//! The strategy is derived once for each kind of particle (size and material), with its
//! dry run, and reused for every particle of that kind; so is the model's prediction for the
//! estimator. A kind the strategy refuses is not sent, and the sites only it could fill say why.
//!
//! The simulated instrument names each particle by the scene's id (the model of the particle's
//! material comes from it, as a lab knows its sample's particles); the controller sees only what
//! the scans show.

use std::time::Instant;

use crate::afm::Afm;
use crate::control::derive::{DerivedStrategy, derive};
use crate::control::moves::run::{MoveRun, move_particle_with};
use crate::control::moves::{MoveError, MoveOptions, MoveRunError, MoveTarget, Verdict};
use crate::control::strategy::runner::Prepared;
use crate::scan::{HeightImage, ScanParams, Tip, scan};
use crate::scene::Scene;
use crate::scene::file::ParticleFile;

use super::book::{AssemblyOptions, Book, MoveDone, MoveRecord, SiteReport, TrueParticle};
use super::pattern::Pattern;
use super::plan::{Plan, PlanSettings, PlannedMove, Seen};
use super::routing::MapRouting;

/// What an assembly reports as it goes.
#[derive(Debug)]
pub enum Event<'a> {
    /// The first plan, from the first full frame.
    Planned {
        /// The plan.
        plan: &'a Plan,
        /// The map it was made from.
        map: &'a [Seen],
    },
    /// A move begins.
    MoveStarted {
        /// Its number, from 1.
        number: usize,
        /// Moves planned in all, those made included.
        of: usize,
        /// The move.
        planned: &'a super::plan::PlannedMove,
    },
    /// A move ended.
    MoveEnded {
        /// Its number.
        number: usize,
        /// What it ended with.
        record: &'a MoveRecord,
    },
    /// A site holds its particle, as the scan after the move shows.
    SiteFilled {
        /// The site.
        site: usize,
    },
    /// The rest, planned again from the map the move's scans updated.
    Replanned {
        /// The plan.
        plan: &'a Plan,
        /// The map.
        map: &'a [Seen],
    },
}

/// How an assembly ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Every site holds a particle within its tolerance, by the last full frame.
    Filled,
    /// A site ended open.
    Incomplete,
    /// Refused before anything moved.
    Refused,
    /// Stopped by the operator.
    Stopped,
}

impl Outcome {
    /// `filled`, `incomplete`, `refused`, `stopped`.
    pub fn code(self) -> &'static str {
        match self {
            Outcome::Filled => "filled",
            Outcome::Incomplete => "incomplete",
            Outcome::Refused => "refused",
            Outcome::Stopped => "stopped",
        }
    }
}

/// A whole assembly.
#[derive(Debug, Clone, PartialEq)]
pub struct AssemblyRun {
    /// How it ended.
    pub outcome: Outcome,
    /// Why it was refused, when it was.
    pub refusal: Option<String>,
    /// Each site, in the pattern's order.
    pub sites: Vec<SiteReport>,
    /// Every move made.
    pub moves: Vec<MoveRecord>,
    /// The first full frame, the map from it and the first plan.
    pub first: (HeightImage, Vec<Seen>, Plan),
    /// The last full frame.
    pub last: Option<HeightImage>,
    /// Wall time (s).
    pub wall_time: f64,
    /// Simulated time of the pushes (s).
    pub push_time: f64,
    /// Simulated time of the scans, full frames and local ones, at the scene's line rate (s).
    pub scan_time: f64,
    /// Hidden: what the truth says went wrong (a pushed particle through another).
    pub violations: Vec<String>,
}

/// The strategy for one kind of particle, derived once.
struct Kind {
    particle: ParticleFile,
    /// The scene with the kind's strategy applied, or why it is refused.
    scene: Result<Scene, String>,
    prepared: Option<Prepared>,
}

/// Assembles `pattern` on `afm` (its tip at the start height) with `scene`'s instrument, as
/// `options` says, telling `events` as it goes; `stop` is asked between moves.
pub fn assemble(
    scene: &Scene,
    afm: &mut Afm,
    pattern: &Pattern,
    options: &AssemblyOptions,
    events: &mut dyn FnMut(Event),
    stop: &dyn Fn() -> bool,
) -> AssemblyRun {
    Assembly::new(scene, afm, pattern, options).run(events, stop)
}

struct Assembly<'a> {
    scene: &'a Scene,
    afm: &'a mut Afm,
    book: Book,
    settings: PlanSettings,
    tip: Tip,
    base: ScanParams,
    kinds: Vec<Kind>,
    scan_time: f64,
    violations: Vec<String>,
}

impl<'a> Assembly<'a> {
    fn new(scene: &'a Scene, afm: &'a mut Afm, pattern: &Pattern, options: &AssemblyOptions) -> Assembly<'a> {
        let settings = PlanSettings::from_scene(scene, options.tolerance);
        let tip = Tip::from_scene(scene);
        let base = ScanParams::from_scene(scene);
        Assembly {
            scene,
            afm,
            book: Book::new(pattern, *options, settings, tip, base.noise_rms),
            settings,
            tip,
            base,
            kinds: Vec::new(),
            scan_time: 0.0,
            violations: Vec::new(),
        }
    }

    /// A full frame of the scene's `[scan]`, and the particles in it.
    fn full_frame(&mut self) -> (HeightImage, Vec<Seen>) {
        let img = scan(&self.afm.surface(), self.tip, self.base);
        self.scan_time += self.base.frame_time();
        let seen = Seen::found_in(&img, &self.tip);
        (img, seen)
    }

    fn run(mut self, events: &mut dyn FnMut(Event), stop: &dyn Fn() -> bool) -> AssemblyRun {
        let started = Instant::now();
        let pushes_from = self.afm.time();
        let (first_img, map) = self.full_frame();
        let refusal = self.book.start(map).err();
        let first = (first_img, self.book.map().to_vec(), self.book.plan().clone());
        if refusal.is_none() {
            events(Event::Planned {
                plan: self.book.plan(),
                map: self.book.map(),
            });
        }
        let mut outcome = refusal.is_some().then_some(Outcome::Refused);
        let mut number = 0;
        while outcome.is_none() {
            let Some(mv) = self.book.next_move().cloned() else {
                break;
            };
            if stop() {
                outcome = Some(Outcome::Stopped);
                break;
            }
            // The strategy for the particle's kind, derived the first time it is sent.
            let Some((id, kind)) = self.kind_of(mv.particle) else {
                self.book
                    .exclude(&[mv.particle], "the instrument does not know this particle");
                continue;
            };
            if let Err(why) = &self.kinds[kind].scene {
                let why = why.clone();
                let same: Vec<usize> = (0..self.book.map().len())
                    .filter(|&k| self.kind_of(k).is_some_and(|(_, j)| j == kind))
                    .collect();
                self.book.exclude(&same, &why);
                continue;
            }
            number += 1;
            let of = number + self.book.plan().moves.len() - 1;
            events(Event::MoveStarted {
                number,
                of,
                planned: &mv,
            });
            let done = self.make_move(&mv, id, kind);
            events(Event::MoveEnded {
                number,
                record: &done.record,
            });
            if let Some(site) = self.book.moved(&mv, done) {
                events(Event::SiteFilled { site });
            }
            events(Event::Replanned {
                plan: self.book.plan(),
                map: self.book.map(),
            });
        }
        let (last_img, last_map) = self.full_frame();
        let truth = |m: (f64, f64)| {
            self.afm
                .particles()
                .iter()
                .min_by(|a, b| (a.x - m.0).hypot(a.y - m.1).total_cmp(&(b.x - m.0).hypot(b.y - m.1)))
                .filter(|q| (q.x - m.0).hypot(q.y - m.1) < 2.0 * q.radius)
                .map(|q| TrueParticle {
                    id: q.id,
                    at: (q.x, q.y),
                })
        };
        let sites = self.book.judge(&last_map, &truth);
        let outcome = outcome.unwrap_or(if sites.iter().all(|s| s.status == "filled") {
            Outcome::Filled
        } else {
            Outcome::Incomplete
        });
        AssemblyRun {
            outcome,
            refusal,
            sites,
            moves: self.book.moves().to_vec(),
            first,
            last: Some(last_img),
            wall_time: started.elapsed().as_secs_f64(),
            push_time: self.afm.time() - pushes_from,
            scan_time: self.scan_time,
            violations: self.violations,
        }
    }

    /// The scene id of map particle `k` and its kind (deriving the kind's strategy the first
    /// time), from the simulated instrument's particle nearest it.
    fn kind_of(&mut self, k: usize) -> Option<(u32, usize)> {
        let p = self.book.map()[k];
        let truth = self
            .afm
            .particles()
            .iter()
            .map(|q| (q.id, (q.x - p.x).hypot(q.y - p.y), q.radius))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|&(_, d, r)| d < 2.0 * r.max(p.radius))?;
        let part = self.scene.file.particles.iter().find(|q| q.id == truth.0)?.clone();
        let same = |a: &ParticleFile| {
            (
                a.radius_nm,
                a.youngs_modulus_gpa,
                a.poisson_ratio,
                a.density_kg_per_m3,
                a.hamaker_zj,
            ) == (
                part.radius_nm,
                part.youngs_modulus_gpa,
                part.poisson_ratio,
                part.density_kg_per_m3,
                part.hamaker_zj,
            )
        };
        if let Some(j) = self.kinds.iter().position(|kd| same(&kd.particle)) {
            return Some((truth.0, j));
        }
        let pattern = self.book.pattern();
        let tolerance = pattern
            .sites
            .iter()
            .filter_map(|s| s.tolerance)
            .fold(self.settings.tolerance, f64::min);
        let scene = derive(self.scene, part.id, tolerance)
            .map(|d: DerivedStrategy| {
                let mut s = self.scene.clone();
                d.apply(&mut s);
                s
            })
            .map_err(|e| format!("the strategy refuses particles of its kind: {e}"));
        self.kinds.push(Kind {
            particle: part,
            scene,
            prepared: None,
        });
        Some((truth.0, self.kinds.len() - 1))
    }

    /// Makes one move of the plan with particle `id` of kind `kind`: `nanopush push`'s move,
    /// routed over the map.
    fn make_move(&mut self, mv: &PlannedMove, id: u32, kind: usize) -> MoveDone {
        let options = MoveOptions {
            tolerance: self.book.tolerance_of(mv.purpose),
            attempts: self.book.options().attempts,
            pause: None,
        };
        let Kind { scene, prepared, .. } = &mut self.kinds[kind];
        let scene = scene.as_ref().expect("a kind sent has its strategy");
        let t0 = self.afm.time();
        let radius = self.book.map()[mv.particle].radius;
        let (result, images) = {
            let mut routing = MapRouting {
                map: self.book.map(),
                mover: mv.particle,
                settings: self.settings,
                scene,
                prepared,
                images: Vec::new(),
            };
            let result = move_particle_with(
                scene,
                self.afm,
                id,
                mv.from,
                radius,
                MoveTarget::Point(mv.to),
                options,
                &mut routing,
            );
            (result, routing.images)
        };
        self.scan_time += images.len() as f64 * local_frame_time(&self.base);
        let mut done = MoveDone {
            images,
            ..MoveDone::begun(mv, id)
        };
        done.record.push_time = self.afm.time() - t0;
        match result {
            Ok(run) => {
                self.check_collisions(&run, id);
                done.path.push((run.before.1.x, run.before.1.y));
                for leg in &run.legs {
                    done.path.extend([leg.from, leg.to, leg.run.summary.estimated_particle]);
                }
                done.record.outcome = run.verdict.code().to_string();
                done.record.pushes = run.legs.len() as u32;
                done.record.error = match run.verdict {
                    Verdict::Ok { error } | Verdict::Missed { error } => Some(error),
                    _ => None,
                };
                done.ended = match (run.after.1, run.legs.last()) {
                    (Some(l), _) => Some(Seen {
                        x: l.x,
                        y: l.y,
                        radius: l.radius,
                    }),
                    (None, Some(last)) => {
                        let (x, y) = last.run.summary.estimated_particle;
                        Some(Seen { x, y, radius })
                    }
                    (None, None) => None,
                };
                done.failed = matches!(run.verdict, Verdict::Failed { .. } | Verdict::NotFound);
            }
            Err(MoveRunError::Locate(MoveError::NotFound { cause, .. })) => {
                done.record.outcome = format!("not_found: {cause}");
                done.failed = true;
                done.absent = true;
            }
            Err(e) => {
                done.record.outcome = format!("refused: {e}");
                done.failed = true;
            }
        }
        done
    }

    /// Hidden: the pushed particle never overlapped another (the simulated instrument lets a
    /// particle pass through another, so the plan must never send one there).
    fn check_collisions(&mut self, run: &MoveRun, id: u32) {
        let others: Vec<_> = self.afm.particles().iter().filter(|p| p.id != id).copied().collect();
        let Some(me) = self.afm.particles().iter().find(|p| p.id == id).copied() else {
            return;
        };
        for leg in &run.legs {
            for row in leg.run.trace.iter().step_by(10) {
                for o in &others {
                    let gap = (row.particle.0 - o.x).hypot(row.particle.1 - o.y) - (me.radius + o.radius);
                    if gap < -1e-9 {
                        self.violations.push(format!(
                            "particle {id} went through particle {} ({:.0} nm deep) at ({:.3}, {:.3}) µm",
                            o.id,
                            -gap * 1e9,
                            row.particle.0 * 1e6,
                            row.particle.1 * 1e6
                        ));
                        return;
                    }
                }
            }
        }
    }
}

/// Time of a local scan (s): [`crate::control::moves::locate::LOCAL_PIXELS`] lines at the
/// scene's line rate.
fn local_frame_time(base: &ScanParams) -> f64 {
    crate::control::moves::locate::LOCAL_PIXELS as f64 / base.line_rate
}

#[cfg(test)]
mod tests;
