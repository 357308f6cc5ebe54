//! The documents of `nanopush model [--force-curve] --json`.

use serde::{Deserialize, Serialize};

/// `nanopush model --json`: the scene's derived quantities (SI units throughout).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelReport {
    /// Always `"nanopush.model"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// Compliance coefficient `c₁` (Eq 10).
    pub c1: f64,
    /// `c₂` (Eq 10).
    pub c2: f64,
    /// `c₃` (Eq 10).
    pub c3: f64,
    /// `k_y = k_c/c₂` (N/m).
    pub k_y: f64,
    /// `k_z = k_c` (N/m).
    pub k_z: f64,
    /// `k_yz = k_c/c₃` (N/m).
    pub k_yz: f64,
    /// Cantilever effective mass `m_c* = k_z/(4π²f_r²)` (kg).
    pub m_c: f64,
    /// Cantilever damping `b_y = b_z = 2πf_r m_c*/Q_c` (N·s/m).
    pub b_y: f64,
    /// Particle-substrate tangential contact stiffness `k_as* = 8RₐG*` (N/m).
    pub k_as: f64,
    /// Paper's adhesion `A_as = 4πRₐγ_L` (N).
    pub a_as: f64,
    /// Paper's adhesion `A_ta = 2πR̃γ_L` (N).
    pub a_ta: f64,
    /// Adhesion the model's particle-substrate friction sees, from the included force terms (N).
    pub a_as_model: f64,
    /// Tip-particle adhesion from the included force terms (N).
    pub a_ta_model: f64,
    /// Effective radius `R̃ = RₜRₐ/(Rₜ+Rₐ)` (m).
    pub r_eff: f64,
    /// Kelvin radius `r₁` (m); 0 when no meniscus can form.
    pub r1: f64,
    /// Meniscus formation gap `L_t = 2r₁` (m).
    pub meniscus_formation_gap: f64,
    /// The JKR meniscus breaking length `δ` of the tip-particle pair (Eq 3) (m).
    pub meniscus_breaking_length: f64,
    /// Shearing point `y*` (Eq 15) with the paper's `A_as = 4πRₐγ_L` (m); `null` when the
    /// particle cannot be pushed.
    pub y_star: Option<f64>,
    /// `y*` (Eq 15) with the adhesion of the terms the scene includes (`a_as_model`) (m).
    pub y_star_model: Option<f64>,
    /// Eq 9 lower bound on `μ_as^s`.
    pub mu_lower_bound: f64,
    /// Eq 16 upper bound on `μ_as^s` (`null` when unbounded: α = 0 or k_y ≤ k_z).
    pub mu_upper_bound: Option<f64>,
    /// The scene's `μ_as^s`.
    pub mu_as_static: f64,
    /// Whether `μ_as^s` lies in the Eq 16 window.
    pub mu_feasible: bool,
    /// Eq 8: the particle does not stick to the tip.
    pub no_sticking_to_tip: bool,
    /// Particle mass `mₐ` (kg).
    pub particle_mass: f64,
    /// Particle-substrate contact period `2π sqrt(mₐ/k_as*)` (s): the stiffest time scale.
    pub contact_period: f64,
    /// Cantilever period `1/f_r` (s).
    pub cantilever_period: f64,
    /// Stage period `1/f_y` (s).
    pub stage_period: f64,
    /// Dimension of the pushing model's state vector for this scene.
    pub state_dimension: usize,
    /// Names of the states, in order.
    pub states: Vec<String>,
    /// Eq 18 steady state with the scene's adhesion (`a_as_model`, `a_ta_model`); `null` when
    /// there is none (see `steady_state_error`).
    pub steady_state: Option<SteadyStateReport>,
    /// Why Eq 18 has no steady state, when it has none.
    pub steady_state_error: Option<String>,
    /// Scene warnings (e.g. μ outside the Eq 16 window).
    pub warnings: Vec<String>,
}

/// The Eq 18 kinetic steady state (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SteadyStateReport {
    /// Tip-particle normal force `F_ta` (N).
    pub normal_ta: f64,
    /// Friction `f_ta = f_as` (N).
    pub friction_ta: f64,
    /// Particle `y` (m).
    pub y: f64,
    /// `ζ_y` (m).
    pub zeta_y: f64,
    /// `ζ_z` (m).
    pub zeta_z: f64,
    /// `β̃` (rad).
    pub beta_tilde: f64,
    /// Particle `z` (m).
    pub z: f64,
}

/// One point of a force curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceCurvePoint {
    /// Piezo distance (m).
    pub distance: f64,
    /// Tip-sample gap (m).
    pub gap: f64,
    /// Cantilever deflection (m).
    pub deflection: f64,
    /// Force on the tip (N), positive repulsive.
    pub force: f64,
    /// Meniscus present.
    pub meniscus: bool,
    /// In contact.
    pub contact: bool,
}

/// `nanopush model --force-curve --json`: the Fig 3 curve (SI units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForceCurveReport {
    /// Always `"nanopush.force_curve"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// Cantilever stiffness (N/m).
    pub k_c: f64,
    /// Tip radius (m).
    pub tip_radius: f64,
    /// Snap-in piezo distance (m), if any.
    pub snap_in_distance: Option<f64>,
    /// Pull-off force (N).
    pub pull_off_force: f64,
    /// Pull-off piezo distance (m), if any.
    pub pull_off_distance: Option<f64>,
    /// Approach branch.
    pub approach: Vec<ForceCurvePoint>,
    /// Retraction branch.
    pub retraction: Vec<ForceCurvePoint>,
}
