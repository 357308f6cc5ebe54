//! The piezoresistive deflection sensor (Sec 4): only `ζ_z` is measurable, as a voltage.

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

#[cfg(test)]
mod tests {
    use super::*;

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
