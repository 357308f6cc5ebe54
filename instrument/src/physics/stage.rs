//! Piezo stage dynamics along the push axis, Eq 13.

/// A closed-loop piezo stage axis (the paper's P-762.3L: `f_y = 250 Hz`, `Q_y = 20`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stage {
    /// Resonant frequency `f_y` (Hz).
    pub f_y: f64,
    /// Amplification factor `Q_y`.
    pub q_y: f64,
    /// Stage + sample moving mass `m_s` (kg).
    pub mass: f64,
}

impl Stage {
    /// `ω_y = 2π f_y` (rad/s).
    pub fn omega(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.f_y
    }

    /// Axis stiffness `k_s = m_s ω_y²` (N/m), from `f_y = sqrt(k_s/m_s)/(2π)`.
    pub fn stiffness(&self) -> f64 {
        self.mass * self.omega().powi(2)
    }

    /// **Eq 13, made dimensionally consistent**: `ÿ_s/ω_y² + ẏ_s/(ω_y Q_y) + y_s = y_ref − f_as/k_s`.
    ///
    /// The print writes `τ_y − f_as` on the right, adding a force to a position; here `τ_y` is the
    /// commanded position `y_ref` of the closed-loop stage and the friction load `f_as` acts
    /// through the axis stiffness `k_s`. Returns `ÿ_s` (m/s²).
    pub fn acceleration(&self, y: f64, v: f64, y_ref: f64, load: f64) -> f64 {
        let w = self.omega();
        w * w * (y_ref - load / self.stiffness() - y) - w / self.q_y * v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn static_deflection_under_load() {
        let s = Stage {
            f_y: 250.0,
            q_y: 20.0,
            mass: 0.05,
        };
        // At rest the stage sits at y_ref − f/k_s.
        let k = s.stiffness();
        assert!(s.acceleration(1e-6 - 1e-6 / k, 0.0, 1e-6, 1e-6).abs() < 1e-6);
    }

    #[test]
    fn the_papers_stage_by_hand() {
        // ω = 2π·250 Hz = 1570.80 rad/s; k_s = 0.05 kg · ω² = 123 370 N/m.
        let s = Stage {
            f_y: 250.0,
            q_y: 20.0,
            mass: 0.05,
        };
        assert!((s.omega() - 1570.796).abs() < 0.001, "{}", s.omega());
        assert!((s.stiffness() - 123_370.0).abs() < 1.0, "{}", s.stiffness());
        // 1 µm from its reference at rest: ÿ = −ω²·1 µm = −2.4674 m/s².
        assert!((s.acceleration(1e-6, 0.0, 0.0, 0.0) + 2.4674).abs() < 1e-4);
    }

    #[test]
    fn resonance_and_damping() {
        // The homogeneous equation is a damped oscillator with ω = 2π·250 Hz and ζ = 1/(2Q).
        let s = Stage {
            f_y: 250.0,
            q_y: 20.0,
            mass: 0.05,
        };
        let w = s.omega();
        assert!((s.acceleration(1.0, 0.0, 0.0, 0.0) + w * w).abs() < 1e-6);
        assert!((s.acceleration(0.0, 1.0, 0.0, 0.0) + w / 20.0).abs() < 1e-9);
    }
}
