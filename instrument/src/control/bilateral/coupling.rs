//! The virtual coupling between the handle and the tip's z set-point, and the renderable region
//! it is sized from (Colgate & Brown's Z-width; Adams & Hannaford's virtual coupling, 1999).
//!
//! The law ([`super`]) renders at the hand, each tick, with `K = g_f k_z g_p` the felt stiffness:
//!
//! ```text
//! F_hand = r g_f ( F_tip·[gate open]  +  k_z (z_ref − z_des) )           (server, 1 kHz)
//! F(x)   = F_hand − K (x − x_a) − B_c ẋ       while in contact or coupled (bridge, its rate)
//! g_f    = min(g_f,asked · β, K_max / (k_z g_p))                            (the region)
//! B_c    = 2 K (T/2 + T_d)
//! ```
//!
//! - the *coupling spring* `k_z (z_ref − z_des)`: the set-point `z_ref` follows the hand's
//!   `z_des` at a bounded speed and stops at the deflection and height limits; whatever it lags
//!   by is felt as a spring of the contact's own stiffness between the hand and the set-point.
//!   A lagging set-point only ever moves toward `z_des` (it relaxes the spring), so it takes no
//!   energy out of the spring that it did not store: the coupling is a spring in series with a
//!   dissipative element. Without it a set-point that lags while the hand withdraws would keep
//!   pushing the hand up with the force of a deeper tip: active.
//! - the *gate*: the tip force is rendered once the deflection leaves 5 σ of the sensor's noise
//!   (`|ζ_z| > ζ_c`) and until it has stayed within it for 20 ms. The noise is an active source
//!   (a random force the hand moves with), scaled by `g_f`; in free space it is all there is. The
//!   hysteresis lets a contact's force cross zero (adhesion to repulsion) without a gap, and the
//!   contact's stiffness stays in the local model while the gate is open.
//! - the *region*: the felt stiffness never exceeds `K_max = min(K_s, b / (T/2 + T_d),
//!   B_max / (2 (T/2 + T_d)))`, the device's Z-width edge at its period `T` and the measured
//!   round trip `T_d`, never what the device declares, and never so stiff that the coupling's
//!   damper would pass the damping `B_max` the device renders (the bridge clamps it there, and
//!   the spring without its damper is the loop the damper prevents: a device declaring
//!   1.5 N·s/m had the let-go press at the default hand the hand −1.36 mJ in 113 chatter
//!   cycles) ([`nanopush_proto::haptic::region`]); a force scale past it is lowered to the edge.
//! - the *coupling damper* `B_c`, rendered by the bridge with the device's velocity of the same
//!   cycle: a spring held over a period `T` and a delay `T_d` gives back `K (T/2 + T_d) ẋ²` more
//!   power than it took (the hold's leak, Colgate's `K T/2`, and the delay's); `B_c` is twice
//!   that. What it does, and what it does not:
//!   - *Passivity against every environment* (Colgate & Schenkel): a damper rendered by a
//!     sampled loop counts *against* the port, so the condition is
//!     `b > K (T/2 + T_d) + B_c = 3 K (T/2 + T_d)`, where `b` is the handle's damping and the
//!     grip's (so this is passivity toward the hand's intended motion, not the bare port's). A
//!     grip that brings that much makes the port passive whatever a passive environment behind
//!     the coupling does (Adams & Hannaford), and the contact is one (the snap-in and the
//!     adhesion give back only what the approach stored; the hysteresis of a closed cycle
//!     dissipates). At 1 kHz with a 1 ms round trip: the stiff grip (20 N·s/m) at every
//!     stiffness to the 2 kN/m edge (9 N·s/m needed), the firm grip (8 N·s/m) to 1788 N/m, the
//!     default's 1452 included ([`super::linear_loop`]'s tests); with a 2 ms round trip the firm
//!     grip only to 1073 N/m of the 1200 N/m edge. (The condition is sufficient: it is exact for
//!     a damper on a backward-differenced velocity, and the bridge's uses the device's sample.)
//!   - *A lighter grip, or none*, leaves the handle's own 0.05 N·s/m, and with that no sampled
//!     stiffness above ~33 N/m is passive against every environment, with a damper or without.
//!     For those hands what is proven is stability with the environment the loop has, the
//!     contact, for the simulated handle (50 g): linearised about it, the loop's spectral radius
//!     is below 1 at every stiffness to the edge, for the loose grip and the let-go hand, at 1
//!     and 4 kHz, for round trips of 1, 2 and 5 ms. Three loops are checked: the held spring
//!     on the current position, the same a round trip late, and the loop as the two processes
//!     render it (the bridge's local spring on the position it has just read, its anchor and
//!     force a round trip late, [`super::linear_loop::LinearLoop::rendered`]); worst ρ =
//!     0.99973 in each (the let-go hand on a 50 N/m spring at 4 kHz). That is what `B_c` is
//!     for: without it, or with a damper inside Colgate's budget (half of what the spring leaves
//!     of `b`, 0.41 N·s/m at the default), the loose grip and the let-go hand are unstable at the
//!     default (as rendered ρ = 1.010 and 1.020 without, 1.006 and 1.016 with the budgeted
//!     damper; a round trip late 1.011 and 1.021, 1.007 and 1.017), and so was the grid (with the
//!     budgeted damper and the edge 10 % lower, 3 loose-grip cells active: −16 mJ and 660
//!     chatter cycles at 10 nm/mm and 2.5 N). A serial device declares no mass: for a light
//!     grip on it the statement rests on the stiffness and damping its maker declares (the
//!     region keeps `B_c` within the declared damping) and on energy bounding.
//!   - What the linearisation leaves out (the snap-in, the adhesion, the gate, the limits, a
//!     stalled process) is measured: every cell of the grid, both processes paused at random
//!     included; and a loop that still leaks pins the passivity controller's damper, which
//!     energy bounding answers below.
//! - *energy bounding* `β`: if the bridge's passivity controller (which watches the port and
//!   damps what still leaks) holds its damper at its cap for more than 50 ms, the region was
//!   wrong for this device or this hand: `β` halves (down to 1/64), the status says why, and the
//!   monitor logs it. A new `scale` or engagement starts at `β = 1` again.

use nanopush_proto::haptic::HapticState;
use nanopush_proto::haptic::region::{Limit, coupling_damping, edge, limit_force_gain};

use super::BilateralParams;

/// How long the passivity damper may stay at its cap before the force scale is lowered (s).
pub const PINNED_FOR: f64 = 0.05;
/// The lowest energy-bounding factor.
pub const MIN_BOUND: f64 = 1.0 / 64.0;
/// Time constant of the round-trip delay's average (s).
pub const DELAY_AVERAGE: f64 = 1.0;
/// The longest round trip the region is computed for (s): beyond, the link is down anyway.
pub const MAX_DELAY: f64 = 5e-3;

/// The region and the coupling, tick by tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Coupling {
    /// Round-trip delay, averaged (s).
    delay: f64,
    /// Energy-bounding factor `β` (1: none).
    bound: f64,
    /// Consecutive ticks with the passivity damper at its cap.
    pinned: u32,
    /// Times the force scale was lowered by energy bounding.
    bounds: u64,
    /// The region's edge for the newest handle (N/m); 0 before one is known.
    k_max: f64,
    /// The force scale in force (hand N per tip N).
    force_gain: f64,
    /// Why it differs from the one asked.
    limit: Limit,
    /// The coupling damper for the stiffness in force (N·s/m).
    damping: f64,
}

impl Coupling {
    /// Before any handle sample: one tick of delay, no bound.
    pub fn new(tick: f64) -> Coupling {
        Coupling {
            delay: tick,
            bound: 1.0,
            pinned: 0,
            bounds: 0,
            k_max: 0.0,
            force_gain: 0.0,
            limit: Limit::None,
            damping: 0.0,
        }
    }

    /// A new scale or engagement: the bound starts over.
    pub fn reset_bound(&mut self) {
        self.bound = 1.0;
        self.pinned = 0;
    }

    /// One tick with the newest handle sample `h` (engaged: the hand's force is live): the
    /// delay's average, the damper's pinning, the region's edge, and the force scale in force,
    /// which it returns. Without a sample the last region holds.
    pub fn update(&mut self, p: &BilateralParams, h: Option<&HapticState>, engaged: bool) -> f64 {
        if let Some(h) = h {
            let measured = h.latency_ns as f64 * 1e-9;
            if measured > 0.0 && measured.is_finite() {
                self.delay += (measured.min(MAX_DELAY) - self.delay) * (p.tick / DELAY_AVERAGE).min(1.0);
            }
            self.delay = self.delay.clamp(p.tick, MAX_DELAY);
            let rate = if h.rate_hz > 0.0 { h.rate_hz } else { 1.0 / p.tick };
            self.k_max = edge(h.max_stiffness, h.spec_rate_hz, rate, self.delay, h.max_damping);
            let pinned = engaged && h.pc_cap > 0.0 && h.pc_damping >= 0.999 * h.pc_cap;
            self.pinned = if pinned { self.pinned + 1 } else { 0 };
            if f64::from(self.pinned) * p.tick > PINNED_FOR && self.bound > MIN_BOUND {
                self.bound = (self.bound * 0.5).max(MIN_BOUND);
                self.bounds += 1;
                self.pinned = 0;
            }
            let k_felt = |g: f64| g * p.k_z * p.position_gain;
            let (g, limit) = limit_force_gain(p.force_gain * self.bound, p.position_gain, p.k_z, self.k_max);
            self.force_gain = g;
            self.limit = if self.bound < 1.0 { Limit::EnergyBounding } else { limit };
            self.damping = coupling_damping(k_felt(g), rate, self.delay);
        }
        self.force_gain
    }

    /// The force scale in force (hand N per tip N).
    pub fn force_gain(&self) -> f64 {
        self.force_gain
    }

    /// Why the force scale in force differs from the one asked.
    pub fn limit(&self) -> Limit {
        self.limit
    }

    /// The region's edge for the newest handle (N/m).
    pub fn k_max(&self) -> f64 {
        self.k_max
    }

    /// The coupling damper (N·s/m).
    pub fn damping(&self) -> f64 {
        self.damping
    }

    /// Times the force scale was lowered by energy bounding.
    pub fn bounds(&self) -> u64 {
        self.bounds
    }

    /// The round-trip delay the region is computed for (s).
    pub fn delay(&self) -> f64 {
        self.delay
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    fn handle(latency_ns: u64, pc_damping: f64) -> HapticState {
        HapticState {
            max_force: 2.5,
            max_stiffness: 2000.0,
            max_damping: 50.0,
            spec_rate_hz: 1000.0,
            rate_hz: 1000.0,
            pc_cap: 40.0,
            pc_damping,
            latency_ns,
            ..HapticState::default()
        }
    }

    /// The paper scene at 10 nm/mm: 1 N of pull-off (1.45 kN/m) is inside the simulated
    /// device's 2 kN/m and kept as asked; 10 N (14.5 kN/m) is lowered to the edge, felt as
    /// 2 kN/m, with the coupling damper `2 K (T/2 + T_d)` = 6 N·s/m.
    #[test]
    fn the_default_is_kept_and_ten_newtons_are_lowered_to_the_edge() {
        let scene = Scene::default_scene();
        let mut p = scene.bilateral_params(1e-3);
        let mut c = Coupling::new(p.tick);
        let g = c.update(&p, Some(&handle(1_000_000, 0.0)), true);
        assert_eq!((g, c.limit()), (p.force_gain, Limit::None));
        assert!((c.k_max() - 2000.0).abs() < 1e-9, "{}", c.k_max());
        p.force_gain *= 10.0;
        let g = c.update(&p, Some(&handle(1_000_000, 0.0)), true);
        assert_eq!(c.limit(), Limit::Region);
        assert!((g * p.k_z * p.position_gain - 2000.0).abs() < 1e-6);
        assert!((c.damping() - 6.0).abs() < 1e-9, "{}", c.damping());
    }

    /// A longer measured round trip shrinks the region (its average moves by `T/τ` of the
    /// difference each tick); one sample of 4 ms moves it by only 3 µs.
    #[test]
    fn the_region_follows_the_averaged_delay() {
        let p = Scene::default_scene().bilateral_params(1e-3);
        let mut c = Coupling::new(p.tick);
        c.update(&p, Some(&handle(4_000_000, 0.0)), true);
        assert!((c.delay() - 1.003e-3).abs() < 1e-12, "{}", c.delay());
        for _ in 0..20_000 {
            c.update(&p, Some(&handle(2_000_000, 0.0)), true);
        }
        assert!((c.delay() - 2e-3).abs() < 1e-9, "{}", c.delay());
        assert!((c.k_max() - 3.0 / 2.5e-3).abs() < 1e-3, "{}", c.k_max());
    }

    /// The damper pinned at its cap for 50 ms is tolerated, for 51 it halves the force scale
    /// (energy bounding), again after another 51, and a new scale starts over.
    #[test]
    fn a_damper_pinned_too_long_halves_the_force_scale() {
        let p = Scene::default_scene().bilateral_params(1e-3);
        let mut c = Coupling::new(p.tick);
        for _ in 0..50 {
            c.update(&p, Some(&handle(1_000_000, 40.0)), true);
        }
        assert_eq!((c.force_gain(), c.bounds()), (p.force_gain, 0));
        c.update(&p, Some(&handle(1_000_000, 40.0)), true);
        assert_eq!(
            (c.force_gain(), c.bounds(), c.limit()),
            (0.5 * p.force_gain, 1, Limit::EnergyBounding)
        );
        for _ in 0..51 {
            c.update(&p, Some(&handle(1_000_000, 40.0)), true);
        }
        assert_eq!((c.force_gain(), c.bounds()), (0.25 * p.force_gain, 2));
        // Not engaged, or below the cap: not pinned.
        c.update(&p, Some(&handle(1_000_000, 39.0)), true);
        c.reset_bound();
        assert_eq!(c.update(&p, Some(&handle(1_000_000, 40.0)), false), p.force_gain);
        assert_eq!(c.limit(), Limit::None);
    }

    /// No handle yet: no region, no force.
    #[test]
    fn without_a_handle_nothing_is_rendered() {
        let p = Scene::default_scene().bilateral_params(1e-3);
        let mut c = Coupling::new(p.tick);
        assert_eq!(c.update(&p, None, false), 0.0);
        // A handle that declares no stiffness renders nothing either.
        let none = HapticState {
            max_stiffness: 0.0,
            ..handle(1_000_000, 0.0)
        };
        assert_eq!(c.update(&p, Some(&none), true), 0.0);
    }
}
