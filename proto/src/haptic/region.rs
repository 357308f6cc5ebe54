//! The renderable region of a 1-DOF haptic device: which felt stiffness and damping it renders
//! passively at its rate and with the loop's round-trip delay (Colgate & Brown's *Z-width*,
//! 1994), and the scales that stay inside it.
//!
//! A sampled virtual spring `K` with a damper `B` (its velocity by a backward difference),
//! rendered with a zero-order hold of period `T` on a device whose port has the damping `b`, is
//! passive iff (Colgate & Schenkel 1997)
//!
//! ```text
//! b > K T / 2 + |B|
//! ```
//!
//! A round-trip delay `T_d` on the force adds to the hold: to first order (Hulin, Albu-Schäffer &
//! Hirzinger 2014, their small-delay approximation) the condition becomes
//! `b > K (T/2 + T_d) + |B|`, so
//!
//! ```text
//! K_max(B) = (b − |B|) / (T/2 + T_d)                                     (the Z-width's edge)
//! ```
//!
//! The port damping `b` is read from the device's own specification, CHAI3D's way: a device
//! declares the largest stiffness `K_s` it renders stably at its rate `1/T_s` in a loop with one
//! period of round trip (the bridge locks its cycle to the server's tick, so that is the loop's
//! round trip: docs/benchmarks.md, haptic latency), which fixes `b = K_s (T_s/2 + T_s)`. The
//! simulated device declares 2 kN/m at 1 kHz; a serial device sends `K_s` and its rate in its
//! info packet. That `b` is the port's damping *with the hand the maker rated the device with*:
//! a bare handle has far less (the simulated one 0.05 N·s/m, a wall of ~33 N/m), so what the
//! region promises, and what the coupling adds for a lighter grip, is argued in
//! `nanopush_instrument::control::bilateral::coupling`. The region at another rate or a longer measured delay follows from the formula,
//! but never beyond what the device declares ([`edge`]): at 4 kHz the formula allows the
//! simulated device 2.67 kN/m, at which a loose grip (1 N·s/m) stays passive but rings (146
//! chatter cycles in the grid's press at 10 nm/mm and 2.5 N, against none at 2 kN/m).
//!
//! The felt contact stiffness of a scaled teleoperator is `K_felt = g_f · k_z · g_p` (`g_f` hand
//! newtons per tip newton, `k_z` the lever, `g_p` tip metres per handle metre). A setting with
//! `K_felt > K_max(0)` is limited by lowering the force scale to `g_f = K_max / (k_z g_p)`: the
//! position scale the operator chose (the resolution of their motion) is kept.

/// The port damping a device's declared stiffness limit implies (N·s/m): `b = K_s (T_s/2 +
/// T_s)`, for `max_stiffness` (N/m) declared at `rate_hz`. Zero for a limit or rate that is not
/// a positive finite number.
pub fn port_damping(max_stiffness: f64, rate_hz: f64) -> f64 {
    if !(max_stiffness.is_finite() && max_stiffness > 0.0 && rate_hz.is_finite() && rate_hz > 0.0) {
        return 0.0;
    }
    let t = 1.0 / rate_hz;
    max_stiffness * 1.5 * t
}

/// The largest stiffness (N/m) rendered passively with a rendered damping `damping` (N·s/m), on
/// a port of damping `port_damping` (N·s/m), at `rate_hz` with a round-trip delay `delay_s`:
/// `K_max(B) = (b − |B|) / (T/2 + T_d)`, 0 outside the region (`|B| ≥ b`) or for input that is
/// not finite.
pub fn max_stiffness(port_damping: f64, damping: f64, rate_hz: f64, delay_s: f64) -> f64 {
    let t = 1.0 / rate_hz;
    let k = (port_damping - damping.abs()) / (0.5 * t + delay_s.max(0.0));
    if k.is_finite() { k.max(0.0) } else { 0.0 }
}

/// The region's edge the scales are limited to (N/m): [`max_stiffness`] with no damping, for a
/// device declaring `declared` (N/m) at `spec_rate_hz`, run at `rate_hz` with a round trip of
/// `delay_s`; never above `declared`; and never so stiff that the coupling's damper
/// ([`coupling_damping`], `2 K (T/2 + T_d)`) would exceed the damping the device renders,
/// `max_damping` (N·s/m): the bridge clamps the damper there, and a spring without its damper
/// is what the damper is there to prevent. A `max_damping` that is not a positive finite number
/// does not limit.
pub fn edge(declared: f64, spec_rate_hz: f64, rate_hz: f64, delay_s: f64, max_damping: f64) -> f64 {
    let z_width = max_stiffness(port_damping(declared, spec_rate_hz), 0.0, rate_hz, delay_s).min(declared.max(0.0));
    let damper = max_damping / (2.0 * (0.5 / rate_hz + delay_s.max(0.0)));
    if damper.is_finite() && damper > 0.0 {
        z_width.min(damper)
    } else {
        z_width
    }
}

/// The virtual coupling's damper for a felt stiffness `stiffness` (N/m) at `rate_hz` with a
/// round-trip delay `delay_s` (N·s/m): twice the dissipation the sampled spring's leak needs,
/// `B_c = 2 K (T/2 + T_d)` (see `nanopush_instrument::control::bilateral::coupling`).
pub fn coupling_damping(stiffness: f64, rate_hz: f64, delay_s: f64) -> f64 {
    let b = 2.0 * stiffness.abs() * (0.5 / rate_hz + delay_s.max(0.0));
    if b.is_finite() { b } else { 0.0 }
}

/// Why the scales in force differ from those asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    /// As asked.
    None,
    /// The felt stiffness would leave the device's renderable region.
    Region,
    /// The passivity controller's damper stayed at its cap: the force scale was lowered.
    EnergyBounding,
}

impl Limit {
    /// Name for status, telemetry and replies.
    pub fn name(self) -> &'static str {
        match self {
            Limit::None => "none",
            Limit::Region => "renderable_region",
            Limit::EnergyBounding => "energy_bounding",
        }
    }

    /// The sentence an operator reads.
    pub fn reason(self) -> &'static str {
        match self {
            Limit::None => "",
            Limit::Region => {
                "the contact would be felt stiffer than the device renders passively (its Z-width at its rate and the measured round trip, at most the stiffness it declares); the force scale was lowered to the region's edge"
            }
            Limit::EnergyBounding => {
                "the passivity controller's damper stayed at its cap for more than 50 ms; the force scale was halved (energy bounding)"
            }
        }
    }

    /// The code carried in a `u32` (metrics, telemetry).
    pub fn code(self) -> u32 {
        match self {
            Limit::None => 0,
            Limit::Region => 1,
            Limit::EnergyBounding => 2,
        }
    }

    /// From [`Limit::code`].
    pub fn from_code(c: u32) -> Limit {
        match c {
            1 => Limit::Region,
            2 => Limit::EnergyBounding,
            _ => Limit::None,
        }
    }
}

/// The force scale in force (hand N per tip N) for the one asked, `force_gain`, at the position
/// scale `position_gain` (tip m per handle m), a lever of `k_lever` (N/m) and a region edge
/// `k_max` (N/m): `min(g_f, K_max / (k_z g_p))`, and whether it was limited.
pub fn limit_force_gain(force_gain: f64, position_gain: f64, k_lever: f64, k_max: f64) -> (f64, Limit) {
    let at_edge = k_max / (k_lever * position_gain);
    if at_edge.is_finite() && at_edge >= 0.0 && force_gain > at_edge {
        (at_edge, Limit::Region)
    } else {
        (force_gain, Limit::None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Colgate's bound, by hand: the simulated device's 2 kN/m at 1 kHz is a port damping of
    /// 3 N·s/m; with one period of delay it renders exactly its 2 kN/m again, at 4 kHz with the
    /// same 1 ms delay 3 / (0.125 ms + 1 ms) = 2.67 kN/m, with 2 ms of delay 1.2 kN/m, and a
    /// damper of 1 N·s/m takes a third of the region away.
    #[test]
    fn the_z_width_follows_colgates_bound_with_the_delay() {
        let b = port_damping(2000.0, 1000.0);
        assert!((b - 3.0).abs() < 1e-12, "{b}");
        assert!((max_stiffness(b, 0.0, 1000.0, 1e-3) - 2000.0).abs() < 1e-9);
        assert!((max_stiffness(b, 0.0, 4000.0, 1e-3) - 3.0 / 1.125e-3).abs() < 1e-9);
        assert!((max_stiffness(b, 0.0, 1000.0, 2e-3) - 1200.0).abs() < 1e-9);
        assert!((max_stiffness(b, 1.0, 1000.0, 1e-3) - 2000.0 * 2.0 / 3.0).abs() < 1e-9);
        assert_eq!(max_stiffness(b, 5.0, 1000.0, 1e-3), 0.0);
        assert_eq!(max_stiffness(f64::NAN, 0.0, 1000.0, 1e-3), 0.0);
        assert_eq!(port_damping(-1.0, 1000.0), 0.0);
        assert!((coupling_damping(-2000.0, 1000.0, 1e-3) - 6.0).abs() < 1e-12);
        // The edge: the declared 2 kN/m at 4 kHz (not 2.67), 1.2 kN/m with 2 ms of delay.
        assert_eq!(edge(2000.0, 1000.0, 4000.0, 1e-3, 50.0), 2000.0);
        assert!((edge(2000.0, 1000.0, 1000.0, 2e-3, 50.0) - 1200.0).abs() < 1e-9);
        assert_eq!(edge(f64::NAN, 1000.0, 1000.0, 1e-3, 50.0), 0.0);
        // A device that renders at most 1.5 N·s/m: the damper 2K (T/2 + T_d) fits up to 500 N/m
        // at 1 kHz with 1 ms of delay; an unknown damping limit does not limit.
        assert!((edge(2000.0, 1000.0, 1000.0, 1e-3, 1.5) - 500.0).abs() < 1e-9);
        assert!((coupling_damping(500.0, 1000.0, 1e-3) - 1.5).abs() < 1e-12);
        assert_eq!(edge(2000.0, 1000.0, 1000.0, 1e-3, 0.0), 2000.0);
    }

    /// The paper scene's lever (8.0 N/m) at 10 nm/mm and 10 N of pull-off (18.15e7 hand N per
    /// tip N) would be felt as 14.5 kN/m: limited to the 2 kN/m edge; the default 1 N (1.45
    /// kN/m) is inside and kept.
    #[test]
    fn a_setting_past_the_edge_gets_the_edges_force_scale() {
        let (k_z, g_p) = (8.0, 1e-5);
        let (g, why) = limit_force_gain(18.15e7, g_p, k_z, 2000.0);
        assert_eq!(why, Limit::Region);
        assert!((g * k_z * g_p - 2000.0).abs() < 1e-9);
        assert_eq!(limit_force_gain(1.815e7, g_p, k_z, 2000.0), (1.815e7, Limit::None));
        for l in [Limit::None, Limit::Region, Limit::EnergyBounding] {
            assert_eq!(Limit::from_code(l.code()), l);
        }
    }
}
