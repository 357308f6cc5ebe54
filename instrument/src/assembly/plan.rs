//! The assembly's plan from what the scans show: which particle fills which site
//! ([`super::assign`]), in which order, and by which legs ([`Router`]), so that no push crosses
//! a particle already placed or one still to move.
//!
//! The plan is played out on the positions as it goes: each move's route avoids every other
//! particle where it will be by then. The order:
//! 1. Sites a particle already fills (within the site's tolerance, of the pattern's size) keep it.
//! 2. The open sites are filled from the pattern's centre outward, so that the outer sites, filled
//!    last, do not wall in the inner ones; of the fills whose site is free and whose route is
//!    clear, the most central goes first.
//! 3. When none can go: a particle the pattern does not need that sits on an open site, or in
//!    the way of a fill's route, is moved out of the pattern (cleared); a particle to move that
//!    sits on another's site is parked out of the way first; and when nothing can move, the
//!    fills left are reported unreachable with the router's reason.
//! 4. Last, every particle the pattern does not need that lies within the clearance of a site
//!    is cleared.
//!
//! A cleared or parked particle goes to the nearest free spot outside the pattern (clear of
//! every site and every other particle by the clearance) that it has a route to.

use super::assign::assign;
use super::pattern::{Pattern, RADIUS_MATCH};
use crate::control::route::{Leg, Obstacle, RouteError, Router, on_stage};
use crate::scene::Scene;

/// A particle as the scans show it (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub radius: f64,
}

impl Seen {
    /// The particles a scan shows, as `find_particles` finds them.
    pub fn found_in(img: &crate::scan::HeightImage, tip: &crate::scan::Tip) -> Vec<Seen> {
        crate::scan::find_particles(img, tip)
            .iter()
            .map(|l| Seen {
                x: l.x,
                y: l.y,
                radius: l.radius,
            })
            .collect()
    }
}

/// What the plan routes with (m), from the scene's strategy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanSettings {
    /// A site's tolerance when it gives none.
    pub tolerance: f64,
    /// Kept between a pushed particle and every other.
    pub clearance: f64,
    /// The longest single push.
    pub max_push: f64,
    /// The contact search's run-up behind a particle, less its diameter
    /// (`strategy.approach_distance_um`).
    pub approach: f64,
    /// The tip's radius.
    pub tip_radius: f64,
    /// The stage's travel in x and y.
    pub range: f64,
}

impl PlanSettings {
    /// The settings of `scene`'s strategy, with `tolerance` for sites that give none.
    pub fn from_scene(scene: &Scene, tolerance: f64) -> PlanSettings {
        let st = &scene.file.strategy;
        PlanSettings {
            tolerance,
            clearance: st.clearance_um * 1e-6,
            max_push: st.max_push_um * 1e-6,
            approach: st.approach_distance_um * 1e-6,
            tip_radius: scene.file.tip.radius_nm * 1e-9,
            range: scene.file.stage.range_um * 1e-6,
        }
    }

    /// The router for a particle of radius `r`, as `nanopush push` routes one.
    pub fn router(&self, r: f64) -> Router {
        Router {
            radius: r,
            edge_radius: r,
            max_push: self.max_push,
            clearance: self.clearance,
            run_up: self.approach + 2.0 * r,
            tip_radius: self.tip_radius,
            range: self.range,
        }
    }
}

/// Why a move is made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// To fill a site (its index).
    Fill {
        /// The site.
        site: usize,
    },
    /// A particle the pattern does not need, out of a site's way or a route's.
    Clear,
    /// A particle to place later, out of another's way for now.
    Park,
}

/// One move of the plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedMove {
    /// The particle (index in the plan's particles).
    pub particle: usize,
    /// Where it is (m).
    pub from: (f64, f64),
    /// Where it goes (m).
    pub to: (f64, f64),
    /// Why.
    pub purpose: Purpose,
    /// The straight pushes that take it there.
    pub legs: Vec<Leg>,
}

/// Why a site is left open.
#[derive(Debug, Clone, PartialEq)]
pub enum Unfilled {
    /// No particle of the pattern's size is left for it.
    NoParticle,
    /// No route reaches it.
    Unreachable(String),
    /// The strategy refuses to push the particles that could fill it.
    Refused(String),
    /// It was tried and missed, as often as the assembly allows.
    Missed(String),
}

impl Unfilled {
    /// `unreachable` for the first two, `refused` or `missed`: the summary's status.
    pub fn status(&self) -> &'static str {
        match self {
            Unfilled::NoParticle | Unfilled::Unreachable(_) => "unreachable",
            Unfilled::Refused(_) => "refused",
            Unfilled::Missed(_) => "missed",
        }
    }

    /// The reason in words.
    pub fn reason(&self) -> String {
        match self {
            Unfilled::NoParticle => "no particle of the pattern's size is left for it".into(),
            Unfilled::Unreachable(why) | Unfilled::Refused(why) | Unfilled::Missed(why) => why.clone(),
        }
    }
}

/// What the plan says of a site.
#[derive(Debug, Clone, PartialEq)]
pub enum SiteState {
    /// A particle fills it already.
    Filled {
        /// The particle.
        particle: usize,
    },
    /// A move of the plan fills it.
    Planned {
        /// The particle sent.
        particle: usize,
    },
    /// It stays open.
    Open(Unfilled),
}

/// An assembly's plan.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Each site's state, in the pattern's order.
    pub sites: Vec<SiteState>,
    /// The moves, in order.
    pub moves: Vec<PlannedMove>,
}

impl Plan {
    /// Sites the plan fills or finds filled.
    pub fn fillable(&self) -> usize {
        self.sites.iter().filter(|s| !matches!(s, SiteState::Open(_))).count()
    }
}

/// What the plan must not use: particles that failed, and sites given up (with why).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Constraints {
    /// Particles not to send (their pushes failed, or the strategy refuses them).
    pub excluded: Vec<(usize, String)>,
    /// Sites given up, and why.
    pub closed: Vec<(usize, Unfilled)>,
    /// Particles the scan before their move did not find where the map has them: never sent
    /// again (to a site or aside), and still kept clear of, since a scan can miss a particle
    /// that is there (a window crowded with particles levels above them).
    pub unfound: Vec<usize>,
}

/// A pattern the scene cannot hold: a site off the stage, or two sites closer than two particles
/// and the clearance.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct PatternUnfit(pub String);

/// The radius the pattern's sites are checked with: the pattern's own, else the particles'
/// largest.
pub fn site_radius(pattern: &Pattern, particles: &[Seen]) -> f64 {
    pattern
        .radius
        .unwrap_or_else(|| particles.iter().map(|p| p.radius).fold(0.0, f64::max))
}

/// Whether the pattern fits the stage: each site keeps a particle of `r` on it whole, and any two
/// sites are at least `2r` plus the clearance apart (a particle is never pushed closer to
/// another).
pub fn check_fit(pattern: &Pattern, r: f64, settings: &PlanSettings) -> Result<(), PatternUnfit> {
    for (i, s) in pattern.sites.iter().enumerate() {
        if !on_stage((s.x, s.y), r, settings.range) {
            let (lo, hi) = crate::control::route::centre_bounds_um(r, settings.range);
            return Err(PatternUnfit(format!(
                "site {i} at ({:.3}, {:.3}) µm is off the stage for a particle {:.3} µm in radius; allowed: [{lo:.3}, {hi:.3}] µm in x and y",
                s.x * 1e6,
                s.y * 1e6,
                r * 1e6
            )));
        }
    }
    let least = 2.0 * r + settings.clearance;
    for i in 0..pattern.sites.len() {
        for j in 0..i {
            let (a, b) = (pattern.sites[i], pattern.sites[j]);
            let d = (a.x - b.x).hypot(a.y - b.y);
            if d < least {
                return Err(PatternUnfit(format!(
                    "sites {j} and {i} are {:.3} µm apart; allowed: at least two particle radii plus the clearance, {:.3} µm",
                    d * 1e6,
                    least * 1e6
                )));
            }
        }
    }
    Ok(())
}

/// The plan that fills `pattern` with `particles` (as the scans show them), given what must not
/// be used.
pub fn plan(particles: &[Seen], pattern: &Pattern, settings: &PlanSettings, constraints: &Constraints) -> Plan {
    Planner::new(particles, pattern, settings, constraints).run()
}

/// The plan as it is played out.
struct Planner<'a> {
    pattern: &'a Pattern,
    settings: &'a PlanSettings,
    /// Where each particle is as the plan goes.
    at: Vec<(f64, f64)>,
    radius: Vec<f64>,
    /// Particles the plan may send.
    usable: Vec<bool>,
    /// Particles that fill their site and stay.
    placed: Vec<bool>,
    /// Particles cleared or parked once already (each at most once, so the plan ends).
    moved_aside: Vec<bool>,
    sites: Vec<SiteState>,
    /// Fills to make: (particle, site).
    pending: Vec<(usize, usize)>,
    moves: Vec<PlannedMove>,
    /// The pattern's centre and the radius of a circle around it that parked particles stay
    /// out of.
    centre: (f64, f64),
    keep_out: f64,
    /// The radius sites are kept clear by.
    site_r: f64,
}

impl<'a> Planner<'a> {
    fn new(
        particles: &[Seen],
        pattern: &'a Pattern,
        settings: &'a PlanSettings,
        constraints: &Constraints,
    ) -> Planner<'a> {
        let n = particles.len();
        let fits = |p: &Seen| {
            pattern
                .radius
                .is_none_or(|r| p.radius <= r * RADIUS_MATCH && p.radius >= r / RADIUS_MATCH)
        };
        let mut usable: Vec<bool> = particles.iter().map(fits).collect();
        for (k, _) in &constraints.excluded {
            if *k < n {
                usable[*k] = false;
            }
        }
        let mut moved_aside = vec![false; n];
        for &k in &constraints.unfound {
            if k < n {
                usable[k] = false;
                moved_aside[k] = true;
            }
        }
        let site_r = site_radius(pattern, particles);
        let centre = pattern.centre();
        let reach = pattern
            .sites
            .iter()
            .map(|s| (s.x - centre.0).hypot(s.y - centre.1))
            .fold(0.0, f64::max);
        let mut p = Planner {
            pattern,
            settings,
            at: particles.iter().map(|p| (p.x, p.y)).collect(),
            radius: particles.iter().map(|p| p.radius).collect(),
            usable,
            placed: vec![false; n],
            moved_aside,
            sites: vec![SiteState::Open(Unfilled::NoParticle); pattern.sites.len()],
            pending: Vec::new(),
            moves: Vec::new(),
            centre,
            keep_out: reach + 2.0 * site_r + settings.clearance,
            site_r,
        };
        let mut closed = vec![false; pattern.sites.len()];
        for (s, why) in &constraints.closed {
            if *s < closed.len() {
                closed[*s] = true;
                p.sites[*s] = SiteState::Open(why.clone());
            }
        }
        // A site given up after its misses keeps the particle that missed it (the nearest one
        // within the clearance): it is the best that site will get, and neither sent elsewhere
        // nor cleared off it.
        for (s, why) in &constraints.closed {
            let (Some(site), Unfilled::Missed(_)) = (pattern.sites.get(*s), why) else {
                continue;
            };
            let on = (0..n)
                .filter(|&k| p.usable[k] && !p.placed[k])
                .map(|k| (k, (p.at[k].0 - site.x).hypot(p.at[k].1 - site.y)))
                .filter(|&(k, d)| d < p.radius[k] + site_r + settings.clearance)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((k, _)) = on {
                p.placed[k] = true;
            }
        }
        // Sites filled already keep their particle (the nearest one within the tolerance).
        for (s, site) in pattern.sites.iter().enumerate() {
            if closed[s] {
                continue;
            }
            let tol = site.tolerance.unwrap_or(settings.tolerance);
            let on = (0..n)
                .filter(|&k| p.usable[k] && !p.placed[k])
                .map(|k| (k, (p.at[k].0 - site.x).hypot(p.at[k].1 - site.y)))
                .filter(|&(_, d)| d <= tol)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((k, _)) = on {
                p.placed[k] = true;
                p.sites[s] = SiteState::Filled { particle: k };
                closed[s] = true;
            }
        }
        // The rest are matched against the particles free to move.
        let open: Vec<usize> = (0..pattern.sites.len()).filter(|&s| !closed[s]).collect();
        let free: Vec<usize> = (0..n).filter(|&k| p.usable[k] && !p.placed[k]).collect();
        let site_xy: Vec<(f64, f64)> = open.iter().map(|&s| (pattern.sites[s].x, pattern.sites[s].y)).collect();
        let free_xy: Vec<(f64, f64)> = free.iter().map(|&k| p.at[k]).collect();
        for (i, a) in assign(&site_xy, &free_xy, |_, _| true).into_iter().enumerate() {
            if let Some(j) = a {
                p.pending.push((free[j], open[i]));
            }
        }
        // A site left without a particle where the excluded ones of its size would have been
        // enough says why they were excluded.
        let excluded_fit: Vec<&String> = constraints
            .excluded
            .iter()
            .filter(|(k, _)| particles.get(*k).is_some_and(fits))
            .map(|(_, why)| why)
            .collect();
        if free.len() < open.len() && free.len() + excluded_fit.len() >= open.len() {
            for &s in &open {
                if !p.pending.iter().any(|&(_, t)| t == s) {
                    p.sites[s] = SiteState::Open(Unfilled::Refused(excluded_fit[0].clone()));
                }
            }
        }
        p
    }

    fn run(mut self) -> Plan {
        let rounds = 4 * (self.at.len() + self.pattern.sites.len()) + 8;
        for _ in 0..rounds {
            if self.pending.is_empty() || !self.step() {
                break;
            }
        }
        // What could not go: unreachable, with the router's reason.
        for (k, s) in std::mem::take(&mut self.pending) {
            let why = match self.route(k, (self.pattern.sites[s].x, self.pattern.sites[s].y), &[k]) {
                Err(e) => e.to_string(),
                Ok(_) => "its site stays taken by a particle that cannot be moved aside".into(),
            };
            self.sites[s] = SiteState::Open(Unfilled::Unreachable(why));
        }
        self.clear_sites();
        Plan {
            sites: self.sites,
            moves: self.moves,
        }
    }

    /// One move of the plan; false when none can be made.
    fn step(&mut self) -> bool {
        // The fills whose sites are free: those whose particle is still inside the pattern's
        // circle first (filled later, they can be walled in by the sites around them), then the
        // most central.
        let mut order: Vec<usize> = (0..self.pending.len()).collect();
        let inside = |i: usize| {
            let k = self.pending[i].0;
            let (x, y) = self.at[k];
            (x - self.centre.0).hypot(y - self.centre.1) < self.keep_out
        };
        order.sort_by(|&a, &b| {
            let d = |i: usize| {
                let s = self.pattern.sites[self.pending[i].1];
                (s.x - self.centre.0).hypot(s.y - self.centre.1)
            };
            inside(b).cmp(&inside(a)).then(d(a).total_cmp(&d(b)))
        });
        let mut blocked_by: Vec<usize> = Vec::new();
        for &i in &order {
            let (k, s) = self.pending[i];
            let site = (self.pattern.sites[s].x, self.pattern.sites[s].y);
            if let Some(q) = self.occupant(site, k) {
                blocked_by.push(q);
                continue;
            }
            match self.route(k, site, &[k]) {
                Ok(legs) => {
                    self.commit(k, site, Purpose::Fill { site: s }, legs);
                    self.placed[k] = true;
                    self.sites[s] = SiteState::Planned { particle: k };
                    self.pending.remove(i);
                    return true;
                }
                Err(RouteError::Blocked { blocker, .. }) => {
                    if let Some(q) = self.particle_at(blocker) {
                        blocked_by.push(q);
                    }
                }
                Err(_) => {}
            }
        }
        // Nothing could go: move aside a particle in the way, one not needed first.
        let needed: Vec<bool> = blocked_by
            .iter()
            .map(|&q| self.pending.iter().any(|&(k, _)| k == q))
            .collect();
        let mut ways: Vec<(usize, bool)> = blocked_by.into_iter().zip(needed).collect();
        ways.sort_by_key(|w| w.1);
        for (q, needed) in ways {
            if self.placed[q] || self.moved_aside[q] {
                continue;
            }
            let purpose = if needed { Purpose::Park } else { Purpose::Clear };
            if self.move_aside(q, purpose) {
                return true;
            }
        }
        false
    }

    /// A particle other than `k` within the clearance of a particle of `k`'s size at `site`.
    fn occupant(&self, site: (f64, f64), k: usize) -> Option<usize> {
        (0..self.at.len()).find(|&q| {
            q != k
                && (self.at[q].0 - site.0).hypot(self.at[q].1 - site.1)
                    < self.radius[q] + self.radius[k] + self.settings.clearance
        })
    }

    /// The particle centred at `p` (a router's blocker).
    fn particle_at(&self, p: (f64, f64)) -> Option<usize> {
        (0..self.at.len()).find(|&q| (self.at[q].0 - p.0).hypot(self.at[q].1 - p.1) < 1e-12)
    }

    /// The legs that take particle `k` to `to` around every particle but those in `skip`, where
    /// they are as the plan goes.
    fn route(&self, k: usize, to: (f64, f64), skip: &[usize]) -> Result<Vec<Leg>, RouteError> {
        let obstacles: Vec<Obstacle> = (0..self.at.len())
            .filter(|q| !skip.contains(q))
            .map(|q| Obstacle {
                x: self.at[q].0,
                y: self.at[q].1,
                radius: self.radius[q],
            })
            .collect();
        self.settings.router(self.radius[k]).route(self.at[k], to, &obstacles)
    }

    fn commit(&mut self, k: usize, to: (f64, f64), purpose: Purpose, legs: Vec<Leg>) {
        self.moves.push(PlannedMove {
            particle: k,
            from: self.at[k],
            to,
            purpose,
            legs,
        });
        self.at[k] = to;
    }

    /// Moves particle `q` to the nearest free spot outside the pattern it has a route to; false
    /// when there is none.
    fn move_aside(&mut self, q: usize, purpose: Purpose) -> bool {
        self.moved_aside[q] = true;
        for spot in self.spots(q) {
            if let Ok(legs) = self.route(q, spot, &[q]) {
                self.commit(q, spot, purpose, legs);
                return true;
            }
        }
        false
    }

    /// Free spots for particle `q`, nearest first: on rings around it, on the stage, outside
    /// the pattern's circle, clear of every site and every other particle.
    fn spots(&self, q: usize) -> Vec<(f64, f64)> {
        let (r, c) = (self.radius[q], self.settings.clearance);
        let from = self.at[q];
        let step = 2.0 * r + c;
        let mut out = Vec::new();
        for ring in 1..=60 {
            let rho = ring as f64 * step;
            let n = (8 * ring).min(64);
            for k in 0..n {
                let a = std::f64::consts::TAU * k as f64 / n as f64;
                let p = (from.0 + rho * a.cos(), from.1 + rho * a.sin());
                if self.free_spot(q, p) {
                    out.push(p);
                }
            }
            if out.len() >= 12 {
                break;
            }
        }
        out.sort_by(|a, b| {
            let d = |p: &(f64, f64)| (p.0 - from.0).hypot(p.1 - from.1);
            d(a).total_cmp(&d(b))
        });
        out
    }

    fn free_spot(&self, q: usize, p: (f64, f64)) -> bool {
        let (r, c) = (self.radius[q], self.settings.clearance);
        on_stage(p, r, self.settings.range)
            && (p.0 - self.centre.0).hypot(p.1 - self.centre.1) > self.keep_out + r
            && self
                .pattern
                .sites
                .iter()
                .all(|s| (s.x - p.0).hypot(s.y - p.1) >= r + self.site_r + 2.0 * c)
            && (0..self.at.len())
                .all(|o| o == q || (self.at[o].0 - p.0).hypot(self.at[o].1 - p.1) >= r + self.radius[o] + 2.0 * c)
    }

    /// Every particle the pattern does not need that lies within the clearance of a site is
    /// cleared (when it has somewhere to go).
    fn clear_sites(&mut self) {
        let filling: Vec<usize> = self
            .sites
            .iter()
            .filter_map(|s| match s {
                SiteState::Filled { particle } | SiteState::Planned { particle } => Some(*particle),
                SiteState::Open(_) => None,
            })
            .collect();
        for q in 0..self.at.len() {
            if filling.contains(&q) || self.placed[q] {
                continue;
            }
            let near = self.pattern.sites.iter().any(|s| {
                (s.x - self.at[q].0).hypot(s.y - self.at[q].1) < self.radius[q] + self.site_r + self.settings.clearance
            });
            if near && !self.moved_aside[q] {
                self.move_aside(q, Purpose::Clear);
            }
        }
    }
}

#[cfg(test)]
mod tests;
