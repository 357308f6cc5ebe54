//! 2-D positioning (the paper's goal) with straight pushes: a target one push cannot reach gets
//! a route of several. A leg is never longer than the longest single push, and a leg's swept
//! corridor (the particle's width plus the clearance, plus the tip's approach run behind it) must
//! not touch another particle. When the straight line is blocked the route goes around the
//! blocking particle through one side-step waypoint; when that is blocked too, it is the
//! cheapest route a visibility graph over all the particles holds ([`search`]).

mod search;

/// A particle the route must keep clear of (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub radius: f64,
}

/// One straight push of a route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    /// Where the particle starts (m).
    pub from: (f64, f64),
    /// Where it should end (m).
    pub to: (f64, f64),
}

impl Leg {
    /// Length (m).
    pub fn length(&self) -> f64 {
        (self.to.0 - self.from.0).hypot(self.to.1 - self.from.1)
    }

    /// Unit direction (`(1, 0)` for a zero-length leg).
    pub fn direction(&self) -> (f64, f64) {
        let l = self.length();
        if l == 0.0 {
            (1.0, 0.0)
        } else {
            ((self.to.0 - self.from.0) / l, (self.to.1 - self.from.1) / l)
        }
    }
}

/// Why no route exists.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RouteError {
    /// No route around the particles is clear: the straight line is blocked, and no detour.
    #[error(
        "no clear path from ({:.2}, {:.2}) µm to ({:.2}, {:.2}) µm: blocked by the particle at ({:.2}, {:.2}) µm",
        .from.0 * 1e6, .from.1 * 1e6, .to.0 * 1e6, .to.1 * 1e6, .blocker.0 * 1e6, .blocker.1 * 1e6
    )]
    Blocked {
        /// Start (m).
        from: (f64, f64),
        /// Target (m).
        to: (f64, f64),
        /// The blocking particle's centre (m).
        blocker: (f64, f64),
    },
    /// The target lies outside the stage range, less the particle's radius at each end: the
    /// particle must lie on the stage whole, and the tip (which stays on it) must reach behind
    /// it (as the server's `push` check states it).
    #[error(
        "target ({:.2}, {:.2}) µm is outside the stage for a particle {:.3} µm in radius; allowed: [{:.3}, {:.3}] µm in x and y",
        .to.0 * 1e6, .to.1 * 1e6, .radius * 1e6, centre_bounds_um(*.radius, *.range).0, centre_bounds_um(*.radius, *.range).1
    )]
    OutOfRange {
        /// The target (m).
        to: (f64, f64),
        /// The particle's radius (m).
        radius: f64,
        /// The stage's travel (m).
        range: f64,
    },
    /// On the way, a push would need the tip off the stage.
    #[error(
        "{what} ({:.3}, {:.3}) µm, off the stage: allowed [{:.3}, {:.3}] µm in x and y{why}",
        .at.0 * 1e6, .at.1 * 1e6, .lo * 1e6, .hi * 1e6
    )]
    OffStage {
        /// What would go there.
        what: String,
        /// Where (m).
        at: (f64, f64),
        /// The allowed range in x and y (m).
        lo: f64,
        /// Its upper end (m).
        hi: f64,
        /// Why it goes there, in words (starting with `: `), or empty.
        why: String,
    },
}

/// Checks the whole way of `legs`, not only their ends: at the start of each push the tip must
/// reach the particle's back, `behind` (`Rₐ + Rₜ`) behind its centre, inside the stage's
/// `[0, range]` (the contact search's run-up further back may be clamped to the stage: the
/// search then starts closer). The push's overshoot past a leg's end (the retraction's drag made
/// up for) is kept on the stage by the push itself ([`crate::control::PushTask::max_travel`]).
pub fn check_reach(legs: &[Leg], behind: f64, range: f64) -> Result<(), RouteError> {
    let on = |p: (f64, f64)| [p.0, p.1].iter().all(|v| (0.0..=range).contains(v));
    for (k, leg) in legs.iter().enumerate() {
        let d = leg.direction();
        let back = (leg.from.0 - d.0 * behind, leg.from.1 - d.1 * behind);
        if !on(back) {
            return Err(RouteError::OffStage {
                what: format!("push {} would need the tip at", k + 1),
                at: back,
                lo: 0.0,
                hi: range,
                why: format!(": behind the particle, {:.3} µm from its centre", behind * 1e6),
            });
        }
    }
    Ok(())
}

/// Where the centre of a particle of radius `r` (m) may lie on a stage of travel `range` (m):
/// `[r, range − r]`, in µm rounded inward to the nanometre, as messages print them (three
/// decimals), so that a value on a printed bound is inside.
pub fn centre_bounds_um(r: f64, range: f64) -> (f64, f64) {
    let (r, range) = (um(r), um(range));
    ((r * 1e3).ceil() / 1e3, ((range - r) * 1e3).floor() / 1e3)
}

/// A length in µm, rounded to the picometre.
fn um(v: f64) -> f64 {
    (v * 1e12).round() / 1e6
}

/// Whether a particle of radius `r` centred at `p` lies on the stage whole (m), checked in µm
/// against [`centre_bounds_um`] (in metres, a target exactly on a printed bound was refused:
/// 500 nm × 1e-9 is a hair above 0.5 µm × 1e-6).
pub fn on_stage(p: (f64, f64), r: f64, range: f64) -> bool {
    let (lo, hi) = centre_bounds_um(r, range);
    [p.0, p.1].iter().all(|&v| um(v) >= lo && um(v) <= hi)
}

/// How far a particle at `from` (m) may be pushed along the unit direction `d` and still lie on
/// a stage of travel `range` whole, its centre in `[r, range − r]` (m): where the ray leaves
/// that square (`+∞` along an axis it does not move on; 0 when it starts outside).
pub fn travel_on_stage(from: (f64, f64), d: (f64, f64), r: f64, range: f64) -> f64 {
    let (lo, hi) = (r, range - r);
    let axis = |p: f64, v: f64| {
        if v > 0.0 {
            (hi - p) / v
        } else if v < 0.0 {
            (lo - p) / v
        } else {
            f64::INFINITY
        }
    };
    axis(from.0, d.0).min(axis(from.1, d.1)).max(0.0)
}

/// The router's settings (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Router {
    /// Radius of the pushed particle.
    pub radius: f64,
    /// Its radius as the move's target was checked against (the scene's, which the server's
    /// `push` check states): the target and the waypoints keep the particle on the stage by it.
    /// The located radius differs by a fraction of a nanometre, and a target on the stated edge
    /// must not be refused when planned.
    pub edge_radius: f64,
    /// Longest single push.
    pub max_push: f64,
    /// Clearance to keep from other particles.
    pub clearance: f64,
    /// Run-up behind the particle that the tip needs (the contact search's start).
    pub run_up: f64,
    /// Radius of the tip (m): at the start of every push it reaches the particle's back,
    /// `Rₐ + Rₜ` behind its centre, on the stage.
    pub tip_radius: f64,
    /// Stage range `[0, range]` in x and y.
    pub range: f64,
}

impl Router {
    /// The first obstacle whose distance to the swept segment (extended backwards by the
    /// run-up, where the tip travels at parking height) is below the two radii plus clearance.
    ///
    /// A particle that starts closer than that to another (two particles left side by side)
    /// may still move, if it never comes closer to it and the tip's run-up passes it at least
    /// a particle's width away (the tip fits where the particle would): so it can be pushed
    /// along or away from its neighbour, never into it.
    fn blocker(&self, from: (f64, f64), to: (f64, f64), obstacles: &[Obstacle]) -> Option<Obstacle> {
        let leg = Leg { from, to };
        let d = leg.direction();
        let start = (from.0 - d.0 * self.run_up, from.1 - d.1 * self.run_up);
        let len = leg.length() + self.run_up;
        // Distance from `o` to the points at `[a, b]` along the extended segment.
        let dist = |o: &Obstacle, a: f64, b: f64| {
            let (rx, ry) = (o.x - start.0, o.y - start.1);
            let s = (rx * d.0 + ry * d.1).clamp(a, b);
            (rx - s * d.0).hypot(ry - s * d.1)
        };
        obstacles.iter().copied().find(|o| {
            let keep = self.radius + o.radius + self.clearance;
            let at_start = (o.x - from.0).hypot(o.y - from.1);
            if at_start >= keep {
                return dist(o, 0.0, len) < keep;
            }
            dist(o, self.run_up, len) < at_start - 1e-12 || dist(o, 0.0, self.run_up) < self.radius + o.radius
        })
    }

    /// Splits a clear segment into equal legs no longer than the longest push.
    fn split(&self, from: (f64, f64), to: (f64, f64), out: &mut Vec<Leg>) {
        let len = (to.0 - from.0).hypot(to.1 - from.1);
        let n = (len / self.max_push).ceil().max(1.0) as usize;
        // The ends exactly where asked: `from + 1.0 (to − from)` can miss `to` by a rounding.
        let at = |k: usize| {
            if k == n {
                return to;
            }
            let a = k as f64 / n as f64;
            (from.0 + a * (to.0 - from.0), from.1 + a * (to.1 - from.1))
        };
        for k in 0..n {
            out.push(Leg {
                from: at(k),
                to: at(k + 1),
            });
        }
    }

    /// The legs that take a particle from `from` to `to` avoiding `obstacles` (the other
    /// particles).
    pub fn route(&self, from: (f64, f64), to: (f64, f64), obstacles: &[Obstacle]) -> Result<Vec<Leg>, RouteError> {
        let inside = |p: (f64, f64)| on_stage(p, self.edge_radius, self.range);
        if !inside(to) {
            return Err(RouteError::OutOfRange {
                to,
                radius: self.edge_radius,
                range: self.range,
            });
        }
        let mut legs = Vec::new();
        let Some(b) = self.blocker(from, to, obstacles) else {
            self.split(from, to, &mut legs);
            return Ok(legs);
        };
        // Side-step: a waypoint beside the blocker, on the side the line passes, far enough
        // for both legs to clear it; try that side first, then the other.
        let d = Leg { from, to }.direction();
        let normal = (-d.1, d.0);
        let side = ((b.x - from.0) * normal.0 + (b.y - from.1) * normal.1).signum();
        let offset = 2.0 * (self.radius + b.radius + self.clearance);
        for sign in [-side, side] {
            let sign = if sign == 0.0 { 1.0 } else { sign };
            let w = (b.x + sign * normal.0 * offset, b.y + sign * normal.1 * offset);
            if inside(w) && self.blocker(from, w, obstacles).is_none() && self.blocker(w, to, obstacles).is_none() {
                self.split(from, w, &mut legs);
                self.split(w, to, &mut legs);
                return Ok(legs);
            }
        }
        if let Some(way) = self.search(from, to, obstacles) {
            for pair in way.windows(2) {
                self.split(pair[0], pair[1], &mut legs);
            }
            return Ok(legs);
        }
        Err(RouteError::Blocked {
            from,
            to,
            blocker: (b.x, b.y),
        })
    }
}

#[cfg(test)]
mod tests;
