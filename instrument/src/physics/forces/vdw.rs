//! Van der Waals forces: tip-particle (sphere-sphere, Eq 1) and particle-substrate
//! (sphere-plane, Eq 2), both corrected (docs/errata.md items 1-3).
//!
//! Sign convention of the paper: a negative force is attractive.

use crate::numerics::dual::Real;

/// The sum `Σ_{n≥3} xⁿ (n−2)/(2n)`, which equals `(x/2)(1/(1−x) + 1) + ln(1−x)` for
/// `0 ≤ x < 1`. Both energies below reduce to it; for small `x` the closed form cancels
/// catastrophically (the leading `x` and `x²/2` terms cancel), so the series is used there.
fn hamaker_energy_kernel(x: f64) -> f64 {
    if x < 0.05 {
        let mut sum = 0.0;
        let mut xn = x * x * x;
        for n in 3..40 {
            let term = xn * (n as f64 - 2.0) / (2.0 * n as f64);
            sum += term;
            if term.abs() < 1e-18 * sum.abs() {
                break;
            }
            xn *= x;
        }
        sum
    } else {
        0.5 * x * (1.0 / (1.0 - x) + 1.0) + (-x).ln_1p()
    }
}

/// Sphere-sphere van der Waals energy (J), the closed form behind Eq 1:
///
/// `W(h) = −H/6 [2RₐRₜ/(C²−r₊²) + 2RₐRₜ/(C²−r₋²) + ln((C²−r₊²)/(C²−r₋²))]`,
/// `C = h + r₊`, `r₊ = Rₜ + Rₐ`, `r₋ = Rₜ − Rₐ`.
///
/// Written as `W = −H/6 · k(x)` with `x = 4RₐRₜ/(C²−r₋²)` and `k` from
/// `hamaker_energy_kernel`, which is the same expression without cancellation.
/// `h` is taken as `max(h, a0)` (docs/errata.md item 3).
pub fn sphere_sphere_energy(hamaker: f64, r_t: f64, r_a: f64, h: f64, a0: f64) -> f64 {
    let h = h.max(a0);
    let r_plus = r_t + r_a;
    let r_minus = r_t - r_a;
    let c = h + r_plus;
    let v = c * c - r_minus * r_minus;
    -hamaker / 6.0 * hamaker_energy_kernel(4.0 * r_a * r_t / v)
}

/// Sphere-sphere van der Waals force (N), **Eq 1 corrected** (docs/errata.md item 1).
///
/// `F = −H C/3 {2RₐRₜ/(h²(h+2r₊)²) + 2RₐRₜ/(C²−r₋²)² − 1/(h(h+2r₊)) + 1/(C²−r₋²)}`, the exact
/// `−dW/dh` of [`sphere_sphere_energy`]; the print has the signs of the last two terms flipped.
/// With `u = h(h+2r₊) = C²−r₊²`, `v = C²−r₋²` and `v − u = 4RₐRₜ`, the braces equal
/// `2RₐRₜ(1/u − 1/v)²`, so it is evaluated as
///
/// `F = −32 H (RₐRₜ)³ C / (3 u² v²)`
///
/// which is exact, free of cancellation, tends to the Derjaguin limit `−H R̃/(6h²)` at contact and
/// decays as `1/h⁷` far away. `h` is clamped to the interatomic cut-off `a0`.
pub fn sphere_sphere_force<T: Real>(hamaker: f64, r_t: f64, r_a: f64, h: T, a0: f64) -> T {
    let h = h.max_c(a0);
    let r_plus = r_t + r_a;
    let r_minus = r_t - r_a;
    let c = h + r_plus;
    let u = h * (h + 2.0 * r_plus);
    let v = c * c - r_minus * r_minus;
    let rr = r_a * r_t;
    let uv = u * v;
    -(c * (32.0 * hamaker * rr * rr * rr / 3.0)) / (uv * uv)
}

/// Sphere-plane van der Waals energy (J), the closed form behind Eq 2:
/// `W(h) = −H/6 [Rₐ/h + Rₐ/(h+2Rₐ) + ln(h/(h+2Rₐ))]`, evaluated without cancellation as
/// `−H/6 · k(2Rₐ/(h+2Rₐ))` (`hamaker_energy_kernel`). `h` is clamped to `a0`.
pub fn sphere_plane_energy(hamaker: f64, r_a: f64, h: f64, a0: f64) -> f64 {
    let h = h.max(a0);
    -hamaker / 6.0 * hamaker_energy_kernel(2.0 * r_a / (h + 2.0 * r_a))
}

/// Sphere-plane van der Waals force (N), **Eq 2 corrected** (docs/errata.md item 2).
///
/// `F = −H/6 {Rₐ/h² + Rₐ/(h+2Rₐ)² − 1/h + 1/(h+2Rₐ)}`: the print's `ln 1/(h+2Rₐ)` is a misprint
/// of `+1/(h+2Rₐ)`. The braces equal `4Rₐ³/(h(h+2Rₐ))²`, so it is evaluated as Hamaker's
/// `F = −2HRₐ³ / (3h²(h+2Rₐ)²)`. `h` is clamped to the interatomic cut-off `a0`.
pub fn sphere_plane_force<T: Real>(hamaker: f64, r_a: f64, h: T, a0: f64) -> T {
    let h = h.max_c(a0);
    let q = h * (h + 2.0 * r_a);
    -(T::cst(2.0 * hamaker * r_a * r_a * r_a / 3.0) / (q * q))
}

/// The Hamaker constant of bodies 1 and 2 across a medium 3 (the paper's water layer):
/// `H = ((H₁ − H₃)(H₂ − H₃))^{1/2}` (Israelachvili's combining rule, as in Sec 2.2.1). When the
/// product is negative (one body "below" the medium) the interaction is repulsive and the sign
/// is kept: `H = sign · |…|^{1/2}`. With no medium pass `h_medium = 0`.
pub fn combined_hamaker(h1: f64, h2: f64, h_medium: f64) -> f64 {
    let p = (h1 - h_medium) * (h2 - h_medium);
    p.signum() * p.abs().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const H: f64 = 1.0e-19;
    const A0: f64 = 0.165e-9;

    /// Central difference of an energy, with a step relative to h.
    fn minus_dwdh(w: impl Fn(f64) -> f64, h: f64) -> f64 {
        let dh = h * 1e-5;
        -(w(h + dh) - w(h - dh)) / (2.0 * dh)
    }

    fn log_grid() -> impl Iterator<Item = f64> {
        // 0.2 nm .. 1 µm, 60 points per decade-ish.
        (0..=220).map(|i| 0.2e-9 * 10f64.powf(i as f64 * (3.7 / 220.0)))
    }

    #[test]
    fn sphere_sphere_force_is_minus_energy_gradient() {
        for (rt, ra) in [(30e-9, 1e-6), (30e-9, 250e-9), (30e-9, 7e-9), (10e-9, 10e-9)] {
            for h in log_grid() {
                let f = sphere_sphere_force(H, rt, ra, h, A0);
                let g = minus_dwdh(|x| sphere_sphere_energy(H, rt, ra, x, A0), h);
                assert!(
                    (f - g).abs() <= 1e-6 * f.abs(),
                    "Rt={rt} Ra={ra} h={h}: F={f} -dW/dh={g}"
                );
            }
        }
    }

    #[test]
    fn sphere_plane_force_is_minus_energy_gradient() {
        for ra in [5e-9, 250e-9, 1e-6, 5e-6] {
            for h in log_grid() {
                let f = sphere_plane_force(H, ra, h, A0);
                let g = minus_dwdh(|x| sphere_plane_energy(H, ra, x, A0), h);
                assert!((f - g).abs() <= 1e-6 * f.abs(), "Ra={ra} h={h}: F={f} vs {g}");
            }
        }
    }

    #[test]
    fn corrected_eq1_differs_from_print_and_matches_braces() {
        // The corrected brace form, term by term, equals the cancellation-free form; the printed
        // signs give a force about 2x too strong at h = 10 nm (docs/errata.md item 1).
        let (rt, ra, h) = (30e-9, 1e-6, 10e-9);
        let rp = rt + ra;
        let rm = rt - ra;
        let c = h + rp;
        let u = h * (h + 2.0 * rp);
        let v = c * c - rm * rm;
        let corrected = -H * c / 3.0 * (2.0 * ra * rt / (u * u) + 2.0 * ra * rt / (v * v) - 1.0 / u + 1.0 / v);
        let printed = -H * c / 3.0 * (2.0 * ra * rt / (u * u) + 2.0 * ra * rt / (v * v) + 1.0 / u - 1.0 / v);
        let ours = sphere_sphere_force(H, rt, ra, h, A0);
        assert!((ours - corrected).abs() < 1e-9 * corrected.abs());
        let ratio = printed / corrected;
        assert!(ratio > 1.8 && ratio < 2.2, "printed/corrected = {ratio}");
    }

    #[test]
    fn derjaguin_limit_near_contact() {
        for (rt, ra) in [(30e-9, 1e-6), (30e-9, 250e-9), (20e-9, 7e-9)] {
            let r_eff = rt * ra / (rt + ra);
            // Relative corrections are O(h/R): at h = 1 pm (no cut-off) they are below 1e-3.
            let h = 1e-12;
            let f = sphere_sphere_force(H, rt, ra, h, 0.0);
            let d = -H * r_eff / (6.0 * h * h);
            assert!((f / d - 1.0).abs() < 1e-3, "sphere-sphere {f} vs Derjaguin {d}");
            let fp = sphere_plane_force(H, ra, h, 0.0);
            let dp = -H * ra / (6.0 * h * h);
            assert!((fp / dp - 1.0).abs() < 1e-3, "sphere-plane {fp} vs {dp}");
        }
    }

    #[test]
    fn far_field_power_laws() {
        // Sphere-sphere decays as h^-7, sphere-plane as h^-4 (Hamaker), far from contact.
        let (rt, ra) = (30e-9, 50e-9);
        let f1 = sphere_sphere_force(H, rt, ra, 100e-6, A0);
        let f2 = sphere_sphere_force(H, rt, ra, 200e-6, A0);
        assert!(((f1 / f2).log2() - 7.0).abs() < 0.01);
        let p1 = sphere_plane_force(H, ra, 100e-6, A0);
        let p2 = sphere_plane_force(H, ra, 200e-6, A0);
        assert!(((p1 / p2).log2() - 4.0).abs() < 0.01);
    }

    /// The kernel switches from its series to its closed form at x = 0.05, where the two agree
    /// to rounding: `Σ xⁿ(n−2)/(2n)` summed by hand against `(x/2)(1/(1−x) + 1) + ln(1−x)`.
    #[test]
    fn kernel_series_and_closed_form_agree() {
        for x in [0.01_f64, 0.0499, 0.05, 0.0501, 0.3] {
            let series: f64 = (3..200).map(|n| x.powi(n) * (n as f64 - 2.0) / (2.0 * n as f64)).sum();
            let closed = 0.5 * x * (1.0 / (1.0 - x) + 1.0) + (1.0 - x).ln();
            let k = hamaker_energy_kernel(x);
            assert!(
                (k / series - 1.0).abs() < 1e-12,
                "x = {x}: {k:e} vs the series {series:e}"
            );
            if x >= 0.0499 {
                assert!(
                    (k / closed - 1.0).abs() < 1e-9,
                    "x = {x}: {k:e} vs the closed form {closed:e}"
                );
            }
        }
    }

    #[test]
    fn cut_off_caps_the_force() {
        let at_a0 = sphere_plane_force(H, 1e-6, A0, A0);
        assert_eq!(sphere_plane_force(H, 1e-6, 0.0, A0), at_a0);
        assert_eq!(sphere_plane_force(H, 1e-6, -1e-9, A0), at_a0);
        assert!(at_a0.is_finite());
    }

    #[test]
    fn combining_rule() {
        assert!((combined_hamaker(18.65e-20, 6.5e-20, 3.7e-20) - (14.95e-20_f64 * 2.8e-20).sqrt()).abs() < 1e-30);
        assert!(combined_hamaker(2e-20, 6.5e-20, 3.7e-20) < 0.0);
    }

    proptest! {
        #[test]
        fn van_der_waals_is_finite_and_attractive(
            rt in 1e-9..1000e-9_f64,
            ra in 2e-9..10e-6_f64,
            h in -5e-9..100e-6_f64,
            hamaker in 1e-21..1e-18_f64,
        ) {
            let f = sphere_sphere_force(hamaker, rt, ra, h, A0);
            prop_assert!(f.is_finite() && f < 0.0, "sphere-sphere {}", f);
            let p = sphere_plane_force(hamaker, ra, h, A0);
            prop_assert!(p.is_finite() && p < 0.0, "sphere-plane {}", p);
        }
    }
}
