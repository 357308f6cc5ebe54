//! The tapping tip's shape: a spherical apex of radius `Rₜ` on a cone of half-angle `θ`.
//!
//! Height of the tip surface above its apex at lateral distance `r` from its axis:
//!
//! ```text
//! P(r) = Rₜ − sqrt(Rₜ² − r²)                       r ≤ r_c = Rₜ cos θ   (the apex sphere)
//! P(r) = Rₜ (1 − sin θ) + (r − Rₜ cos θ) cot θ     r > r_c              (the cone's flank)
//! ```
//!
//! The cone is tangent to the sphere at `r_c`, where both slopes are `cot θ`. `θ = 0` is a
//! hemisphere on a cylinder: `P = ∞` beyond `Rₜ`. The cone is taken as infinitely tall (a real
//! tip is a few µm high, `L_z`, more than the particles the scenes hold).

/// A spherical apex of radius `radius` (m) on a cone of half-angle `half_angle` (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tip {
    /// Apex radius `Rₜ` (m).
    pub radius: f64,
    /// Cone half-angle `θ` (rad), in `[0, π/2)`.
    pub half_angle: f64,
}

impl Tip {
    /// Lateral radius `r_c = Rₜ cos θ` where the apex sphere meets the cone (m).
    pub fn apex_edge(&self) -> f64 {
        self.radius * self.half_angle.cos()
    }

    /// Height `P(r)` of the tip surface above its apex at lateral distance `r` (m).
    pub fn profile(&self, r: f64) -> f64 {
        let (rt, th) = (self.radius, self.half_angle);
        let rc = self.apex_edge();
        if r <= rc {
            rt - (rt * rt - r * r).max(0.0).sqrt()
        } else if th == 0.0 {
            f64::INFINITY
        } else {
            rt * (1.0 - th.sin()) + (r - rc) / th.tan()
        }
    }

    /// The same tip grown by `ra` in every direction (Minkowski sum with a ball of radius
    /// `ra`): apex radius `Rₜ + ra`, same half-angle, same sphere centre. A ball of radius `ra`
    /// touches the tip exactly when its centre lies on the grown tip's surface.
    pub fn grown(&self, ra: f64) -> Tip {
        Tip {
            radius: self.radius + ra,
            half_angle: self.half_angle,
        }
    }

    /// Height above the substrate of the image of a sphere of radius `ra` resting on a flat
    /// substrate, at lateral distance `d` from its centre (m), where the tip touches the sphere:
    /// `2Rₐ − P'(d)` with `P'` the profile of [`Tip::grown`]`(ra)` (derivation in
    /// [`crate::scan::sphere_image`]). Negative where the tip touches the substrate instead.
    pub fn sphere_image_height(&self, ra: f64, d: f64) -> f64 {
        2.0 * ra - self.grown(ra).profile(d)
    }

    /// Whether the whole image of a sphere of radius `ra` comes from the apex sphere (down to
    /// the substrate): `Rₐ ≤ Rₜ (1 − sin θ)/(1 + sin θ)`. Larger spheres are imaged by the flank.
    pub fn apex_only(&self, ra: f64) -> bool {
        let s = self.half_angle.sin();
        ra <= self.radius * (1.0 - s) / (1.0 + s)
    }

    /// Lateral distance where the profile reaches height `h ≥ 0` (m), the inverse of
    /// [`Tip::profile`]: `sqrt(Rₜ² − (Rₜ − h)²)` on the apex sphere, `r_c + (h − Rₜ(1 − sin θ))
    /// tan θ` on the flank.
    pub fn profile_inverse(&self, h: f64) -> f64 {
        let (rt, th) = (self.radius, self.half_angle);
        let h_edge = rt * (1.0 - th.sin());
        if h <= h_edge {
            (rt * rt - (rt - h).powi(2)).max(0.0).sqrt()
        } else {
            self.apex_edge() + (h - h_edge) * th.tan()
        }
    }

    /// Apparent width (m) of a sphere of radius `ra` on a flat substrate at `fraction` of its
    /// apparent height `2Rₐ`: twice the `d` where `2Rₐ − P'(d) = fraction·2Rₐ`.
    pub fn sphere_width_at(&self, ra: f64, fraction: f64) -> f64 {
        2.0 * self.grown(ra).profile_inverse((1.0 - fraction) * 2.0 * ra)
    }

    /// Apparent base width (m) of a sphere of radius `ra` on a flat substrate: twice the `d`
    /// where [`Tip::sphere_image_height`] is 0, i.e. `P'(d) = 2Rₐ`. On the apex sphere this is
    /// `2 sqrt(R'² − (R' − 2Rₐ)²) = 4 sqrt(Rₐ Rₜ)`, the classic result; on the flank
    /// `2 (R' cos θ + (2Rₐ − R'(1 − sin θ)) tan θ)` with `R' = Rₜ + Rₐ`.
    pub fn sphere_base_width(&self, ra: f64) -> f64 {
        self.sphere_width_at(ra, 0.0)
    }

    /// The radius whose [`Tip::sphere_width_at`] `fraction` is `width` (bisection: the width
    /// grows with the radius). `None` when `width` is not positive and finite.
    pub fn radius_from_width(&self, width: f64, fraction: f64) -> Option<f64> {
        if !(width.is_finite() && width > 0.0) {
            return None;
        }
        let w = |ra: f64| self.sphere_width_at(ra, fraction);
        let mut hi = width;
        while w(hi) < width {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        while hi - lo > 1e-12 * hi {
            let mid = 0.5 * (lo + hi);
            if w(mid) < width {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(0.5 * (lo + hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NM: f64 = 1e-9;

    fn tip(rt_nm: f64, deg: f64) -> Tip {
        Tip {
            radius: rt_nm * NM,
            half_angle: deg.to_radians(),
        }
    }

    #[test]
    fn profile_is_continuous_and_smooth_at_the_tangent_point() {
        let t = tip(30.0, 20.0);
        let rc = t.apex_edge();
        let e = 1e-15;
        assert!((t.profile(rc - e) - t.profile(rc + e)).abs() < 1e-14);
        // Slopes on both sides equal cot θ (the tangent condition).
        let h = 1e-13;
        let left = (t.profile(rc) - t.profile(rc - h)) / h;
        let right = (t.profile(rc + h) - t.profile(rc)) / h;
        let cot = 1.0 / t.half_angle.tan();
        assert!(
            (left - cot).abs() < 1e-3 * cot && (right - cot).abs() < 1e-6 * cot,
            "{left} {right}"
        );
        assert_eq!(t.profile(0.0), 0.0);
        assert!(tip(30.0, 0.0).profile(31.0 * NM).is_infinite());
    }

    #[test]
    fn small_sphere_width_is_four_sqrt_ra_rt() {
        // The textbook tip-convolution result on the apex sphere: 2Rₐ high, 4 sqrt(Rₐ Rₜ) wide.
        let t = tip(30.0, 20.0);
        let ra = 10.0 * NM;
        assert!(t.apex_only(ra));
        assert!((t.sphere_base_width(ra) - 4.0 * (ra * t.radius).sqrt()).abs() < 1e-18);
        assert!((t.sphere_image_height(ra, 0.0) - 2.0 * ra).abs() < 1e-20);
        assert!(t.sphere_image_height(ra, 0.5 * t.sphere_base_width(ra)).abs() < 1e-18);
        // A hemispherical tip on a cylinder (θ = 0) keeps the relation up to Rₐ = Rₜ.
        let c = tip(30.0, 0.0);
        assert!(c.apex_only(30.0 * NM));
        assert!((c.sphere_base_width(30.0 * NM) - 4.0 * 30.0 * NM).abs() < 1e-18);
    }

    #[test]
    fn large_sphere_width_comes_from_the_flank() {
        let t = tip(30.0, 20.0);
        let ra = 1000.0 * NM;
        assert!(!t.apex_only(ra));
        let w = t.sphere_base_width(ra);
        // Wider than the apex-only formula would say, and the image height is 0 there.
        assert!(w > 4.0 * (ra * t.radius).sqrt());
        assert!(t.sphere_image_height(ra, 0.5 * w).abs() < 1e-15);
        // By hand: R' = 1030 nm, d = R' cos 20° + (2000 − R'(1 − sin 20°)) tan 20°.
        let th = 20f64.to_radians();
        let d = 1030.0 * th.cos() + (2000.0 - 1030.0 * (1.0 - th.sin())) * th.tan();
        assert!((w - 2.0 * d * NM).abs() < 1e-15);
        // The inverse recovers the radius in both regimes.
        for ra in [5.0 * NM, 10.0 * NM, 500.0 * NM, ra] {
            for f in [0.0, 0.5] {
                let back = t.radius_from_width(t.sphere_width_at(ra, f), f).unwrap();
                assert!((back - ra).abs() < 1e-9 * ra, "{ra:e} at {f} -> {back:e}");
            }
        }
        assert_eq!(t.radius_from_width(0.0, 0.5), None);
        // At half height the apex-regime image is the grown sphere's: 2 sqrt(R'² − (R' − Rₐ)²).
        let (ra, g) = (10.0 * NM, 40.0 * NM);
        let half = 2.0 * (g * g - (g - ra).powi(2)).sqrt();
        assert!((t.sphere_width_at(ra, 0.5) - half).abs() < 1e-18);
    }

    /// docs/manipulation.md, "Scans (`nanopush scan`)": a sphere is imaged by the apex alone up to
    /// `Rₐ = Rₜ(1 − sin θ)/(1 + sin θ)`, 14.7 nm for a 30 nm tip at 20°; beyond it, by the flank.
    #[test]
    fn the_apex_regime_ends_where_the_cone_takes_over() {
        let t = tip(30.0, 20.0);
        let s = 20f64.to_radians().sin();
        let edge = 30.0 * NM * (1.0 - s) / (1.0 + s);
        assert!((edge - 14.7 * NM).abs() <= 0.05 * NM, "{edge:e}");
        assert!(t.apex_only(edge) && t.apex_only(14.70 * NM));
        assert!(!t.apex_only(edge * (1.0 + 1e-12)) && !t.apex_only(14.72 * NM));
    }
}
