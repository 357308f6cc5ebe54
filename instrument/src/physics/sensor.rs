//! The piezoresistive deflection sensor (Sec 4): only `ζ_z` is measurable, as a voltage.

use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand_distr::{Distribution, Normal};

/// A linear piezoresistive readout of `ζ_z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Output at zero deflection (V); the paper's instrument reads −0.2 V (Fig 9).
    pub baseline: f64,
    /// Gain (V/m).
    pub gain: f64,
    /// White noise RMS (V).
    pub noise_rms: f64,
}

impl Sensor {
    /// The noiseless reading (V) of a deflection `ζ_z` (m): `U = U₀ + g ζ_z`.
    pub fn volts(&self, zeta_z: f64) -> f64 {
        self.baseline + self.gain * zeta_z
    }

    /// The deflection (m) a noiseless reading stands for.
    pub fn deflection(&self, volts: f64) -> f64 {
        (volts - self.baseline) / self.gain
    }
}

/// Full scale of the readout's analogue-to-digital converter (V): `±10 V`, the input range of
/// the usual AFM controller ADCs.
pub const FULL_SCALE: f64 = 10.0;

/// The instrument's readout of the sensor at the 1 kHz sampling: the linear reading plus white
/// noise (Gaussian, `noise_rms`) and a periodic perturbation `A sin(2πft)` (the hardware and
/// environment noise of Fig 15), digitized by an ADC that saturates at `±full_scale`:
/// `U = clamp(U₀ + g ζ_z + A sin(2πft) + n, −U_fs, U_fs)`. Seeded, so a run is reproducible.
#[derive(Debug, Clone)]
pub struct Readout {
    /// The sensor.
    pub sensor: Sensor,
    /// Perturbation amplitude `A` (V).
    pub perturbation: f64,
    /// Perturbation frequency `f` (Hz).
    pub perturbation_hz: f64,
    /// The ADC's full scale `U_fs` (V): readings saturate at `±U_fs`.
    pub full_scale: f64,
    rng: SmallRng,
    normal: Option<Normal<f64>>,
}

impl Readout {
    /// A readout with the given perturbation and noise seed.
    pub fn new(sensor: Sensor, perturbation: f64, perturbation_hz: f64, seed: u64) -> Readout {
        Readout {
            normal: (sensor.noise_rms > 0.0).then(|| Normal::new(0.0, sensor.noise_rms).expect("finite σ > 0")),
            sensor,
            perturbation,
            perturbation_hz,
            full_scale: FULL_SCALE,
            rng: SmallRng::seed_from_u64(seed),
        }
    }

    /// The same readout with an ADC of full scale `±full_scale` (V).
    pub fn with_full_scale(mut self, full_scale: f64) -> Readout {
        self.full_scale = full_scale;
        self
    }

    /// Whether a reading sits on one of the ADC's rails.
    pub fn saturated(&self, volts: f64) -> bool {
        volts.abs() >= self.full_scale
    }

    /// A noiseless, unperturbed readout with no ADC limit (for tests and the model's own
    /// predictions).
    pub fn ideal(sensor: Sensor) -> Readout {
        Readout::new(
            Sensor {
                noise_rms: 0.0,
                ..sensor
            },
            0.0,
            50.0,
            0,
        )
        .with_full_scale(f64::INFINITY)
    }

    /// The reading (V) of deflection `ζ_z` (m) at time `t` (s).
    pub fn read(&mut self, t: f64, zeta_z: f64) -> f64 {
        let mut u = self.sensor.volts(zeta_z);
        if self.perturbation != 0.0 {
            u += self.perturbation * (std::f64::consts::TAU * self.perturbation_hz * t).sin();
        }
        if let Some(n) = &self.normal {
            u += n.sample(&mut self.rng);
        }
        u.clamp(-self.full_scale, self.full_scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readout_noise_and_perturbation() {
        let s = Sensor {
            baseline: -0.2,
            gain: -0.05e9,
            noise_rms: 0.005,
        };
        let mut r = Readout::new(s, 0.02, 50.0, 3);
        let n = 20_000;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for k in 0..n {
            let t = k as f64 * 1e-3;
            let e = r.read(t, 0.0) - s.volts(0.0) - 0.02 * (std::f64::consts::TAU * 50.0 * t).sin();
            sum += e;
            sum2 += e * e;
        }
        let mean = sum / n as f64;
        let rms = (sum2 / n as f64 - mean * mean).sqrt();
        // 20 000 samples: the mean within 4σ/√n, the RMS within 3 %.
        assert!(mean.abs() < 4.0 * 0.005 / (n as f64).sqrt(), "mean {mean}");
        assert!((rms - 0.005).abs() < 0.00015, "rms {rms}");
        let mut ideal = Readout::ideal(s);
        assert_eq!(ideal.read(0.123, 1e-9), s.volts(1e-9));
    }

    #[test]
    fn the_adc_saturates_at_its_full_scale() {
        let s = Sensor {
            baseline: -0.2,
            gain: -0.8e9,
            noise_rms: 0.005,
        };
        let mut r = Readout::new(s, 0.0, 50.0, 1).with_full_scale(10.0);
        // −548 nm of deflection would read +438 V on a linear sensor: the ADC's rail is +10 V.
        assert_eq!(r.read(0.0, -548e-9), 10.0);
        assert_eq!(r.read(0.0, 548e-9), -10.0);
        assert!(r.saturated(10.0) && r.saturated(-10.0) && !r.saturated(9.99));
        // Inside the range the reading is linear (within the noise).
        assert!((r.read(0.0, 1e-9) - s.volts(1e-9)).abs() < 0.03);
        assert_eq!(Readout::new(s, 0.0, 50.0, 1).full_scale, FULL_SCALE);
        // docs/manipulation.md, "Physics guarded every tick": `sensor.full_scale_v`, default ±10 V
        // (no shipped scene sets it).
        assert_eq!(FULL_SCALE, 10.0);
        assert_eq!(crate::scene::Scene::default_scene().readout().full_scale, 10.0);
    }

    #[test]
    fn reading_round_trip() {
        let s = Sensor {
            baseline: -0.2,
            gain: -0.05e9,
            noise_rms: 0.0,
        };
        assert_eq!(s.volts(0.0), -0.2);
        // Fig 9's contact set point −1.5 V is 26 nm of deflection at −0.05 V/nm.
        assert!((s.deflection(-1.5) - 26e-9).abs() < 1e-18);
    }
}
