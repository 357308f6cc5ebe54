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
use crate::scan::{HeightImage, ScanParams, Tip, find_particles, scan};
use crate::scene::Scene;
use crate::scene::file::ParticleFile;

use super::pattern::Pattern;
use super::plan::{Constraints, Plan, PlanSettings, Purpose, Seen, SiteState, Unfilled, check_fit, plan, site_radius};
use super::routing::{MapRouting, update_map};

/// How an assembly is run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssemblyOptions {
    /// A site's tolerance when the pattern gives none (m).
    pub tolerance: f64,
    /// Pushes a move may make (the first and its corrections).
    pub attempts: u32,
    /// Moves a site gets before it is given up.
    pub tries_per_site: u32,
}

impl Default for AssemblyOptions {
    fn default() -> AssemblyOptions {
        AssemblyOptions {
            tolerance: crate::control::derive::DEFAULT_TOLERANCE,
            attempts: crate::control::moves::DEFAULT_ATTEMPTS,
            tries_per_site: 3,
        }
    }
}

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

/// One move as it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveRecord {
    /// Why it was made.
    pub purpose: Purpose,
    /// The particle's scene id.
    pub particle: Option<u32>,
    /// Where it was sent from and to (m).
    pub from: (f64, f64),
    /// Its target.
    pub to: (f64, f64),
    /// `ok`, `missed`, `not_found`, a push's failure code, or why the move could not be made.
    pub outcome: String,
    /// Its distance from the target, as the scan after measured it (m).
    pub error: Option<f64>,
    /// Pushes made.
    pub pushes: u32,
    /// Simulated time of its pushes (s).
    pub push_time: f64,
}

/// One site at the end.
#[derive(Debug, Clone, PartialEq)]
pub struct SiteReport {
    /// The site (m).
    pub target: (f64, f64),
    /// Its tolerance (m).
    pub tolerance: f64,
    /// The scene id of the particle on it, or of the particle last sent to it.
    pub particle: Option<u32>,
    /// Where the last full frame shows that particle (m).
    pub measured: Option<(f64, f64)>,
    /// Hidden: where it truly is (m).
    pub true_position: Option<(f64, f64)>,
    /// Hidden: its true distance from the target (m).
    pub error: Option<f64>,
    /// `filled`, `missed`, `unreachable` or `refused`.
    pub status: &'static str,
    /// Why it is not filled.
    pub reason: Option<String>,
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
    pattern: &'a Pattern,
    options: &'a AssemblyOptions,
    settings: PlanSettings,
    tip: Tip,
    base: ScanParams,
    map: Vec<Seen>,
    kinds: Vec<Kind>,
    constraints: Constraints,
    tries: Vec<u32>,
    failures: Vec<u32>,
    moves: Vec<MoveRecord>,
    scan_time: f64,
    violations: Vec<String>,
    /// The scene id last sent to each site.
    sent: Vec<Option<u32>>,
}

impl<'a> Assembly<'a> {
    fn new(scene: &'a Scene, afm: &'a mut Afm, pattern: &'a Pattern, options: &'a AssemblyOptions) -> Assembly<'a> {
        Assembly {
            scene,
            afm,
            pattern,
            options,
            settings: PlanSettings::from_scene(scene, options.tolerance),
            tip: Tip::from_scene(scene),
            base: ScanParams::from_scene(scene),
            map: Vec::new(),
            kinds: Vec::new(),
            constraints: Constraints::default(),
            tries: vec![0; pattern.sites.len()],
            failures: Vec::new(),
            moves: Vec::new(),
            scan_time: 0.0,
            violations: Vec::new(),
            sent: vec![None; pattern.sites.len()],
        }
    }

    /// A full frame of the scene's `[scan]`, and the particles in it.
    fn full_frame(&mut self) -> (HeightImage, Vec<Seen>) {
        let img = scan(&self.afm.surface(), self.tip, self.base);
        self.scan_time += self.base.frame_time();
        let seen = find_particles(&img, &self.tip)
            .iter()
            .map(|l| Seen {
                x: l.x,
                y: l.y,
                radius: l.radius,
            })
            .collect();
        (img, seen)
    }

    fn replan(&self) -> Plan {
        plan(&self.map, self.pattern, &self.settings, &self.constraints)
    }

    fn run(mut self, events: &mut dyn FnMut(Event), stop: &dyn Fn() -> bool) -> AssemblyRun {
        let started = Instant::now();
        let pushes_from = self.afm.time();
        let (first_img, map) = self.full_frame();
        self.map = map;
        self.failures = vec![0; self.map.len()];
        let r = site_radius(self.pattern, &self.map);
        let first_plan = self.replan();
        let refusal = if let Err(e) = check_fit(self.pattern, r, &self.settings) {
            Some(e.0)
        } else if self.map.is_empty() {
            Some("the full frame shows no particle".into())
        } else {
            None
        };
        let first = (first_img, self.map.clone(), first_plan.clone());
        if refusal.is_none() {
            events(Event::Planned {
                plan: &first_plan,
                map: &self.map,
            });
        }
        let mut plan = first_plan;
        let mut outcome = (refusal.is_some() || plan.fillable() == 0).then_some(Outcome::Refused);
        let budget = 4 * (self.map.len() + self.pattern.sites.len()) + 10;
        let mut number = 0;
        while outcome.is_none() {
            let Some(mv) = plan.moves.first().cloned() else { break };
            if stop() {
                outcome = Some(Outcome::Stopped);
                break;
            }
            if number >= budget {
                break;
            }
            // The strategy for the particle's kind, derived the first time it is sent.
            let Some((id, kind)) = self.kind_of(mv.particle) else {
                self.constraints
                    .excluded
                    .push((mv.particle, "the instrument does not know this particle".into()));
                plan = self.replan();
                continue;
            };
            if let Err(why) = &self.kinds[kind].scene {
                let why = why.clone();
                for k in 0..self.map.len() {
                    if self.kind_of(k).is_some_and(|(_, j)| j == kind) {
                        self.constraints.excluded.push((k, why.clone()));
                    }
                }
                plan = self.replan();
                continue;
            }
            number += 1;
            let of = number + plan.moves.len() - 1;
            events(Event::MoveStarted {
                number,
                of,
                planned: &mv,
            });
            let record = self.make_move(&mv, id, kind);
            events(Event::MoveEnded {
                number,
                record: &record,
            });
            if let Purpose::Fill { site } = mv.purpose {
                self.sent[site] = Some(id);
                if record.outcome == "ok" {
                    events(Event::SiteFilled { site });
                } else {
                    self.tries[site] += 1;
                    if self.tries[site] >= self.options.tries_per_site {
                        let why = format!(
                            "missed after {} moves; the last: {}{}",
                            self.tries[site],
                            record.outcome,
                            record
                                .error
                                .map_or(String::new(), |e| format!(", {:.1} nm from it", e * 1e9))
                        );
                        self.constraints.closed.push((site, Unfilled::Missed(why)));
                    }
                }
            }
            self.moves.push(record);
            plan = self.replan();
            events(Event::Replanned {
                plan: &plan,
                map: &self.map,
            });
        }
        let (last_img, last_map) = self.full_frame();
        let sites = self.judge(&plan, &last_map);
        let outcome = outcome.unwrap_or(if sites.iter().all(|s| s.status == "filled") {
            Outcome::Filled
        } else {
            Outcome::Incomplete
        });
        let refusal = match outcome {
            Outcome::Refused => Some(refusal.unwrap_or_else(|| {
                let reasons: Vec<String> = sites
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| s.reason.as_ref().map(|r| format!("site {i}: {r}")))
                    .collect();
                format!("no site can be filled: {}", reasons.join("; "))
            })),
            _ => None,
        };
        AssemblyRun {
            outcome,
            refusal,
            sites,
            moves: self.moves,
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
        let p = self.map[k];
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
        let tolerance = self
            .pattern
            .sites
            .iter()
            .filter_map(|s| s.tolerance)
            .fold(self.options.tolerance, f64::min);
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

    /// Makes one move of the plan with particle `id` of kind `kind`, and updates the map from
    /// its scans.
    fn make_move(&mut self, mv: &super::plan::PlannedMove, id: u32, kind: usize) -> MoveRecord {
        let tolerance = match mv.purpose {
            Purpose::Fill { site } => self.pattern.sites[site].tolerance.unwrap_or(self.options.tolerance),
            // Aside, anywhere near the spot will do.
            Purpose::Clear | Purpose::Park => (0.5 * self.settings.clearance).max(self.options.tolerance),
        };
        let options = MoveOptions {
            tolerance,
            attempts: self.options.attempts,
            pause: None,
        };
        let Kind { scene, prepared, .. } = &mut self.kinds[kind];
        let scene = scene.as_ref().expect("a kind sent has its strategy");
        let t0 = self.afm.time();
        let radius = self.map[mv.particle].radius;
        let (result, images) = {
            let mut routing = MapRouting {
                map: &self.map,
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
        let mut record = MoveRecord {
            purpose: mv.purpose,
            particle: Some(id),
            from: mv.from,
            to: mv.to,
            outcome: String::new(),
            error: None,
            pushes: 0,
            push_time: self.afm.time() - t0,
        };
        // Where the mover was during the move: the scans taken then show it there.
        let mut path = vec![mv.from];
        if let Ok(run) = &result {
            path.push((run.before.1.x, run.before.1.y));
            for leg in &run.legs {
                path.extend([leg.from, leg.to, leg.run.summary.estimated_particle]);
            }
        }
        match result {
            Ok(run) => {
                self.check_collisions(&run, id);
                record.outcome = run.verdict.code().to_string();
                record.pushes = run.legs.len() as u32;
                record.error = match run.verdict {
                    Verdict::Ok { error } | Verdict::Missed { error } => Some(error),
                    _ => None,
                };
                if let Some(l) = run.after.1 {
                    self.map[mv.particle] = Seen {
                        x: l.x,
                        y: l.y,
                        radius: l.radius,
                    };
                } else if let Some(last) = run.legs.last() {
                    let (x, y) = last.run.summary.estimated_particle;
                    self.map[mv.particle].x = x;
                    self.map[mv.particle].y = y;
                }
                path.push((self.map[mv.particle].x, self.map[mv.particle].y));
                if matches!(run.verdict, Verdict::Failed { .. } | Verdict::NotFound) {
                    self.failed(mv.particle, &record.outcome);
                }
            }
            Err(MoveRunError::Locate(MoveError::NotFound { cause, .. })) => {
                record.outcome = format!("not_found: {cause}");
                self.failed(mv.particle, &record.outcome);
            }
            Err(e) => {
                record.outcome = format!("refused: {e}");
                self.failed(mv.particle, &record.outcome);
            }
        }
        update_map(
            &mut self.map,
            mv.particle,
            &path,
            &images,
            &self.tip,
            self.base.noise_rms,
        );
        self.failures.resize(self.map.len(), 0);
        record
    }

    /// A particle whose move failed; twice, and it is not sent again.
    fn failed(&mut self, k: usize, why: &str) {
        self.failures[k] += 1;
        if self.failures[k] >= 2 {
            self.constraints.excluded.push((
                k,
                format!("the pushes of the particle that could fill it failed twice: {why}"),
            ));
        }
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

    /// Each site by the last full frame: filled when a particle lies within its tolerance, else
    /// why it is not.
    fn judge(&self, plan: &Plan, last: &[Seen]) -> Vec<SiteReport> {
        let mut taken = vec![false; last.len()];
        self.pattern
            .sites
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let tolerance = s.tolerance.unwrap_or(self.options.tolerance);
                let on = last
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| !taken[*k])
                    .map(|(k, p)| (k, (p.x - s.x).hypot(p.y - s.y)))
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                let filled = on.filter(|&(_, d)| d <= tolerance);
                if let Some((k, _)) = filled {
                    taken[k] = true;
                }
                let measured = on.map(|(k, _)| (last[k].x, last[k].y));
                let truth = measured.and_then(|m| {
                    self.afm
                        .particles()
                        .iter()
                        .min_by(|a, b| (a.x - m.0).hypot(a.y - m.1).total_cmp(&(b.x - m.0).hypot(b.y - m.1)))
                        .filter(|q| (q.x - m.0).hypot(q.y - m.1) < 2.0 * q.radius)
                        .copied()
                });
                let (status, reason) = if filled.is_some() {
                    ("filled", None)
                } else {
                    match &plan.sites[i] {
                        SiteState::Open(u) => (u.status(), Some(u.reason())),
                        _ => (
                            "missed",
                            Some(format!(
                                "no particle within its {:.1} nm tolerance in the last full frame",
                                tolerance * 1e9
                            )),
                        ),
                    }
                };
                let near =
                    filled.is_some() || on.is_some_and(|(_, d)| d < 4.0 * self.settings.clearance.max(tolerance));
                SiteReport {
                    target: (s.x, s.y),
                    tolerance,
                    particle: if filled.is_some() {
                        truth.map(|t| t.id)
                    } else {
                        self.sent[i]
                    },
                    measured: measured.filter(|_| near),
                    true_position: truth.filter(|_| near).map(|t| (t.x, t.y)),
                    error: truth.filter(|_| near).map(|t| (t.x - s.x).hypot(t.y - s.y)),
                    status,
                    reason,
                }
            })
            .collect()
    }
}

/// Time of a local scan (s): [`crate::control::moves::locate::LOCAL_PIXELS`] lines at the
/// scene's line rate.
fn local_frame_time(base: &ScanParams) -> f64 {
    crate::control::moves::locate::LOCAL_PIXELS as f64 / base.line_rate
}

#[cfg(test)]
mod tests;
