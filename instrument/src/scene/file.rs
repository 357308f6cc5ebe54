//! The scene file as written: TOML, user units with the unit in each field's name.
//!
//! Every table rejects unknown keys, and every field is required (the default scene shows them
//! all), so a typo is an error, not a silently ignored setting.

use serde::{Deserialize, Serialize};

/// A whole scene file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Short name.
    pub name: String,
    /// What the scene is.
    pub description: String,
    /// The AFM tip.
    pub tip: TipFile,
    /// The cantilever.
    pub cantilever: CantileverFile,
    /// The substrate.
    pub substrate: SubstrateFile,
    /// The particles on the substrate (at least one).
    pub particles: Vec<ParticleFile>,
    /// Ambient conditions.
    pub environment: EnvironmentFile,
    /// Friction coefficients.
    pub friction: FrictionFile,
    /// The push.
    pub push: PushFile,
    /// The piezo stage.
    pub stage: StageFile,
    /// The deflection sensor.
    pub sensor: SensorFile,
    /// Which physics the scene includes.
    pub physics: PhysicsFile,
    /// `[strategy]`: the manipulation strategy of Sec 2.1 (defaults when absent).
    #[serde(default)]
    pub strategy: StrategyFile,
    /// Tapping-mode scans (optional: [`ScanFile::default`] when absent).
    #[serde(default)]
    pub scan: ScanFile,
    /// `[haptic]`: haptic z-control from a 1-DOF handle (optional: [`HapticFile::default`]).
    #[serde(default)]
    pub haptic: HapticFile,
}

/// `[haptic]`: the bilateral scaling and limits of haptic z-control (`control/bilateral.rs`).
/// Optional; every field has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HapticFile {
    /// Tip nanometres per handle millimetre (position scaling).
    pub nm_per_mm: f64,
    /// Force the hand feels at the scene's pull-off force (N): sets the force scaling.
    pub pull_off_at_hand_n: f64,
    /// Height above the detected surface the tip parks at when haptic z-control engages (nm).
    pub park_gap_nm: f64,
    /// Fastest the hand may move the tip's height (nm/s).
    pub max_speed_nm_per_s: f64,
    /// Highest the hand may take the tip above the detected surface (nm).
    pub max_height_nm: f64,
}

impl Default for HapticFile {
    /// 1 mm of handle = 10 nm of tip; the pull-off is felt as 1 N; the tip parks 100 nm above
    /// the surface (10 mm of handle); the hand moves it at most 1 µm/s (100 mm/s of handle, the
    /// strategy's own approach speed) and at most 300 nm above the surface.
    fn default() -> HapticFile {
        HapticFile {
            nm_per_mm: 10.0,
            pull_off_at_hand_n: 1.0,
            park_gap_nm: 100.0,
            max_speed_nm_per_s: 1000.0,
            max_height_nm: 300.0,
        }
    }
}

/// `[tip]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TipFile {
    /// Apex radius `Rₜ` (nm).
    pub radius_nm: f64,
    /// Young's modulus `Eₜ` (GPa).
    pub youngs_modulus_gpa: f64,
    /// Poisson's ratio `νₜ`.
    pub poisson_ratio: f64,
    /// Hamaker constant across vacuum (zJ = 1e-21 J).
    pub hamaker_zj: f64,
}

/// `[cantilever]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CantileverFile {
    /// Normal stiffness `k_c` (N/m).
    pub stiffness_n_per_m: f64,
    /// Width `L_x` (µm).
    pub width_um: f64,
    /// Length `L_y` (µm).
    pub length_um: f64,
    /// Tip height `L_z` (µm).
    pub tip_height_um: f64,
    /// Thickness `t_c` (µm).
    pub thickness_um: f64,
    /// First resonance `f_r` (kHz).
    pub resonance_khz: f64,
    /// Quality factor in air `Q_c`.
    pub quality_factor: f64,
    /// Tilt `α` (degrees).
    pub tilt_deg: f64,
}

/// `[substrate]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubstrateFile {
    /// Material name, for display.
    pub material: String,
    /// Young's modulus `E_s` (GPa).
    pub youngs_modulus_gpa: f64,
    /// Poisson's ratio `ν_s`.
    pub poisson_ratio: f64,
    /// Hamaker constant across vacuum (zJ).
    pub hamaker_zj: f64,
    /// Tilt of the substrate plane along x (mrad): its height rises `tilt·x` (Fig 15's drift).
    #[serde(default)]
    pub tilt_x_mrad: f64,
    /// Tilt along y (mrad).
    #[serde(default)]
    pub tilt_y_mrad: f64,
    /// RMS roughness (nm): a sum of sinusoids of random direction and phase (0 = flat).
    #[serde(default)]
    pub roughness_rms_nm: f64,
    /// Typical wavelength of the roughness (µm).
    #[serde(default = "default_roughness_wavelength_um")]
    pub roughness_wavelength_um: f64,
    /// Seed of the roughness pattern.
    #[serde(default = "default_seed")]
    pub roughness_seed: u64,
}

fn default_roughness_wavelength_um() -> f64 {
    5.0
}

fn default_seed() -> u64 {
    1
}

/// `[[particles]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleFile {
    /// Identifier, unique in the scene.
    pub id: u32,
    /// Material name, for display.
    pub material: String,
    /// Radius `Rₐ` (nm).
    pub radius_nm: f64,
    /// Position on the substrate, x (µm).
    pub x_um: f64,
    /// Position on the substrate, y (µm).
    pub y_um: f64,
    /// Young's modulus `Eₐ` (GPa).
    pub youngs_modulus_gpa: f64,
    /// Poisson's ratio `νₐ`.
    pub poisson_ratio: f64,
    /// Density (kg/m³).
    pub density_kg_per_m3: f64,
    /// Hamaker constant of its surface across vacuum (zJ).
    pub hamaker_zj: f64,
}

/// `[environment]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentFile {
    /// Relative humidity `P/Pₛ`, in [0, 1).
    pub relative_humidity: f64,
    /// Liquid (water) surface tension `γ_L` (mJ/m²).
    pub surface_tension_mj_per_m2: f64,
    /// Solid-liquid interface energy `γ_SL` (mJ/m²): the JKR work of adhesion of the solid
    /// contacts (Eq 3's `F_s-s`); 0 gives Hertz contacts.
    pub solid_liquid_energy_mj_per_m2: f64,
    /// Hamaker constant of the liquid layer (zJ), used in the combining rule when humid.
    pub medium_hamaker_zj: f64,
    /// Interatomic cut-off `a₀` (nm).
    pub interatomic_cutoff_nm: f64,
    /// Work-function voltage tip-particle `U` (V).
    pub tip_particle_voltage_v: f64,
    /// Work-function voltage particle-substrate `U` (V).
    pub particle_substrate_voltage_v: f64,
    /// Work-function voltage tip-substrate `U` (V).
    pub tip_substrate_voltage_v: f64,
}

/// `[friction]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionFile {
    /// `μ_as^s`.
    pub particle_substrate_static: f64,
    /// `μ_as^k`.
    pub particle_substrate_kinetic: f64,
    /// `μ_ta^s`.
    pub tip_particle_static: f64,
    /// `μ_ta^k`.
    pub tip_particle_kinetic: f64,
    /// Damping ratio ζ of the contacts: `b_as = 2ζ sqrt(k_as* mₐ)`, `b_ta = 2ζ sqrt(k_ta* mₐ)`.
    pub contact_damping_ratio: f64,
}

/// `[push]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PushFile {
    /// Id of the particle the model pushes.
    pub particle_id: u32,
    /// Tip-particle contact angle `β` (degrees); derived by the planner when absent (30°, the
    /// paper's, until then).
    #[serde(default = "default_contact_angle_deg")]
    pub contact_angle_deg: f64,
    /// Stage speed `V` (µm/s); derived by the planner when absent (1 µm/s, the paper's, until
    /// then).
    #[serde(default = "default_speed_um_per_s")]
    pub speed_um_per_s: f64,
}

fn default_contact_angle_deg() -> f64 {
    30.0
}

fn default_speed_um_per_s() -> f64 {
    1.0
}

/// `[stage]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageFile {
    /// Resonance `f_y` (Hz).
    pub resonance_hz: f64,
    /// Amplification factor `Q_y`.
    pub quality_factor: f64,
    /// Stage + sample moving mass (g).
    pub moving_mass_g: f64,
    /// Travel in x, y, z (µm).
    pub range_um: f64,
}

/// `[sensor]`: the piezoresistive measurement of `ζ_z`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFile {
    /// Output at zero deflection (V).
    pub baseline_v: f64,
    /// Gain (V per nm of `ζ_z`).
    pub gain_v_per_nm: f64,
    /// White noise, RMS (mV).
    pub noise_rms_mv: f64,
    /// Amplitude of the periodic perturbation (mV): hardware and environment noise (Fig 15).
    #[serde(default)]
    pub perturbation_mv: f64,
    /// Frequency of the periodic perturbation (Hz).
    #[serde(default = "default_perturbation_hz")]
    pub perturbation_hz: f64,
    /// Seed of the readout noise.
    #[serde(default = "default_seed")]
    pub noise_seed: u64,
    /// Full scale of the readout's ADC (V): readings saturate at ± this, and a saturated
    /// reading trips the deflection limit.
    #[serde(default = "default_full_scale")]
    pub full_scale_v: f64,
}

fn default_full_scale() -> f64 {
    crate::physics::sensor::FULL_SCALE
}

fn default_perturbation_hz() -> f64 {
    50.0
}

/// How a degree of freedom enters the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DofFile {
    /// With inertia.
    Dynamic,
    /// At force balance (no inertia).
    QuasiStatic,
    /// Left out.
    Off,
}

/// `[physics]`: which force terms and degrees of freedom the scene includes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsFile {
    /// Van der Waals (Eq 1, 2).
    pub van_der_waals: bool,
    /// Capillary (Eq 3).
    pub capillary: bool,
    /// Electrostatic (Eq 4).
    pub electrostatic: bool,
    /// Particle position along the push: `dynamic` or `quasi_static`.
    pub particle_y: DofFile,
    /// Particle height: `dynamic`, `quasi_static` or `off`.
    pub particle_z: DofFile,
    /// Particle rotation: `dynamic`, `quasi_static` or `off`.
    pub particle_rotation: DofFile,
    /// Cantilever y/z deflection: `dynamic` or `quasi_static`.
    pub cantilever: DofFile,
    /// Stage: `dynamic` (Eq 13) or `off` (ideal, constant speed).
    pub stage: DofFile,
}

/// How force-controlled pushing closes its loops (Sec 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ControlFile {
    /// xy-position control (Fig 6): the push stops when the Eq 19 estimate of the particle's
    /// position reaches the target.
    #[default]
    Xy,
    /// z-position control: the tip height is regulated to hold `ζ_z` at the push set point; the
    /// stage travels the commanded distance.
    Z,
    /// Both.
    Xyz,
}

impl ControlFile {
    /// The name a scene file and the command line use (`xy`, `z`, `xyz`).
    pub fn name(self) -> &'static str {
        match self {
            ControlFile::Xy => "xy",
            ControlFile::Z => "z",
            ControlFile::Xyz => "xyz",
        }
    }
}

/// `[strategy]`: the auto-parking, contact detection, push and retract of Sec 2.1, with the
/// limits that end a run safely. Defaults are the paper's (Sec 5) where it gives them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StrategyFile {
    /// Tip apex height above the substrate at the start (A), unknown to the controller (µm).
    pub start_height_um: f64,
    /// Speed of the z approach of auto-parking and of the retraction (µm/s).
    pub approach_speed_um_per_s: f64,
    /// Speed of moves between pushes, at the start height (µm/s).
    pub travel_speed_um_per_s: f64,
    /// Deflection change that means the tip touched the substrate during auto-parking (mV).
    pub substrate_threshold_mv: f64,
    /// Step of the contact search `Δ` (µm); the paper: 0.1.
    pub step_um: f64,
    /// Pause after each step of the contact search, while the deflection is read (ms).
    pub dwell_ms: f64,
    /// Contact set point `ζ_set` (V); the paper: −1.5.
    pub set_point_v: f64,
    /// Where the contact search starts: this far behind the point of contact (µm).
    pub approach_distance_um: f64,
    /// Longest contact search before "no contact within range" (µm).
    pub search_range_um: f64,
    /// Safety limit on the reading (V): beyond it (on the set point's side of the baseline) the
    /// tip retracts at once.
    pub safety_limit_v: f64,
    /// "Particle lost": the deflection fell back within this of the baseline (mV) during a push;
    /// 0 turns the test off (a particle that rolls ahead of the tip with no load on the lever
    /// reads as the baseline, as a lost one does: the scan after the push judges it).
    pub lost_threshold_mv: f64,
    /// Longest single push (µm); a longer move is planned as several pushes.
    pub max_push_um: f64,
    /// Clearance kept between a pushed particle and the others when planning (µm).
    pub clearance_um: f64,
    /// Longest time any one phase may take before it fails with a time-out (s).
    pub phase_timeout_s: f64,
    /// How the push closes its loops.
    pub control: ControlFile,
    /// Proportional gain of the z force loop (nm of height per V of error per tick).
    pub z_gain_nm_per_v: f64,
    /// Whether the tip follows the substrate's slope, as the local scan before each push measured
    /// it, through the contact search and the push: the tip then keeps its height above the
    /// substrate and the contact angle its value. `false` holds the stage's height, as the paper
    /// does (its Fig 15 shows the slope changing the contact angle along a push).
    pub follow_slope: bool,
}

impl Default for StrategyFile {
    /// The paper's values where it gives them (Δ = 0.1 µm, ζ_set = −1.5 V, Sec 5), else
    /// conservative ones for the paper's 1 µm particles.
    fn default() -> StrategyFile {
        StrategyFile {
            start_height_um: 3.0,
            approach_speed_um_per_s: 1.0,
            travel_speed_um_per_s: 10.0,
            substrate_threshold_mv: 150.0,
            step_um: 0.1,
            dwell_ms: 5.0,
            set_point_v: -1.5,
            approach_distance_um: 4.25,
            search_range_um: 10.0,
            safety_limit_v: -4.0,
            lost_threshold_mv: 60.0,
            max_push_um: 20.0,
            clearance_um: 0.5,
            phase_timeout_s: 120.0,
            control: ControlFile::Xy,
            z_gain_nm_per_v: 2.0,
            follow_slope: false,
        }
    }
}

/// `[scan]`: tapping-mode scans of the scene (`nanopush scan`). Optional; every field has a
/// default, listed in [`ScanFile::default`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanFile {
    /// Centre of the scanned square, x (µm).
    pub centre_x_um: f64,
    /// Centre of the scanned square, y (µm).
    pub centre_y_um: f64,
    /// Side of the scanned square (µm).
    pub size_um: f64,
    /// Pixels per line and lines per frame.
    pub pixels: u32,
    /// Lines per second (Hz).
    pub line_rate_hz: f64,
    /// RMS of the height noise (nm).
    pub noise_rms_nm: f64,
    /// Seed of the height noise.
    pub noise_seed: u64,
    /// Drift of the tip relative to the sample along x (nm/s).
    pub drift_x_nm_per_s: f64,
    /// Drift along y (nm/s).
    pub drift_y_nm_per_s: f64,
    /// Drift of the recorded height (nm/s).
    pub drift_z_nm_per_s: f64,
    /// Piezo hysteresis: width of the loop as a percentage of the scan size.
    pub hysteresis_percent: f64,
    /// Half-angle of the tip's cone above its spherical apex (degrees).
    pub tip_half_angle_deg: f64,
}

impl Default for ScanFile {
    /// - centre (50, 50) µm, size 50 µm: the middle half of the paper's 100 µm stage (Sec 2.4);
    /// - 256 × 256 pixels at 1 line/s: a usual tapping-mode image;
    /// - noise 0.2 nm RMS, seed 1: tapping-mode z noise is 0.05-0.3 nm on commercial AFMs;
    /// - no drift and no hysteresis: a closed-loop stage after warm-up (the paper's P-762.3L
    ///   quotes 0.1 % hysteresis, `hysteresis_percent = 0.1`);
    /// - cone half-angle 20°: etched silicon tapping tips (e.g. NanoWorld Pointprobe NCH: 20-25°
    ///   along the cantilever, 10° at the apex).
    fn default() -> ScanFile {
        ScanFile {
            centre_x_um: 50.0,
            centre_y_um: 50.0,
            size_um: 50.0,
            pixels: 256,
            line_rate_hz: 1.0,
            noise_rms_nm: 0.2,
            noise_seed: 1,
            drift_x_nm_per_s: 0.0,
            drift_y_nm_per_s: 0.0,
            drift_z_nm_per_s: 0.0,
            hysteresis_percent: 0.0,
            tip_half_angle_deg: 20.0,
        }
    }
}
