//! An assembly's book: what it knows and what it has done, whoever makes its moves (the
//! command line against the simulated AFM, [`super::run`], or the server through its control
//! loop). It holds the map (every particle as the scans last showed it), the plan, what each
//! site and particle has been through, and it plans again after every move.

use super::pattern::Pattern;
use super::plan::{
    Constraints, Plan, PlanSettings, PlannedMove, Purpose, Seen, SiteState, Unfilled, check_fit, plan, site_radius,
};
use super::routing::update_map;
use crate::scan::{HeightImage, Tip};

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

/// What a move's maker reports back.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveDone {
    /// The record of it.
    pub record: MoveRecord,
    /// Whether it failed (its push failed, or its particle was not found), as opposed to a miss.
    pub failed: bool,
    /// Whether the scan before its first push found nothing where the map has the particle: the
    /// map may be wrong there (a particle counted twice, or one the full frame's pixels made up),
    /// or the scan may have missed it; either way sending it again would find nothing again, so
    /// it is not sent again, and routes still keep clear of it.
    pub absent: bool,
    /// Where the scan after found the particle, or else where the controller estimates it.
    pub ended: Option<Seen>,
    /// Where the particle was during the move: scans taken then show it there.
    pub path: Vec<(f64, f64)>,
    /// Every local scan the move took.
    pub images: Vec<HeightImage>,
}

impl MoveDone {
    /// The report of move `mv` of the instrument's particle `particle` before anything is done:
    /// no outcome yet, the particle where the plan has it.
    pub fn begun(mv: &PlannedMove, particle: u32) -> MoveDone {
        MoveDone {
            record: MoveRecord {
                purpose: mv.purpose,
                particle: Some(particle),
                from: mv.from,
                to: mv.to,
                outcome: String::new(),
                error: None,
                pushes: 0,
                push_time: 0.0,
            },
            failed: false,
            absent: false,
            ended: None,
            path: vec![mv.from],
            images: Vec::new(),
        }
    }
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

/// A particle as the simulation has it, for the report's hidden columns: its scene id and
/// where it truly is (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueParticle {
    /// Its scene id.
    pub id: u32,
    /// Where it is (m).
    pub at: (f64, f64),
}

/// The book of one assembly.
#[derive(Debug, Clone)]
pub struct Book {
    pattern: Pattern,
    options: AssemblyOptions,
    settings: PlanSettings,
    tip: Tip,
    noise_rms: f64,
    map: Vec<Seen>,
    constraints: Constraints,
    tries: Vec<u32>,
    failures: Vec<u32>,
    sent: Vec<Option<u32>>,
    plan: Plan,
    moves: Vec<MoveRecord>,
    budget: usize,
}

impl Book {
    /// A book for `pattern` on an instrument of `settings`, with the scans' `tip` and noise RMS
    /// (m), which find particles in the moves' scans.
    pub fn new(pattern: &Pattern, options: AssemblyOptions, settings: PlanSettings, tip: Tip, noise_rms: f64) -> Book {
        Book {
            pattern: pattern.clone(),
            options,
            settings,
            tip,
            noise_rms,
            map: Vec::new(),
            constraints: Constraints::default(),
            tries: vec![0; pattern.sites.len()],
            failures: Vec::new(),
            sent: vec![None; pattern.sites.len()],
            plan: Plan {
                sites: Vec::new(),
                moves: Vec::new(),
            },
            moves: Vec::new(),
            budget: 0,
        }
    }

    /// Starts from the particles of the first full frame: the first plan, or why the
    /// assembly is refused before anything moves (the pattern does not fit, the frame shows no
    /// particle, no site can be filled).
    pub fn start(&mut self, map: Vec<Seen>) -> Result<&Plan, String> {
        self.map = map;
        self.failures = vec![0; self.map.len()];
        self.budget = 4 * (self.map.len() + self.pattern.sites.len()) + 10;
        // A pattern that does not fit is not planned: its sites may lie anywhere, and a plan
        // of them would name moves and blockers that can never be.
        let unfit = if self.map.is_empty() {
            Some("the full frame shows no particle".to_string())
        } else {
            check_fit(&self.pattern, site_radius(&self.pattern, &self.map), &self.settings)
                .err()
                .map(|e| e.0)
        };
        if let Some(why) = unfit {
            self.plan = Plan {
                sites: vec![SiteState::Open(Unfilled::Refused(why.clone())); self.pattern.sites.len()],
                moves: Vec::new(),
            };
            return Err(why);
        }
        self.replan();
        if self.plan.fillable() == 0 {
            let reasons: Vec<String> = self
                .plan
                .sites
                .iter()
                .enumerate()
                .filter_map(|(i, s)| match s {
                    SiteState::Open(u) => Some(format!("site {i}: {}", u.reason())),
                    _ => None,
                })
                .collect();
            return Err(format!("no site can be filled: {}", reasons.join("; ")));
        }
        Ok(&self.plan)
    }

    /// The plan as it stands.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The map as it stands.
    pub fn map(&self) -> &[Seen] {
        &self.map
    }

    /// The pattern.
    pub fn pattern(&self) -> &Pattern {
        &self.pattern
    }

    /// The options it runs with.
    pub fn options(&self) -> &AssemblyOptions {
        &self.options
    }

    /// The moves made so far.
    pub fn moves(&self) -> &[MoveRecord] {
        &self.moves
    }

    /// The next move to make: the plan's first, unless the moves' budget (four per particle
    /// and site) is spent.
    pub fn next_move(&self) -> Option<&PlannedMove> {
        if self.moves.len() >= self.budget {
            return None;
        }
        self.plan.moves.first()
    }

    /// What the moves toward `site` should be judged by: its tolerance; aside, anywhere near the
    /// spot will do.
    pub fn tolerance_of(&self, purpose: Purpose) -> f64 {
        match purpose {
            Purpose::Fill { site } => self.pattern.sites[site].tolerance.unwrap_or(self.options.tolerance),
            Purpose::Clear | Purpose::Park => (0.5 * self.settings.clearance).max(self.options.tolerance),
        }
    }

    /// Particles not to send again, with why; the plan is made again without them.
    pub fn exclude(&mut self, particles: &[usize], why: &str) {
        for &k in particles {
            self.constraints.excluded.push((k, why.to_string()));
        }
        self.replan();
    }

    /// Records the move `mv` as its maker reports it, updates the map from its scans, and plans
    /// the rest again. Returns the site it filled, if it filled one.
    pub fn moved(&mut self, mv: &PlannedMove, done: MoveDone) -> Option<usize> {
        if let Some(at) = done.ended {
            self.map[mv.particle] = at;
        }
        let mut path = done.path.clone();
        path.push((self.map[mv.particle].x, self.map[mv.particle].y));
        update_map(
            &mut self.map,
            mv.particle,
            &path,
            &done.images,
            &self.tip,
            self.noise_rms,
        );
        self.failures.resize(self.map.len(), 0);
        if done.failed {
            self.failures[mv.particle] += 1;
            if self.failures[mv.particle] >= 2 {
                self.constraints.excluded.push((
                    mv.particle,
                    format!(
                        "the pushes of the particle that could fill it failed twice: {}",
                        done.record.outcome
                    ),
                ));
            }
        }
        let mut filled = None;
        if let Purpose::Fill { site } = mv.purpose {
            self.sent[site] = done.record.particle;
            if done.record.outcome == "ok" {
                filled = Some(site);
            } else {
                self.tries[site] += 1;
                // A miss without a push: the particle lies nearer its site than a push can
                // correct, and sending it again would only scan it again.
                let unpushable = done.record.pushes == 0 && done.record.outcome == "missed";
                if unpushable {
                    let why = format!(
                        "missed: the particle lies {} from it, nearer than a push can correct, outside its {:.1} nm tolerance",
                        done.record
                            .error
                            .map_or("too near".to_string(), |e| format!("{:.1} nm", e * 1e9)),
                        self.tolerance_of(mv.purpose) * 1e9
                    );
                    self.constraints.closed.push((site, Unfilled::Missed(why)));
                } else if self.tries[site] >= self.options.tries_per_site {
                    let why = format!(
                        "missed after {} moves; the last: {}{}",
                        self.tries[site],
                        done.record.outcome,
                        done.record
                            .error
                            .map_or(String::new(), |e| format!(", {:.1} nm from it", e * 1e9))
                    );
                    self.constraints.closed.push((site, Unfilled::Missed(why)));
                }
            }
        }
        self.moves.push(done.record);
        if done.absent && !self.constraints.unfound.contains(&mv.particle) {
            self.constraints.unfound.push(mv.particle);
        }
        self.replan();
        filled
    }

    fn replan(&mut self) {
        self.plan = plan(&self.map, &self.pattern, &self.settings, &self.constraints);
    }

    /// Each site by the particles of the last full frame: `filled` when one lies within its
    /// tolerance, else why not; `truth` names the particle nearest a point and where it truly is.
    pub fn judge(&self, last: &[Seen], truth: &dyn Fn((f64, f64)) -> Option<TrueParticle>) -> Vec<SiteReport> {
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
                let real = measured.and_then(truth);
                let (status, reason) = if filled.is_some() {
                    ("filled", None)
                } else {
                    match self.plan.sites.get(i) {
                        Some(SiteState::Open(u)) => (u.status(), Some(u.reason())),
                        // Planned, but the assembly ended (a stop) before a particle was sent.
                        _ if self.sent[i].is_none() => (
                            "missed",
                            Some("never tried: the assembly ended before its move".to_string()),
                        ),
                        _ => (
                            "missed",
                            Some(format!(
                                "no particle within its {:.1} nm tolerance in the last full frame",
                                tolerance * 1e9
                            )),
                        ),
                    }
                };
                // A particle far from the site is not its: the columns stay empty.
                let near =
                    filled.is_some() || on.is_some_and(|(_, d)| d < 4.0 * self.settings.clearance.max(tolerance));
                SiteReport {
                    target: (s.x, s.y),
                    tolerance,
                    particle: if filled.is_some() {
                        real.map(|t| t.id)
                    } else {
                        self.sent[i]
                    },
                    measured: measured.filter(|_| near),
                    true_position: real.filter(|_| near).map(|t| t.at),
                    error: real.filter(|_| near).map(|t| (t.at.0 - s.x).hypot(t.at.1 - s.y)),
                    status,
                    reason,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
