//! How a push ended: its typed failure, the contact search's steps, and the summary.

/// Why a run failed. Each ends with the tip retracted.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Failure {
    /// The z approach went further than the start height plus margin without touching.
    #[error("no substrate found within {range_um:.2} µm of z approach")]
    NoSubstrate {
        /// Approach travelled (µm).
        range_um: f64,
    },
    /// The contact search travelled its whole range without reaching the set point.
    #[error("no contact within range: {travel_um:.2} µm searched ({steps} steps) without reaching ζ_set")]
    NoContact {
        /// Search travel (µm).
        travel_um: f64,
        /// Steps made.
        steps: u32,
    },
    /// The deflection fell back to the baseline during the push: the tip lost the particle.
    #[error("particle lost after {travel_um:.3} µm of push: the deflection fell back to the baseline")]
    ParticleLost {
        /// Push travel (µm).
        travel_um: f64,
    },
    /// The deflection went beyond the safety limit, or the reading saturated the readout on
    /// either side (`limit` is then the rail): emergency retract.
    #[error("deflection {volts:.3} V at or beyond the limit {limit:.3} V in phase {phase}: emergency retract")]
    DeflectionLimit {
        /// Reading (V).
        volts: f64,
        /// Limit (V).
        limit: f64,
        /// Phase it happened in.
        phase: &'static str,
    },
    /// The push travelled well past its distance without a separation (`t*`) being seen.
    #[error("no particle-substrate separation (t*) seen after {travel_um:.3} µm of push")]
    NoSeparation {
        /// Push travel (µm).
        travel_um: f64,
    },
    /// The tip was still held (the reading saturated, or beyond the substrate threshold, on the
    /// pull side) after rising further than its pull-off needs (see
    /// [`super::pull_off`]): lifted straight up.
    #[error(
        "the tip was still held {rise_nm:.1} nm above the detected substrate in phase {phase}, past the {bound_nm:.1} nm allowed for its pull-off: the reading stayed on the pull side"
    )]
    StillHeld {
        /// Rise above the detected substrate (nm).
        rise_nm: f64,
        /// The rise allowed (nm): `1.5 (F_ad/k_c + L_t + δ_b + a₀) + 10 nm` from the substrate,
        /// the start height in the retraction.
        bound_nm: f64,
        /// Phase it happened in.
        phase: &'static str,
    },
    /// The tip let go of the substrate above the parking height, and snapped back onto it coming
    /// down to the parking height.
    #[error(
        "the tip snapped back onto the substrate coming down to the parking height, {height_nm:.1} nm above where the approach detected it"
    )]
    SnappedBack {
        /// The parking height's rise above the detected substrate (nm).
        height_nm: f64,
    },
    /// The operator (or a shutdown) stopped the run.
    #[error("stopped: {reason}")]
    Stopped {
        /// Who or what stopped it.
        reason: &'static str,
    },
    /// The simulated instrument left physics (a solver-health guard tripped): see
    /// [`crate::afm::Unphysical`]. The push model is dropped where it last was physical.
    #[error("unphysical state in phase {phase}: {what} = {value:e} beyond its bound {limit:e}")]
    Unphysical {
        /// What was out of bounds.
        what: &'static str,
        /// Its value (SI).
        value: f64,
        /// The bound (SI).
        limit: f64,
        /// Phase it happened in.
        phase: &'static str,
    },
    /// A phase took longer than its time-out.
    #[error("time-out: phase {phase} took more than {timeout_s} s")]
    Timeout {
        /// Phase.
        phase: &'static str,
        /// Limit (s).
        timeout_s: f64,
    },
}

impl Failure {
    /// The failure's code in reports and the WebSocket protocol.
    pub fn code(&self) -> &'static str {
        match self {
            Failure::NoSubstrate { .. } => "no_substrate",
            Failure::NoContact { .. } => "no_contact",
            Failure::ParticleLost { .. } => "particle_lost",
            Failure::DeflectionLimit { .. } => "deflection_limit",
            Failure::NoSeparation { .. } => "no_separation",
            Failure::StillHeld { .. } => "still_held",
            Failure::SnappedBack { .. } => "snapped_back",
            Failure::Stopped { .. } => "stopped",
            Failure::Timeout { .. } => "timeout",
            Failure::Unphysical { .. } => "unphysical",
        }
    }
}

/// One step of the contact search, as Fig 9 plots it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchStep {
    /// Step number (1-based).
    pub step: u32,
    /// Reading at the end of the step (mean over the dwell), V.
    pub volts: f64,
}

/// The strategy's result.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Failure, if any (the tip is retracted either way).
    pub failure: Option<Failure>,
    /// Detected substrate height at the parking point (stage z, m).
    pub substrate_z: Option<f64>,
    /// Step at which the set point was reached.
    pub contact_step: Option<u32>,
    /// Stage position where the contact search stopped (m).
    pub contact_stage: Option<[f64; 3]>,
    /// Detected `t*` (s).
    pub t_star: Option<f64>,
    /// Estimated particle displacement at the end of the push (m).
    pub estimated_distance: f64,
    /// Stage travel of the push (m).
    pub push_travel: f64,
    /// Fig 9: the reading after each contact-search step.
    pub search: Vec<SearchStep>,
    /// Estimated particle centre at the end (m).
    pub estimated_particle: (f64, f64),
}
