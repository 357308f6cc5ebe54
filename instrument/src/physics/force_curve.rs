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

use crate::numerics::dual::{Real, derivative};
use crate::physics::contact::jkr::Jkr;
use crate::physics::forces::capillary::Meniscus;
use crate::physics::pushing::params::{Attraction, LongRange};

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
    /// attraction's gradient exceeds `k_c`) (m): found by root-finding, see
    /// [`TipSample::snap_in`].
    pub snap_in_distance: Option<f64>,
    /// Force on the tip at the pull-off, the last equilibrium in contact on retraction (N,
    /// negative): found by root-finding, see [`TipSample::pull_off`]; without a pull-off
    /// in the range, the most attractive force of the retraction.
    pub pull_off_force: f64,
    /// Piezo distance where the contact broke on retraction (m).
    pub pull_off_distance: Option<f64>,
}

/// Bisection steps: the interval closes to adjacent doubles well before.
const BISECTION_STEPS: usize = 200;

/// Steps of the scan that brackets a fold or a balance on a force-curve branch.
const FOLD_SCAN: usize = 4000;

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

    /// The terms of [`Self::adhesion`] that pull hardest (at contact, the meniscus formed;
    /// [`Attraction::ranked`]).
    pub fn adhesion_sources(&self) -> Vec<Attraction> {
        let mut terms = self
            .long_range
            .terms(self.r_t, None, self.a0, Meniscus::Formed, self.a0);
        terms.push((Attraction::Contact, -self.jkr.pull_off_load()));
        Attraction::ranked(terms)
    }

    /// How far the piezo must rise above a contact before the tip surely hangs free (m):
    /// `F_ad / k_c + L_t + δ_b + a₀`. While the contact or the meniscus holds the tip, the lever
    /// bends toward the sample by at most the adhesion over its stiffness ([`Self::adhesion`]
    /// bounds the attraction: every term is strongest at contact), and the meniscus ruptures
    /// at the gap `L_t + δ_b` (above `a₀`); past both the tip is on the free branch, which is
    /// the approach's.
    pub fn release_distance(&self) -> f64 {
        let rupture = self
            .long_range
            .capillary
            .as_ref()
            .filter(|c| c.possible())
            .map_or(0.0, |c| c.rupture_gap);
        self.adhesion().max(0.0) / self.k_c + rupture + self.a0
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

    /// Tip-sample force at gap `h` in state `s` (N, positive repulsive), generic so that
    /// [`Self::branch`] has its exact slope.
    fn force<T: Real>(&self, s: Contact, h: T) -> T {
        let elastic = if s.contact {
            self.jkr
                .load_from_indentation(T::cst(self.a0) - h)
                .unwrap_or(T::cst(0.0))
        } else {
            T::cst(0.0)
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

    /// The piezo distance at which gap `h` is an equilibrium in state `s`,
    /// `d(h) = h − F(h)/k_c`, and its slope `d'(h) = 1 − F'(h)/k_c`: the branch is stable
    /// where `d' > 0` and ends at a fold where `d' = 0`.
    fn branch(&self, s: Contact, h: f64) -> (f64, f64) {
        let (f, df) = derivative(|h| self.force(s, h), h);
        (h - f / self.k_c, 1.0 - df / self.k_c)
    }

    /// The first `h` from `from` toward `to` where `test(h)` holds: a scan of [`FOLD_SCAN`]
    /// equal steps brackets it, bisection closes the bracket to adjacent doubles.
    fn first_where(&self, from: f64, to: f64, test: impl Fn(f64) -> bool) -> Option<f64> {
        let mut prev = from;
        for k in 1..=FOLD_SCAN {
            let h = from + (to - from) * k as f64 / FOLD_SCAN as f64;
            if test(h) {
                let (mut out, mut inside) = (prev, h);
                for _ in 0..BISECTION_STEPS {
                    let mid = 0.5 * (out + inside);
                    if mid == out || mid == inside {
                        break;
                    }
                    if test(mid) {
                        inside = mid;
                    } else {
                        out = mid;
                    }
                }
                return Some(inside);
            }
            prev = h;
        }
        None
    }

    /// The snap-in on approach from a gap `h_far` (m): the piezo distance where the tip first
    /// touches. Root-finding on the equations of the non-contact branch `d(h) = h − F(h)/k_c`:
    /// the tip follows it down until a fold (`d' = 0`, the attraction's gradient reaching
    /// `k_c`), or until the meniscus forms at `L_t` and the formed branch has no equilibrium
    /// above `a₀` at that piezo distance; else it reaches `a₀` on a stable branch.
    pub fn snap_in(&self, h_far: f64) -> f64 {
        let free = Contact {
            meniscus: Meniscus::Absent,
            contact: false,
        };
        let a0 = self.a0;
        let formation = match &self.long_range.capillary {
            Some(c) if c.possible() => Some(c.formation_gap + a0),
            _ => None,
        };
        let bottom = formation.unwrap_or(a0).max(a0);
        if let Some(h) = self.first_where(h_far, bottom, |h| self.branch(free, h).1 <= 0.0) {
            return self.branch(free, h).0;
        }
        let Some(h_form) = formation.filter(|&h| h > a0) else {
            return self.branch(free, a0).0;
        };
        let d_form = self.branch(free, h_form).0;
        let wet = Contact {
            meniscus: Meniscus::Formed,
            ..free
        };
        // The formed branch's equilibrium at the formation's piezo distance, if any, and its fold.
        match self.first_where(h_form, a0, |h| self.branch(wet, h).0 <= d_form) {
            None => d_form,
            Some(h_eq) => match self.first_where(h_eq, a0, |h| self.branch(wet, h).1 <= 0.0) {
                Some(h) => self.branch(wet, h).0,
                None => self.branch(wet, a0).0,
            },
        }
    }

    /// The pull-off on retraction from the contact at gap `h_deep` (m, `< a₀`) with the
    /// meniscus in `meniscus`: the piezo distance where the contact breaks and the force
    /// `k_c ζ = F(h)` there (N). Root-finding on the contact branch `d(h) = h − F(h)/k_c`: the
    /// tip follows it up until a fold (`d' = 0`: the JKR load's slope reaching `−k_c`), or to
    /// the end of the JKR contact's stable branch (`a₀ − h` = the minimum indentation).
    pub fn pull_off(&self, h_deep: f64, meniscus: Meniscus) -> (f64, f64) {
        let s = Contact {
            meniscus,
            contact: true,
        };
        let end = self.a0 - self.jkr.min_indentation();
        let h = self
            .first_where(h_deep, end, |h| self.branch(s, h).1 <= 0.0)
            .unwrap_or(end);
        (self.branch(s, h).0, self.force(s, h))
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
        let h_far = track.gap;
        sweep(d_far, d_near, &mut approach, &mut track);
        let deepest = track;
        sweep(d_near, d_retract.max(d_far), &mut retraction, &mut track);

        // Snap-in and pull-off by root-finding on the equations, not read off the grid (at the
        // default 200 steps the grid read −53.8 nN for a −55.1 nN pull-off). The grid says
        // whether they happen within the curve's range.
        let made = |pts: &[CurvePoint], to: bool| pts.windows(2).any(|w| w[0].contact != to && w[1].contact == to);
        let snap_in_distance = made(&approach, true).then(|| self.snap_in(h_far));
        let pull_off = (deepest.in_contact() && made(&retraction, false))
            .then(|| self.pull_off(deepest.gap, deepest.state.meniscus));
        ForceCurve {
            snap_in_distance,
            pull_off_distance: pull_off.map(|(d, _)| d),
            pull_off_force: pull_off.map_or_else(|| retraction.iter().map(|p| p.force).fold(0.0, f64::min), |(_, f)| f),
            approach,
            retraction,
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

    /// Where a decreasing `slope` falls to `k` in `[lo, hi]`, by bisection: a branch's fold.
    fn fold(slope: impl Fn(f64) -> f64, k: f64, mut lo: f64, mut hi: f64) -> f64 {
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if slope(mid) > k {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
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
        // Wet: the meniscus forms at h = 2r₁ + a₀ (Eq 3) and the formed branch has no balance
        // above a₀ at that piezo distance (27 nN of meniscus against 8 N/m): the snap-in is
        // where the tip reaches the formation gap, d = h − F_vdW(h)/k_c.
        let h_form = 2.0 * crate::physics::forces::capillary::kelvin_radius(0.73) + 0.165e-9;
        let expected = h_form - sphere_plane_force(1.865e-19, 30e-9, h_form, 0.165e-9) / 8.0;
        let d = c.snap_in_distance.unwrap();
        assert!((d / expected - 1.0).abs() < 1e-9, "{d} vs {expected}");
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

    /// The pull-off is not read off the grid (−53.8 nN at 200 steps against −55.1 nN from the
    /// equations). With Hertz contacts (γ_SL = 0, no JKR adhesion) the
    /// contact leaves at zero indentation, where the force is exactly the long-range
    /// attraction at the cut-off: the meniscus `4πRₜγ_L` plus van der Waals `HRₜ/(6a₀²)`,
    /// in closed form. Root-finding reaches it to 10⁻⁹ at any grid.
    #[test]
    fn the_pull_off_is_the_closed_form_adhesion_at_any_grid() {
        let t = si_tip(true);
        let expected =
            -(4.0 * std::f64::consts::PI * 30e-9 * 0.072) + sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        assert!(
            (t.adhesion() + expected).abs() < 1e-9 * expected.abs(),
            "the closed form itself"
        );
        for steps in [20, 200, 2000] {
            let c = t.curve(10e-9, -5e-9, 10e-9, steps);

            assert!(
                (c.pull_off_force / expected - 1.0).abs() < 1e-9,
                "{steps} steps: {} vs {expected}",
                c.pull_off_force
            );
        }
        // Dry: van der Waals alone.
        let dry = si_tip(false).curve(10e-9, -5e-9, 10e-9, 20);
        let vdw = sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        assert!((dry.pull_off_force / vdw - 1.0).abs() < 1e-9, "{}", dry.pull_off_force);
    }

    /// The adhesion's closed form with a JKR contact: the work of adhesion adds the JKR pull-off
    /// load `(3/2)πRₜw` to the long-range attraction at contact: for w = 0.1 J/m² and
    /// Rₜ = 30 nm, 14.137 nN more than the same tip with a Hertz contact.
    #[test]
    fn a_jkr_contact_adds_its_pull_off_load_to_the_adhesion() {
        let hertz = si_tip(true);
        let jkr = TipSample {
            jkr: Jkr::new(30e-9, contact_modulus(70e9, 0.3, 169e9, 0.27), 0.1),
            ..hertz
        };
        let extra = jkr.adhesion() - hertz.adhesion();
        assert!((extra - 14.137e-9).abs() < 0.001e-9, "{extra:e}");
    }

    /// The release distance bounds the rise a retraction needs before the tip hangs free (no
    /// contact, no meniscus), and is not loose: for soft to stiff levers, wet or dry, with and
    /// without JKR adhesion, the tip is free at or before `F_ad/k_c + L_t + δ_b + a₀`, and not
    /// before half of it.
    #[test]
    fn the_tip_hangs_free_within_its_release_distance() {
        for k_c in [0.1, 1.0, 8.0, 40.0] {
            for wet in [false, true] {
                for w in [0.0, 0.1] {
                    let base = si_tip(wet);
                    let t = TipSample {
                        k_c,
                        jkr: Jkr::new(30e-9, contact_modulus(70e9, 0.3, 169e9, 0.27), w),
                        ..base
                    };
                    let bound = t.release_distance();
                    let mut track = TipTrack::far(20e-9);
                    t.track(&mut track, 20e-9);
                    t.track(&mut track, -1e-9);
                    assert!(track.in_contact());
                    let step = 0.05e-9;
                    let mut d = -1e-9;
                    while track.in_contact() || track.state.meniscus == Meniscus::Formed {
                        d += step;
                        t.track(&mut track, d);
                        assert!(
                            d < 2.0 * bound + 10e-9,
                            "k_c {k_c} wet {wet} w {w}: still held at {d:e}"
                        );
                    }
                    assert!(
                        d <= bound + step && d >= 0.5 * bound,
                        "k_c {k_c} wet {wet} w {w}: free at {:.2} nm, bound {:.2} nm",
                        d * 1e9,
                        bound * 1e9
                    );
                }
            }
        }
    }

    /// The tip's track says whether it touches: not far away, yes pressed into the surface, and
    /// no again once retracted past the pull-off.
    #[test]
    fn the_track_knows_when_the_tip_touches() {
        // Dry: the snap-in is at about 0.9 nm (see the next test), the pull-off near 4 nm.
        let t = si_tip(false);
        let mut track = TipTrack::far(10e-9);
        assert!(!track.in_contact());
        t.track(&mut track, 5e-9);
        assert!(!track.in_contact(), "5 nm away, before the snap-in");
        t.track(&mut track, -2e-9);
        assert!(track.in_contact(), "pressed 2 nm past the surface");
        t.track(&mut track, 20e-9);
        assert!(!track.in_contact(), "retracted past the pull-off");
    }

    /// Dry snap-in: Hamaker's sphere-plane force `F = −C/q²`, `C = 2HRₜ³/3`, `q = h(h+2Rₜ)`,
    /// has its fold where `F' = 2C(2h+2Rₜ)/q³ = k_c` (solved here by bisection on that
    /// hand-derived slope), and the piezo distance there is `d* = h* − F(h*)/k_c`; for `h ≪ Rₜ`
    /// it tends to `1.5 (HRₜ/(3k_c))^{1/3}`.
    #[test]
    fn the_dry_snap_in_is_at_the_van_der_waals_fold() {
        let t = si_tip(false);
        let (hm, r, k) = (1.865e-19_f64, 30e-9_f64, 8.0);
        let c = 2.0 * hm * r.powi(3) / 3.0;
        let slope = |h: f64| {
            let q = h * (h + 2.0 * r);
            2.0 * c * (2.0 * h + 2.0 * r) / q.powi(3)
        };
        let h = fold(slope, k, 0.2e-9, 5e-9);
        let q = h * (h + 2.0 * r);
        let expected = h + c / (q * q) / k;
        let simple = 1.5 * (hm * r / (3.0 * k)).cbrt();
        assert!((expected / simple - 1.0).abs() < 0.01, "{expected} vs {simple}");
        for steps in [20, 2000] {
            let d = t.curve(10e-9, -5e-9, 10e-9, steps).snap_in_distance.unwrap();
            assert!((d / expected - 1.0).abs() < 1e-9, "{steps} steps: {d} vs {expected}");
        }
    }

    /// A stiff lever (100 N/m) is not snapped in by the meniscus when it forms: the tip goes on
    /// down the formed branch to its fold, where the slopes of van der Waals
    /// (`2C(2h+2Rₜ)/q³`) and of the meniscus (`F₀/(2r₁(1+(h−a₀)/2r₁)²)`, Eq 3) together reach
    /// `k_c` (bisection on those hand-derived slopes), at `d = h* − F(h*)/k_c`.
    #[test]
    fn the_wet_snap_in_of_a_stiff_lever_is_at_the_formed_branchs_fold() {
        let t = TipSample {
            k_c: 100.0,
            ..si_tip(true)
        };
        let (hm, r, a0, k) = (1.865e-19_f64, 30e-9_f64, 0.165e-9_f64, 100.0);
        let c = 2.0 * hm * r.powi(3) / 3.0;
        let r1 = crate::physics::forces::capillary::kelvin_radius(0.73);
        let f0 = 2.0 * std::f64::consts::PI * 30e-9 * 2.0 * 0.072;
        let force = |h: f64| {
            let q = h * (h + 2.0 * r);
            -c / (q * q) - f0 / (1.0 + (h - a0) / (2.0 * r1))
        };
        let slope = |h: f64| {
            let q = h * (h + 2.0 * r);
            let x = 1.0 + (h - a0) / (2.0 * r1);
            2.0 * c * (2.0 * h + 2.0 * r) / q.powi(3) + f0 / (2.0 * r1 * x * x)
        };
        assert!(slope(a0) > k, "a fold above a₀");
        let h = fold(slope, k, a0, 2.0 * r1 + a0);
        let expected = h - force(h) / k;
        let d = t.curve(10e-9, -5e-9, 10e-9, 200).snap_in_distance.unwrap();
        assert!((d / expected - 1.0).abs() < 1e-9, "{d} vs {expected}");
        // Below the formation gap: the tip was not snapped in where the meniscus formed.
        assert!(d < 2.0 * r1 + a0, "{d}");
    }

    /// With a JKR contact (w = 0.05 J/m²) the tip leaves where the contact branch folds: at the
    /// cut-off `a₀`, above which the long-range attraction's gradient (van der Waals alone
    /// `2C(2a₀+2Rₜ)/q³` ≈ 420 N/m at `a₀`, by hand) exceeds `k_c`.
    /// There the JKR contact is at zero indentation, where its load is `−(4/3)πRₜw` (from
    /// `δ = a²/R − (2/3)√(6πwa/K) = 0`), on top of the meniscus `2πRₜ·2γ_L` and van der Waals at
    /// `a₀`; the end of the stable branch (δ_min = −0.047 nm) is never reached.
    #[test]
    fn a_jkr_contact_lets_go_at_the_cut_off_with_its_zero_indentation_load() {
        let w = 0.05;
        let t = TipSample {
            jkr: Jkr::new(30e-9, contact_modulus(70e9, 0.3, 169e9, 0.27), w),
            ..si_tip(true)
        };
        let pi = std::f64::consts::PI;
        let expected = -4.0 / 3.0 * pi * 30e-9 * w - 2.0 * pi * 30e-9 * 2.0 * 0.072
            + sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        let c = t.curve(10e-9, -5e-9, 20e-9, 200);
        assert!(
            (c.pull_off_force / expected - 1.0).abs() < 1e-6,
            "{:e} vs {expected:e}",
            c.pull_off_force
        );
        assert!(t.jkr.min_indentation() < 0.0);
    }

    /// The curve's bookkeeping: equally spaced piezo distances both ways; no snap-in or pull-off
    /// reported for a curve that never touches, for one that starts and stays in contact, or for
    /// a retraction too short to pull off.
    #[test]
    fn the_curve_reports_only_the_events_it_contains() {
        let t = si_tip(false);
        let c = t.curve(10e-9, -5e-9, 10e-9, 30);
        for (k, p) in c.approach.iter().enumerate() {
            assert!((p.distance - (10e-9 - 15e-9 * k as f64 / 30.0)).abs() < 1e-21, "{k}");
        }
        for (k, p) in c.retraction.iter().enumerate() {
            assert!((p.distance - (-5e-9 + 15e-9 * k as f64 / 30.0)).abs() < 1e-21, "{k}");
        }
        let never = t.curve(10e-9, 3e-9, 10e-9, 30);
        assert!(never.snap_in_distance.is_none() && never.pull_off_distance.is_none());
        assert!(never.approach.iter().chain(&never.retraction).all(|p| !p.contact));
        let pressed = t.curve(-1e-9, -3e-9, -0.5e-9, 30);
        assert!(pressed.approach.iter().chain(&pressed.retraction).all(|p| p.contact));
        assert!(pressed.snap_in_distance.is_none() && pressed.pull_off_distance.is_none());
        // From 2 nm and back: still held by the adhesion (the dry pull-off is at 4.4 nm).
        // (A retraction runs at least back to where the approach started.)
        let short = t.curve(2e-9, -3e-9, 2e-9, 30);
        assert!(short.snap_in_distance.is_some());
        assert!(short.pull_off_distance.is_none(), "{:?}", short.pull_off_distance);
    }

    #[test]
    fn dry_van_der_waals_only_pull_off() {
        let t = si_tip(false);
        let c = t.curve(10e-9, -5e-9, 10e-9, 600);
        let vdw = sphere_plane_force(1.865e-19, 30e-9, 0.165e-9, 0.165e-9);
        assert!((c.pull_off_force / vdw - 1.0).abs() < 0.05);
    }
}
