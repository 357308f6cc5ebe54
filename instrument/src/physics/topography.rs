//! The substrate's topography: a tilted plane with a random roughness. The paper's silicon "is
//! not perfectly flat" (Sec 5, Fig 15): the deflection while pushing drifts with stage position.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// Number of sinusoids in the roughness.
const WAVES: usize = 12;

/// One sinusoidal component of the roughness: `a cos(kx·x + ky·y + φ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Wave {
    amplitude: f64,
    kx: f64,
    ky: f64,
    phase: f64,
}

/// Substrate height `z_s(x, y) = t_x x + t_y y + Σ aᵢ cos(kᵢ·r + φᵢ)` (m) above the plane through
/// the stage origin.
#[derive(Debug, Clone, PartialEq)]
pub struct Topography {
    /// Slope along x (m/m).
    pub tilt_x: f64,
    /// Slope along y (m/m).
    pub tilt_y: f64,
    waves: Vec<Wave>,
}

impl Topography {
    /// A flat, level substrate.
    pub fn flat() -> Topography {
        Topography {
            tilt_x: 0.0,
            tilt_y: 0.0,
            waves: Vec::new(),
        }
    }

    /// A tilted plane with roughness of RMS `rms` (m) made of sinusoids whose wavelengths spread
    /// over `[λ/2, 2λ]` around `wavelength` (m), in random directions with random phases drawn
    /// from `seed`. Each of the `N` waves has amplitude `rms·sqrt(2/N)`, so the RMS over a large
    /// area is `rms`. With `rms = 0` no wave is kept (a left-out term is never evaluated).
    pub fn new(tilt_x: f64, tilt_y: f64, rms: f64, wavelength: f64, seed: u64) -> Topography {
        let mut waves = Vec::new();
        if rms > 0.0 {
            let mut rng = SmallRng::seed_from_u64(seed);
            let a = rms * (2.0 / WAVES as f64).sqrt();
            for _ in 0..WAVES {
                let lambda = wavelength * 2f64.powf(rng.random_range(-1.0..=1.0));
                let dir = rng.random_range(0.0..std::f64::consts::TAU);
                let k = std::f64::consts::TAU / lambda;
                waves.push(Wave {
                    amplitude: a,
                    kx: k * dir.cos(),
                    ky: k * dir.sin(),
                    phase: rng.random_range(0.0..std::f64::consts::TAU),
                });
            }
        }
        Topography { tilt_x, tilt_y, waves }
    }

    /// Whether the substrate is flat and level.
    pub fn is_flat(&self) -> bool {
        self.tilt_x == 0.0 && self.tilt_y == 0.0 && self.waves.is_empty()
    }

    /// Height `z_s(x, y)` (m).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let mut z = self.tilt_x * x + self.tilt_y * y;
        for w in &self.waves {
            z += w.amplitude * (w.kx * x + w.ky * y + w.phase).cos();
        }
        z
    }

    /// The tilt's plane at `(x, y)` (m): the height without the roughness.
    pub fn plane(&self, x: f64, y: f64) -> f64 {
        self.tilt_x * x + self.tilt_y * y
    }

    /// The most the roughness can add to the plane (m): the sum of its waves' amplitudes.
    pub fn roughness_bound(&self) -> f64 {
        self.waves.iter().map(|w| w.amplitude.abs()).sum()
    }

    /// An upper bound on the surface's curvature (1/m): `Σ a k²` over the waves (a plane has
    /// none).
    pub fn curvature_bound(&self) -> f64 {
        self.waves
            .iter()
            .map(|w| w.amplitude.abs() * (w.kx * w.kx + w.ky * w.ky))
            .sum()
    }

    /// Gradient `(∂z_s/∂x, ∂z_s/∂y)`.
    pub fn gradient(&self, x: f64, y: f64) -> (f64, f64) {
        let (mut gx, mut gy) = (self.tilt_x, self.tilt_y);
        for w in &self.waves {
            let s = -w.amplitude * (w.kx * x + w.ky * y + w.phase).sin();
            gx += s * w.kx;
            gy += s * w.ky;
        }
        (gx, gy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilt_is_a_plane() {
        let t = Topography::new(1e-3, -2e-3, 0.0, 5e-6, 1);
        assert!(t.waves.is_empty());
        assert!((t.height(10e-6, 5e-6) - (1e-8 - 1e-8)).abs() < 1e-20);
        assert_eq!(t.gradient(3e-6, 4e-6), (1e-3, -2e-3));
        assert!(Topography::flat().is_flat());
        assert!(Topography::new(0.0, 0.0, 0.0, 5e-6, 1).is_flat());
        // Any one of a tilt along x, one along y, or roughness makes it not flat.
        assert!(!Topography::new(1e-3, 0.0, 0.0, 5e-6, 1).is_flat());
        assert!(!Topography::new(0.0, -1e-3, 0.0, 5e-6, 1).is_flat());
        assert!(!Topography::new(0.0, 0.0, 1e-9, 5e-6, 1).is_flat());
    }

    #[test]
    fn roughness_has_the_requested_rms_and_is_reproducible() {
        let t = Topography::new(0.0, 0.0, 2e-9, 5e-6, 7);
        let (mut sum, mut sum2, n) = (0.0, 0.0, 200);
        for i in 0..n {
            for j in 0..n {
                let z = t.height(i as f64 * 0.5e-6, j as f64 * 0.5e-6);
                sum += z;
                sum2 += z * z;
            }
        }
        let m = (n * n) as f64;
        let rms = (sum2 / m - (sum / m).powi(2)).sqrt();
        // A 100 µm square holds 10-40 wavelengths: the sample RMS is within 15 % of 2 nm.
        assert!((rms - 2e-9).abs() < 0.3e-9, "rms {rms:e}");
        assert_eq!(t, Topography::new(0.0, 0.0, 2e-9, 5e-6, 7));
        assert_ne!(t, Topography::new(0.0, 0.0, 2e-9, 5e-6, 8));
    }

    #[test]
    fn gradient_matches_finite_difference() {
        let t = Topography::new(1e-3, 0.5e-3, 3e-9, 4e-6, 3);
        let (x, y, h) = (12e-6, 7e-6, 1e-10);
        let (gx, gy) = t.gradient(x, y);
        let fx = (t.height(x + h, y) - t.height(x - h, y)) / (2.0 * h);
        let fy = (t.height(x, y + h) - t.height(x, y - h)) / (2.0 * h);
        assert!((gx - fx).abs() < 1e-6 && (gy - fy).abs() < 1e-6);
    }
}
