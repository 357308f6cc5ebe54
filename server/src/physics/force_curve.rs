//! The tip-sample force curve of Fig 3: cantilever deflection against piezo distance for an
//! approach and the retraction that follows, with snap-in, adhesion and pull-off hysteresis.
//!
//! The tip (sphere `Rₜ` on a cantilever of stiffness `k_c`) faces the flat substrate. At piezo
//! distance `d` (the gap the tip would have without deflection) the tip sits at a gap
//! `h = d + ζ` where its deflection balances the tip-sample force: `k_c ζ = F(h)`. `F` is the
//! JKR contact (Eq 5, overlap `a₀ − h`) plus the included long-range terms (Eq 2, 3 substrate
//! form with `Rₐ → Rₜ`, 4). The tip follows its equilibrium quasi-statically; when that
//! equilibrium vanishes (a fold: the force gradient exceeds `k_c`) it jumps to the next one in
//! the direction it is moving: snap-in on approach, pull-off on retraction. The meniscus
//! (Eq 3: forms at `L_t`, ruptures at `L_t + δ_b`) and the JKR contact (forms at `a₀`,
//! breaks off its stable branch) keep their state between steps, so the two curves differ.

use crate::physics::contact::jkr::Jkr;
use crate::physics::forces::capillary::Meniscus;
use crate::physics::pushing::params::LongRange;

/// A tip facing a flat sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipSample {
    /// Tip radius (m).
    pub r_t: f64,
    /// Cantilever normal stiffness (N/m).
    pub k_c: f64,
    /// Tip-substrate JKR contact.
    pub jkr: Jkr,
    /// Included long-range terms (sphere-plane forms).
    pub long_range: LongRange,
    /// Interatomic cut-off `a₀` (m).
    pub a0: f64,
}

/// One point of a force curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    /// Piezo distance `d` (m): positive is away from the sample.
    pub distance: f64,
    /// Tip-sample gap `h` (m).
    pub gap: f64,
    /// Deflection `ζ` (m), positive away from the sample.
    pub deflection: f64,
    /// Force on the tip `k_c ζ` (N), positive repulsive.
    pub force: f64,
    /// Meniscus present.
    pub meniscus: bool,
    /// In contact.
    pub contact: bool,
}

/// Both branches of a force curve and what they show.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceCurve {
    /// Approach, from far to the deepest point.
    pub approach: Vec<CurvePoint>,
    /// Retraction, from the deepest point back out.
    pub retraction: Vec<CurvePoint>,
    /// Piezo distance where the tip came into contact on approach (the snap-in jump when the
    /// attraction's gradient exceeds `k_c`) (m).
    pub snap_in_distance: Option<f64>,
    /// Most attractive force on retraction, just before pull-off (N, negative).
    pub pull_off_force: f64,
    /// Piezo distance where the contact broke on retraction (m).
    pub pull_off_distance: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Contact {
    meniscus: Meniscus,
    contact: bool,
}

/// The tip's state over the sample, carried from one piezo position to the next: the force
/// curve's hysteresis (meniscus, contact) lives here.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipTrack {
    state: Contact,
    gap: f64,
}

impl TipTrack {
    /// A tip far from the sample at piezo distance `d` (m): no meniscus, no contact.
    pub fn far(d: f64) -> TipTrack {
        TipTrack {
            state: Contact {
                meniscus: Meniscus::Absent,
                contact: false,
            },
            gap: d,
        }
    }

    /// Whether the tip touches the sample.
    pub fn in_contact(&self) -> bool {
        self.state.contact
    }
}

impl TipSample {
    /// The adhesion of the tip on the substrate at contact (N, positive): the long-range
    /// attraction at the cut-off `a₀` with a formed meniscus plus the JKR pull-off load — the
    /// scale of the pull-off force, in closed form.
    pub fn adhesion(&self) -> f64 {
        -self
            .long_range
            .sphere_plane(self.r_t, self.a0, Meniscus::Formed, self.a0)
            - self.jkr.pull_off_load()
    }

    /// Moves the tip's piezo to distance `d` (m) from where `track` left it and returns the
    /// equilibrium reached: the tip follows its equilibrium quasi-statically and jumps at a
    /// fold (snap-in, pull-off), re-settling until the contact state agrees with the gap.
    pub fn track(&self, track: &mut TipTrack, d: f64) -> CurvePoint {
        for _ in 0..8 {
            let h_new = self.settle(track.state, track.gap, d);
            let s_new = self.state_at(track.state, h_new);
            track.gap = h_new;
            if s_new == track.state {
                break;
            }
            track.state = s_new;
        }
        self.point(track.state, track.gap, d)
    }

    /// The contact state after moving monotonically from state `s` to gap `h`.
    fn state_at(&self, s: Contact, h: f64) -> Contact {
        let meniscus = match &self.long_range.capillary {
            Some(c) => c.update(s.meniscus, h),
            None => Meniscus::Absent,
        };
        let contact = if s.contact {
            (self.a0 - h) >= self.jkr.min_indentation()
        } else {
            h <= self.a0
        };
        Contact { meniscus, contact }
    }

    /// Tip-sample force at gap `h` in state `s` (N, positive repulsive).
    fn force(&self, s: Contact, h: f64) -> f64 {
        let elastic = if s.contact {
            self.jkr.load_from_indentation(self.a0 - h).unwrap_or(0.0)
        } else {
            0.0
        };
        elastic + self.long_range.sphere_plane(self.r_t, h, s.meniscus, self.a0)
    }

    /// Net upward force on the tip at gap `h` for piezo distance `d`, with the state reached by
    /// moving there from `s`.
    fn net(&self, s: Contact, h: f64, d: f64) -> f64 {
        self.force(self.state_at(s, h), h) - self.k_c * (h - d)
    }

    /// The equilibrium gap reached from `h0` at piezo distance `d`: the tip moves the way the
    /// net force pushes it until the first balance (bracketed by doubling steps, then bisected).
    fn settle(&self, s: Contact, h0: f64, d: f64) -> f64 {
        let g0 = self.net(s, h0, d);
        if g0 == 0.0 {
            return h0;
        }
        let dir = g0.signum();
        let mut step = 1e-13;
        let mut lo = h0;
        let mut hi = h0 + dir * step;
        for _ in 0..200 {
            if self.net(s, hi, d) * dir <= 0.0 {
                break;
            }
            lo = hi;
            step *= 2.0;
            hi = h0 + dir * step;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid == lo || mid == hi {
                break;
            }
            if self.net(s, mid, d) * dir > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    fn point(&self, s: Contact, h: f64, d: f64) -> CurvePoint {
        let deflection = h - d;
        CurvePoint {
            distance: d,
            gap: h,
            deflection,
            force: self.k_c * deflection,
            meniscus: s.meniscus == Meniscus::Formed,
            contact: s.contact,
        }
    }

    /// Approach from `d_far` to `d_near`, then retract to `d_retract` (≥ `d_far`: a soft lever
    /// needs a long way out before the adhesion lets go), in `steps` equal steps each way.
    pub fn curve(&self, d_far: f64, d_near: f64, d_retract: f64, steps: usize) -> ForceCurve {
        let steps = steps.max(2);
        let mut track = TipTrack::far(d_far);
        let mut approach = Vec::with_capacity(steps + 1);
        let mut retraction = Vec::with_capacity(steps + 1);
        let sweep = |from: f64, to: f64, out: &mut Vec<CurvePoint>, track: &mut TipTrack| {
            for k in 0..=steps {
                let d = from + (to - from) * k as f64 / steps as f64;
                out.push(self.track(track, d));
            }
        };
        sweep(d_far, d_near, &mut approach, &mut track);
        sweep(d_near, d_retract.max(d_far), &mut retraction, &mut track);

        // Contact made on approach, broken on retraction: the piezo distance of the first point
        // past the change.
        let change = |pts: &[CurvePoint], to: bool| {
            pts.windows(2)
                .find(|w| w[0].contact != to && w[1].contact == to)
                .map(|w| w[1].distance)
        };
        let pull_off_force = retraction.iter().map(|p| p.force).fold(0.0, f64::min);
        ForceCurve {
            snap_in_distance: change(&approach, true),
            pull_off_distance: change(&retraction, false),
            approach,
            retraction,
            pull_off_force,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::contact::jkr::contact_modulus;
    use crate::physics::forces::capillary::Capillary;
    use crate::physics::forces::vdw::sphere_plane_force;

    fn si_tip(capillary: bool) -> TipSample {
        let a0 = 0.165e-9;
        let jkr = Jkr::new(30e-9, contact_modulus(70e9, 0.3, 169e9, 0.27), 0.0);
        let cap = capillary.then(|| Capillary::new(30e-9, 2.0 * 0.072, 0.73, jkr.meniscus_breaking_length(0.072), a0));
        TipSample {
            r_t: 30e-9,
            k_c: 8.0,
            jkr,
            long_range: LongRange {
                hamaker: Some(1.865e-19),
                capillary: cap,
                electrostatic: None,
            },
            a0,
        }
    }

    /// The pull-off force is the meniscus (4πRₜγ_L = 27 nN) plus van der Waals at contact
    /// (HRₜ/(6a₀²) ≈ 34 nN), within 5 %.
    fn assert_pull_off_is_meniscus_plus_vdw(c: &ForceCurve) {
        let expected =
            -(4.0 * std::f64::consts::PI * 30e-9 * 0.072) + sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        assert!(
            (c.pull_off_force / expected - 1.0).abs() < 0.05,
            "{} vs {}",
            c.pull_off_force,
            expected
        );
    }

    #[test]
    fn soft_lever_pulls_off_too() {
        // At k_c = 0.5 N/m the ~54 nN adhesion needs ~110 nm of retraction to let go.
        let mut t = si_tip(true);
        t.k_c = 0.5;
        let c = t.curve(10e-9, -20e-9, 10e-9 + 1.5 * 60e-9 / 0.5, 2000);
        assert!(c.pull_off_distance.is_some(), "never let go");
        assert!(!c.retraction.last().unwrap().contact);
        assert_pull_off_is_meniscus_plus_vdw(&c);
        assert!(c.snap_in_distance.unwrap() > c.approach.last().unwrap().distance);
    }

    #[test]
    fn snap_in_and_pull_off_hysteresis() {
        let t = si_tip(true);
        let c = t.curve(10e-9, -5e-9, 10e-9, 600);
        // Approach: no force far away, a snap-in, then repulsion at the deepest point.
        assert!(c.approach[0].force.abs() < 0.1e-9, "{}", c.approach[0].force);
        assert!(c.snap_in_distance.is_some());
        assert!(c.approach.last().unwrap().force > 0.0);
        // Retraction: adhesion holds the tip beyond the snap-in point; the pull-off force is the
        // meniscus (4πRₜγ_L = 27 nN) plus van der Waals at contact (HRₜ/(6a₀²) ≈ 34 nN).
        assert_pull_off_is_meniscus_plus_vdw(&c);
        assert!(c.pull_off_distance.unwrap() > c.snap_in_distance.unwrap());
        // The curves differ: hysteresis.
        let area: f64 = c
            .approach
            .iter()
            .zip(c.retraction.iter().rev())
            .map(|(a, r)| (a.force - r.force).abs())
            .sum();
        assert!(area > 0.0);
        assert!(
            c.approach
                .iter()
                .chain(&c.retraction)
                .all(|p| p.force.is_finite() && p.gap.is_finite())
        );
    }

    #[test]
    fn equilibrium_holds_at_every_point() {
        let t = si_tip(true);
        let c = t.curve(10e-9, -5e-9, 10e-9, 200);
        for p in c.approach.iter().chain(&c.retraction) {
            let s = Contact {
                meniscus: if p.meniscus { Meniscus::Formed } else { Meniscus::Absent },
                contact: p.contact,
            };
            let f = t.force(s, p.gap);
            assert!(
                (f - p.force).abs() < 1e-3 * p.force.abs().max(1e-9),
                "{p:?}: F(h) = {f}"
            );
        }
    }

    #[test]
    fn dry_van_der_waals_only_pull_off() {
        let t = si_tip(false);
        let c = t.curve(10e-9, -5e-9, 10e-9, 600);
        let vdw = sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        assert!((c.pull_off_force / vdw - 1.0).abs() < 0.05);
    }
}
