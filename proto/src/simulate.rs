//! The document of `nanopush simulate --json`.

use serde::{Deserialize, Serialize};

/// `nanopush simulate --json`: one push at constant stage speed (SI units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulateReport {
    /// Always `"nanopush.simulate"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// Integration method.
    pub method: String,
    /// Relative tolerance.
    pub rtol: f64,
    /// Simulated time (s).
    pub duration: f64,
    /// Stage speed `V` (m/s).
    pub speed: f64,
    /// Final particle position along the push (m).
    pub final_particle_y: f64,
    /// Final stage travel (m).
    pub final_stage: f64,
    /// Measured deflection `ζ_z`, mean over the last 20 % of the run (m): the steady value (the
    /// mean is what Sec 3 prescribes when the motion is periodic).
    pub steady_zeta_z: f64,
    /// Shearing time `t*`: first stick → slip of the particle on the substrate (s); `null` if it
    /// never sheared.
    pub shearing_time: Option<f64>,
    /// Friction phase at the end: `stick`, `slip` or `roll`.
    pub final_phase: String,
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps.
    pub rejected: u64,
    /// Jacobian evaluations.
    pub jacobians: u64,
    /// LU factorizations.
    pub factorizations: u64,
    /// Mode switches (events).
    pub events: u64,
    /// Estimated global error of the final particle y (m): the difference from a rerun at
    /// `rtol/100` (at least 1e-12) with the same method and sampling; `null` when the rerun
    /// failed (below double precision's reach).
    pub estimated_error_y: Option<f64>,
    /// Estimated global error of the final ζ_z (m), likewise.
    pub estimated_error_zeta_z: Option<f64>,
    /// Wall time of the run (s), the rerun excluded.
    pub wall_time: f64,
    /// Simulated time per wall time.
    pub real_time_factor: f64,
    /// Rows written to the trace CSV (0 without `--out`).
    pub trace_rows: usize,
}
