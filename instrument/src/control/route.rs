//! 2-D positioning (the paper's goal) with straight pushes: a target one push cannot reach gets
//! a route of several. A leg is never longer than the longest single push, and a leg's swept
//! corridor (the particle's width plus the clearance, plus the tip's approach run behind it) must
//! not touch another particle; when the straight line is blocked the route goes around the
//! blocking particle through one side-step waypoint.

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
    /// Neither the straight line nor a detour around the blocking particle is clear.
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
    /// Stage range `[0, range]` in x and y.
    pub range: f64,
}

impl Router {
    /// The first obstacle whose distance to the swept segment (extended backwards by the
    /// run-up, where the tip travels at parking height) is below the two radii plus clearance.
    fn blocker(&self, from: (f64, f64), to: (f64, f64), obstacles: &[Obstacle]) -> Option<Obstacle> {
        let leg = Leg { from, to };
        let d = leg.direction();
        let start = (from.0 - d.0 * self.run_up, from.1 - d.1 * self.run_up);
        let len = leg.length() + self.run_up;
        obstacles.iter().copied().find(|o| {
            let (rx, ry) = (o.x - start.0, o.y - start.1);
            let s = (rx * d.0 + ry * d.1).clamp(0.0, len);
            let dist = (rx - s * d.0).hypot(ry - s * d.1);
            dist < self.radius + o.radius + self.clearance
        })
    }

    /// Splits a clear segment into equal legs no longer than the longest push.
    fn split(&self, from: (f64, f64), to: (f64, f64), out: &mut Vec<Leg>) {
        let len = (to.0 - from.0).hypot(to.1 - from.1);
        let n = (len / self.max_push).ceil().max(1.0) as usize;
        for k in 0..n {
            let a = k as f64 / n as f64;
            let b = (k + 1) as f64 / n as f64;
            out.push(Leg {
                from: (from.0 + a * (to.0 - from.0), from.1 + a * (to.1 - from.1)),
                to: (from.0 + b * (to.0 - from.0), from.1 + b * (to.1 - from.1)),
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
        Err(RouteError::Blocked {
            from,
            to,
            blocker: (b.x, b.y),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const UM: f64 = 1e-6;

    fn router() -> Router {
        Router {
            radius: 0.5 * UM,
            edge_radius: 0.5 * UM,
            max_push: 12.0 * UM,
            clearance: 0.5 * UM,
            run_up: 5.0 * UM,
            range: 100.0 * UM,
        }
    }

    fn clear_of(legs: &[Leg], o: &Obstacle, p: &Router) -> bool {
        legs.iter().all(|l| p.blocker(l.from, l.to, &[*o]).is_none())
    }

    #[test]
    fn a_short_clear_move_is_one_leg() {
        let legs = router()
            .route((40.0 * UM, 30.0 * UM), (45.0 * UM, 30.0 * UM), &[])
            .unwrap();
        assert_eq!(legs.len(), 1);
        assert!((legs[0].length() - 5.0 * UM).abs() < 1e-12);
    }

    #[test]
    fn a_long_move_is_split_into_equal_legs_within_the_longest_push() {
        let p = router();
        let legs = p.route((10.0 * UM, 10.0 * UM), (40.0 * UM, 50.0 * UM), &[]).unwrap();
        // 50 µm in legs of at most 12 µm: 5 legs of 10 µm, end to end.
        assert_eq!(legs.len(), 5);
        for w in legs.windows(2) {
            assert_eq!(w[0].to, w[1].from);
        }
        assert!(legs.iter().all(|l| (l.length() - 10.0 * UM).abs() < 1e-9));
        assert_eq!(legs.last().unwrap().to, (40.0 * UM, 50.0 * UM));
    }

    #[test]
    fn a_blocked_line_goes_around_the_blocker() {
        let p = router();
        let o = Obstacle {
            x: 50.0 * UM,
            y: 30.2 * UM,
            radius: 0.5 * UM,
        };
        let (from, to) = ((40.0 * UM, 30.0 * UM), (60.0 * UM, 30.0 * UM));
        assert!(p.blocker(from, to, &[o]).is_some());
        let legs = p.route(from, to, &[o]).unwrap();
        assert!(legs.len() >= 2);
        assert!(clear_of(&legs, &o, &p));
        assert_eq!(legs.first().unwrap().from, from);
        assert_eq!(legs.last().unwrap().to, to);
    }

    /// A push to 99.9 µm of a 1 µm particle would take its centre to 100.88 µm (the push goes
    /// 0.977 µm further for the retraction's drag). The target must keep the particle
    /// on the stage whole; the push's overshoot is cut where it would leave it; a push the tip
    /// cannot get behind is refused.
    #[test]
    fn the_whole_way_stays_on_the_stage_target_overshoot_and_the_tips_reach() {
        let p = Router {
            radius: 1.0 * UM,
            edge_radius: 1.0 * UM,
            ..router()
        };
        let e = p
            .route((59.9 * UM, 50.0 * UM), (99.9 * UM, 50.0 * UM), &[])
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "target (99.90, 50.00) µm is outside the stage for a particle 1.000 µm in radius; allowed: [1.000, 99.000] µm in x and y"
        );
        assert!(p.route((59.0 * UM, 50.0 * UM), (99.0 * UM, 50.0 * UM), &[]).is_ok());
        // The push's overshoot stops where the particle would leave the stage: 0.5 µm left of
        // the 0.977 µm, along x; along y nothing; diagonally, the nearer edge.
        let r = 1.0 * UM;
        assert!((travel_on_stage((98.5 * UM, 50.0 * UM), (1.0, 0.0), r, 100.0 * UM) - 0.5 * UM).abs() < 1e-12);
        assert!((travel_on_stage((98.5 * UM, 50.0 * UM), (-1.0, 0.0), r, 100.0 * UM) - 97.5 * UM).abs() < 1e-12);
        let diag = (0.6, 0.8);
        assert!((travel_on_stage((90.0 * UM, 95.0 * UM), diag, r, 100.0 * UM) - 5.0 * UM).abs() < 1e-12);
        assert_eq!(travel_on_stage((99.5 * UM, 50.0 * UM), (1.0, 0.0), r, 100.0 * UM), 0.0);
        // Pushed toward −x from 99.5 µm: the tip would have to be at 100.53 µm.
        let leg = |from: f64, to: f64| Leg {
            from: (from * UM, 50.0 * UM),
            to: (to * UM, 50.0 * UM),
        };
        let e = check_reach(&[leg(40.0, 41.0), leg(99.5, 90.0)], 1.03 * UM, 100.0 * UM).unwrap_err();
        assert!(
            e.to_string().starts_with(
                "push 2 would need the tip at (100.530, 50.000) µm, off the stage: allowed [0.000, 100.000] µm"
            ),
            "{e}"
        );
        assert_eq!(check_reach(&[leg(98.97, 90.0)], 1.03 * UM, 100.0 * UM), Ok(()));
    }

    #[test]
    fn targets_outside_the_stage_and_walled_in_paths_are_refused() {
        let p = router();
        let e = p
            .route((40.0 * UM, 30.0 * UM), (140.0 * UM, 30.0 * UM), &[])
            .unwrap_err();
        assert!(e.to_string().contains("allowed: [0.500, 99.500] µm in x and y"), "{e}");
        // A wall of particles across the whole path, 3 µm apart.
        let wall: Vec<Obstacle> = (0..=33)
            .map(|k| Obstacle {
                x: 50.0 * UM,
                y: k as f64 * 3.0 * UM,
                radius: 0.5 * UM,
            })
            .collect();
        let e = p
            .route((40.0 * UM, 30.0 * UM), (60.0 * UM, 30.0 * UM), &wall)
            .unwrap_err();
        assert!(matches!(e, RouteError::Blocked { .. }), "{e}");
    }
}
