//! Range checks of a parsed scene: each rejected value gets one error naming the field, the
//! value and the allowed range.

use super::error::SceneError;
use super::file::{DofFile, SceneFile};
use super::hand_set::HandSet;

/// An allowed interval with its unit, e.g. `(0, 10000] nm`.
#[derive(Debug, Clone, Copy)]
pub struct Range {
    lo: f64,
    hi: f64,
    lo_open: bool,
    hi_open: bool,
    unit: &'static str,
}

impl Range {
    /// The upper bound.
    pub const fn hi(&self) -> f64 {
        self.hi
    }

    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
            unit,
        }
    }
    /// `(lo, hi]`.
    pub const fn open_closed(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: true,
            hi_open: false,
            unit,
        }
    }
    /// `[lo, hi)`.
    pub const fn closed_open(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: true,
            unit,
        }
    }
    fn contains(&self, v: f64) -> bool {
        let lo_ok = if self.lo_open { v > self.lo } else { v >= self.lo };
        let hi_ok = if self.hi_open { v < self.hi } else { v <= self.hi };
        lo_ok && hi_ok
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let l = if self.lo_open { '(' } else { '[' };
        let r = if self.hi_open { ')' } else { ']' };
        write!(f, "{l}{}, {}{r}", self.lo, self.hi)?;
        if !self.unit.is_empty() {
            write!(f, " {}", self.unit)?;
        }
        Ok(())
    }
}

/// Checks one number against its range.
fn check(origin: &str, field: &str, value: f64, range: Range) -> Result<(), SceneError> {
    if !value.is_finite() {
        return Err(SceneError::NotFinite {
            origin: origin.into(),
            field: field.into(),
            value,
            allowed: range.to_string(),
        });
    }
    if !range.contains(value) {
        return Err(SceneError::OutOfRange {
            origin: origin.into(),
            field: field.into(),
            value,
            allowed: range.to_string(),
        });
    }
    Ok(())
}

const MODULUS: Range = Range::closed(0.01, 1500.0, "GPa");
const POISSON: Range = Range::closed(0.0, 0.5, "");
const HAMAKER: Range = Range::closed(1.0, 1000.0, "zJ");
const MU: Range = Range::closed(0.0, 5.0, "");
/// `cantilever.stiffness_n_per_m` (the planner names no stiffness beyond it).
pub const STIFFNESS_N_PER_M: Range = Range::closed(0.01, 500.0, "N/m");
/// `strategy.start_height_um` (the planner lifts no higher).
pub const START_HEIGHT_UM: Range = Range::open_closed(0.0, 50.0, "µm");

/// Every range check of a scene, in file order; the first failure is returned.
pub fn validate(origin: &str, s: &SceneFile, hand_set: &HandSet) -> Result<(), SceneError> {
    let c = |field: &str, v: f64, r: Range| check(origin, field, v, r);
    c("tip.radius_nm", s.tip.radius_nm, Range::closed(1.0, 1000.0, "nm"))?;
    c("tip.youngs_modulus_gpa", s.tip.youngs_modulus_gpa, MODULUS)?;
    c("tip.poisson_ratio", s.tip.poisson_ratio, POISSON)?;
    c("tip.hamaker_zj", s.tip.hamaker_zj, HAMAKER)?;

    let k = &s.cantilever;
    c("cantilever.stiffness_n_per_m", k.stiffness_n_per_m, STIFFNESS_N_PER_M)?;
    c("cantilever.width_um", k.width_um, Range::closed(1.0, 1000.0, "µm"))?;
    c("cantilever.length_um", k.length_um, Range::closed(5.0, 5000.0, "µm"))?;
    c(
        "cantilever.tip_height_um",
        k.tip_height_um,
        Range::closed(0.5, 100.0, "µm"),
    )?;
    c(
        "cantilever.thickness_um",
        k.thickness_um,
        Range::closed(0.05, 50.0, "µm"),
    )?;
    c(
        "cantilever.resonance_khz",
        k.resonance_khz,
        Range::closed(1.0, 10000.0, "kHz"),
    )?;
    c(
        "cantilever.quality_factor",
        k.quality_factor,
        Range::closed(0.5, 100000.0, ""),
    )?;
    c("cantilever.tilt_deg", k.tilt_deg, Range::closed(0.0, 75.0, "degrees"))?;

    c("substrate.youngs_modulus_gpa", s.substrate.youngs_modulus_gpa, MODULUS)?;
    c("substrate.poisson_ratio", s.substrate.poisson_ratio, POISSON)?;
    c("substrate.hamaker_zj", s.substrate.hamaker_zj, HAMAKER)?;
    let tilt = Range::closed(-100.0, 100.0, "mrad");
    c("substrate.tilt_x_mrad", s.substrate.tilt_x_mrad, tilt)?;
    c("substrate.tilt_y_mrad", s.substrate.tilt_y_mrad, tilt)?;
    c(
        "substrate.roughness_rms_nm",
        s.substrate.roughness_rms_nm,
        Range::closed(0.0, 100.0, "nm"),
    )?;
    c(
        "substrate.roughness_wavelength_um",
        s.substrate.roughness_wavelength_um,
        Range::closed(0.1, 1000.0, "µm"),
    )?;

    c(
        "stage.resonance_hz",
        s.stage.resonance_hz,
        Range::closed(1.0, 100000.0, "Hz"),
    )?;
    c(
        "stage.quality_factor",
        s.stage.quality_factor,
        Range::closed(0.5, 1000.0, ""),
    )?;
    c(
        "stage.moving_mass_g",
        s.stage.moving_mass_g,
        Range::closed(0.1, 100000.0, "g"),
    )?;
    c(
        "stage.range_um",
        s.stage.range_um,
        Range::open_closed(0.0, 1000.0, "µm"),
    )?;

    if s.particles.is_empty() {
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: "particles".into(),
            message: "the scene needs at least one [[particles]] entry".into(),
        });
    }
    if s.particles.len() > MAX_PARTICLES {
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: "particles".into(),
            message: format!(
                "{} particles; allowed: at most {MAX_PARTICLES} (every scan images each particle at every pixel: 4705 took 11.5 s a push)",
                s.particles.len()
            ),
        });
    }
    let travel = Range::closed(0.0, s.stage.range_um, "µm (the stage range)");
    for (i, p) in s.particles.iter().enumerate() {
        let f = |name: &str| format!("particles[{i}].{name}");
        c(&f("radius_nm"), p.radius_nm, Range::closed(2.0, 10000.0, "nm"))?;
        c(&f("x_um"), p.x_um, travel)?;
        c(&f("y_um"), p.y_um, travel)?;
        c(&f("youngs_modulus_gpa"), p.youngs_modulus_gpa, MODULUS)?;
        c(&f("poisson_ratio"), p.poisson_ratio, POISSON)?;
        c(
            &f("density_kg_per_m3"),
            p.density_kg_per_m3,
            Range::closed(100.0, 25000.0, "kg/m³"),
        )?;
        c(&f("hamaker_zj"), p.hamaker_zj, HAMAKER)?;
    }
    if let Some((i, j, same_id)) = first_clash(&s.particles) {
        let (p, q) = (&s.particles[i], &s.particles[j]);
        let field = format!("particles[{i}].{}", if same_id { "id" } else { "x_um" });
        let message = if same_id {
            format!("id {} is already used by particles[{j}]", p.id)
        } else {
            let d_nm = ((p.x_um - q.x_um).powi(2) + (p.y_um - q.y_um).powi(2)).sqrt() * 1e3;
            format!(
                "particle {} overlaps particle {}: centres {d_nm:.1} nm apart, radii sum to {:.1} nm",
                p.id,
                q.id,
                p.radius_nm + q.radius_nm
            )
        };
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field,
            message,
        });
    }

    let e = &s.environment;
    c(
        "environment.relative_humidity",
        e.relative_humidity,
        Range::closed_open(0.0, 1.0, "(P/Pₛ)"),
    )?;
    c(
        "environment.surface_tension_mj_per_m2",
        e.surface_tension_mj_per_m2,
        Range::closed(0.0, 500.0, "mJ/m²"),
    )?;
    c(
        "environment.solid_liquid_energy_mj_per_m2",
        e.solid_liquid_energy_mj_per_m2,
        Range::closed(0.0, 500.0, "mJ/m²"),
    )?;
    c(
        "environment.medium_hamaker_zj",
        e.medium_hamaker_zj,
        Range::closed(0.0, 1000.0, "zJ"),
    )?;
    c(
        "environment.interatomic_cutoff_nm",
        e.interatomic_cutoff_nm,
        Range::closed(0.1, 0.5, "nm"),
    )?;
    let volts = Range::closed(-10.0, 10.0, "V");
    c("environment.tip_particle_voltage_v", e.tip_particle_voltage_v, volts)?;
    c(
        "environment.particle_substrate_voltage_v",
        e.particle_substrate_voltage_v,
        volts,
    )?;
    c("environment.tip_substrate_voltage_v", e.tip_substrate_voltage_v, volts)?;

    let fr = &s.friction;
    c("friction.particle_substrate_static", fr.particle_substrate_static, MU)?;
    c(
        "friction.particle_substrate_kinetic",
        fr.particle_substrate_kinetic,
        Range::closed(0.0, fr.particle_substrate_static, "(at most the static coefficient)"),
    )?;
    c("friction.tip_particle_static", fr.tip_particle_static, MU)?;
    c(
        "friction.tip_particle_kinetic",
        fr.tip_particle_kinetic,
        Range::closed(0.0, fr.tip_particle_static, "(at most the static coefficient)"),
    )?;
    c(
        "friction.contact_damping_ratio",
        fr.contact_damping_ratio,
        Range::closed(0.0, 10.0, ""),
    )?;

    c(
        "push.contact_angle_deg",
        s.push.contact_angle_deg,
        Range::closed(1.0, 89.0, "degrees"),
    )?;
    c(
        "push.speed_um_per_s",
        s.push.speed_um_per_s,
        Range::open_closed(0.0, 1000.0, "µm/s"),
    )?;
    if !s.particles.iter().any(|p| p.id == s.push.particle_id) {
        let ids: Vec<String> = s.particles.iter().map(|p| p.id.to_string()).collect();
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: "push.particle_id".into(),
            message: format!(
                "no particle has id {}; ids in the scene: {}",
                s.push.particle_id,
                ids.join(", ")
            ),
        });
    }

    c(
        "sensor.baseline_v",
        s.sensor.baseline_v,
        Range::closed(-10.0, 10.0, "V"),
    )?;
    c(
        "sensor.gain_v_per_nm",
        s.sensor.gain_v_per_nm,
        Range::closed(-10.0, 10.0, "V/nm"),
    )?;
    if s.sensor.gain_v_per_nm == 0.0 {
        return Err(SceneError::OutOfRange {
            origin: origin.into(),
            field: "sensor.gain_v_per_nm".into(),
            value: 0.0,
            allowed: "[-10, 10] V/nm, not 0".into(),
        });
    }
    c(
        "sensor.noise_rms_mv",
        s.sensor.noise_rms_mv,
        Range::closed(0.0, 1000.0, "mV"),
    )?;
    c(
        "sensor.full_scale_v",
        s.sensor.full_scale_v,
        Range::closed(1.0, 100.0, "V"),
    )?;
    validate_strategy(origin, s, hand_set)?;
    c(
        "sensor.perturbation_mv",
        s.sensor.perturbation_mv,
        Range::closed(0.0, 1000.0, "mV"),
    )?;
    c(
        "sensor.perturbation_hz",
        s.sensor.perturbation_hz,
        Range::open_closed(0.0, 500.0, "Hz (below the 1 kHz sampling's Nyquist limit)"),
    )?;

    validate_scan(origin, s)?;
    validate_haptic(origin, s)?;

    let ph = &s.physics;
    // Across the water layer the Hamaker combining rule (Sec 2.2.1) is attractive only when every
    // body's constant exceeds the medium's; the model's van der Waals laws are attractive.
    if ph.van_der_waals && e.relative_humidity > 0.0 {
        let medium = e.medium_hamaker_zj;
        let mut bodies: Vec<(String, f64)> = vec![
            ("tip.hamaker_zj".into(), s.tip.hamaker_zj),
            ("substrate.hamaker_zj".into(), s.substrate.hamaker_zj),
        ];
        bodies.extend(
            s.particles
                .iter()
                .enumerate()
                .map(|(i, p)| (format!("particles[{i}].hamaker_zj"), p.hamaker_zj)),
        );
        for (field, h) in bodies {
            if h <= medium {
                return Err(SceneError::OutOfRange {
                    origin: origin.into(),
                    field,
                    value: h,
                    allowed: format!(
                        "above environment.medium_hamaker_zj = {medium} zJ: at or below it van der Waals across the water layer is repulsive, which the model does not describe"
                    ),
                });
            }
        }
    }
    let dof = |field: &str, v: DofFile, allowed: &[DofFile]| -> Result<(), SceneError> {
        if allowed.contains(&v) {
            return Ok(());
        }
        let names: Vec<&str> = allowed.iter().map(|d| dof_name(*d)).collect();
        Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: field.into(),
            message: format!("\"{}\" is not allowed here; allowed: {}", dof_name(v), names.join(", ")),
        })
    };
    use DofFile::*;
    dof("physics.particle_y", ph.particle_y, &[Dynamic, QuasiStatic])?;
    dof("physics.particle_z", ph.particle_z, &[Dynamic, QuasiStatic, Off])?;
    dof(
        "physics.particle_rotation",
        ph.particle_rotation,
        &[Dynamic, QuasiStatic, Off],
    )?;
    dof("physics.cantilever", ph.cantilever, &[Dynamic, QuasiStatic])?;
    dof("physics.stage", ph.stage, &[Dynamic, Off])?;
    Ok(())
}

/// Largest image side (pixels) a scene may ask for.
pub const MAX_SCAN_PIXELS: u32 = 4096;

/// The most particles a scene may hold.
pub const MAX_PARTICLES: usize = 2000;

/// The first pair of particles that clash, in file order: the smallest `i` with an earlier `j`
/// of the same id or overlapping it (centres closer than the radii's sum), the smallest such
/// `j`, and whether it is the id (checked before the overlap, for each `j`). In O(n log n) for
/// scattered particles (a sweep along x), where comparing every pair made 1.8·10⁹ comparisons for 60 000.
pub(crate) fn first_clash(ps: &[crate::scene::file::ParticleFile]) -> Option<(usize, usize, bool)> {
    let mut best: Option<(usize, usize, bool)> = None;
    let mut keep = |i: usize, j: usize, same_id: bool| {
        let (a, b) = (i.max(j), i.min(j));
        let cand = (a, b, same_id);
        // For one pair, the id is checked first.
        if best.is_none_or(|x| (a, b, !same_id) < (x.0, x.1, !x.2)) {
            best = Some(cand);
        }
    };
    let mut first_of: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for (i, p) in ps.iter().enumerate() {
        match first_of.get(&p.id) {
            Some(&j) => keep(i, j, true),
            None => {
                first_of.insert(p.id, i);
            }
        }
    }
    let r_max = ps.iter().map(|p| p.radius_nm).fold(0.0, f64::max);
    let mut order: Vec<usize> = (0..ps.len()).collect();
    order.sort_by(|&a, &b| ps[a].x_um.total_cmp(&ps[b].x_um));
    for (k, &a) in order.iter().enumerate() {
        let p = &ps[a];
        for &b in &order[k + 1..] {
            let q = &ps[b];
            if (q.x_um - p.x_um) * 1e3 >= p.radius_nm + r_max {
                break;
            }
            let d_nm = ((p.x_um - q.x_um).powi(2) + (p.y_um - q.y_um).powi(2)).sqrt() * 1e3;
            if d_nm < p.radius_nm + q.radius_nm {
                keep(a, b, false);
            }
        }
    }
    best
}
/// Smallest image side (pixels).
pub const MIN_SCAN_PIXELS: u32 = 8;

/// `[scan]`: each value in range, and the scanned square inside the stage's travel.
fn validate_scan(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    let c = |field: &str, v: f64, r: Range| check(origin, field, v, r);
    let sc = &s.scan;
    let travel = s.stage.range_um;
    c(
        "scan.size_um",
        sc.size_um,
        Range::open_closed(0.0, travel, "µm (the stage range)"),
    )?;
    let half = 0.5 * sc.size_um;
    let centre = Range::closed(half, travel - half, "µm (the square must stay within the stage range)");
    c("scan.centre_x_um", sc.centre_x_um, centre)?;
    c("scan.centre_y_um", sc.centre_y_um, centre)?;
    c(
        "scan.pixels",
        sc.pixels as f64,
        Range::closed(MIN_SCAN_PIXELS as f64, MAX_SCAN_PIXELS as f64, "pixels"),
    )?;
    c("scan.line_rate_hz", sc.line_rate_hz, Range::closed(0.01, 100.0, "Hz"))?;
    c("scan.noise_rms_nm", sc.noise_rms_nm, Range::closed(0.0, 100.0, "nm"))?;
    let drift = Range::closed(-100.0, 100.0, "nm/s");
    c("scan.drift_x_nm_per_s", sc.drift_x_nm_per_s, drift)?;
    c("scan.drift_y_nm_per_s", sc.drift_y_nm_per_s, drift)?;
    c("scan.drift_z_nm_per_s", sc.drift_z_nm_per_s, drift)?;
    c(
        "scan.hysteresis_percent",
        sc.hysteresis_percent,
        Range::closed(0.0, 20.0, "%"),
    )?;
    c(
        "scan.tip_half_angle_deg",
        sc.tip_half_angle_deg,
        Range::closed(0.0, 60.0, "degrees"),
    )?;
    // Every particle must stand out of a scan: the localization takes a pixel as a particle
    // when it is more than max(6σ, 0.5 nm) above the levelled substrate, σ the image's noise
    // (scan noise and roughness); a particle whose height 2Rₐ is not twice that cannot be found
    // before a push. (The local scan's pixels follow the particle and tip radii, see
    // `control::moves::locate::local_scan_size`, so the pitch never hides it.)
    let sigma = sc.noise_rms_nm.hypot(s.substrate.roughness_rms_nm);
    let threshold = (6.0 * sigma).max(0.5);
    for (k, p) in s.particles.iter().enumerate() {
        if 2.0 * p.radius_nm < 2.0 * threshold {
            return Err(SceneError::Inconsistent {
                origin: origin.into(),
                field: format!("particles[{k}].radius_nm"),
                message: format!(
                    "{} nm: a scan cannot resolve it: its height 2Rₐ = {} nm is less than twice the localization threshold max(6σ, 0.5 nm) = {threshold:.3} nm, with σ = √(scan.noise_rms_nm² + substrate.roughness_rms_nm²) = {sigma:.3} nm; lower the noise or the roughness, or use a larger particle",
                    p.radius_nm,
                    2.0 * p.radius_nm
                ),
            });
        }
    }
    Ok(())
}

fn dof_name(d: DofFile) -> &'static str {
    match d {
        DofFile::Dynamic => "dynamic",
        DofFile::QuasiStatic => "quasi_static",
        DofFile::Off => "off",
    }
}

/// `[haptic]`: every number in range.
fn validate_haptic(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    let c = |field: &str, v: f64, r: Range| check(origin, &format!("haptic.{field}"), v, r);
    let h = &s.haptic;
    c("nm_per_mm", h.nm_per_mm, Range::closed(0.01, 1000.0, "nm/mm"))?;
    c(
        "pull_off_at_hand_n",
        h.pull_off_at_hand_n,
        Range::closed(0.01, 10.0, "N"),
    )?;
    c("park_gap_nm", h.park_gap_nm, Range::closed(1.0, 10_000.0, "nm"))?;
    c(
        "max_speed_nm_per_s",
        h.max_speed_nm_per_s,
        Range::closed(1.0, 100_000.0, "nm/s"),
    )?;
    c("max_height_nm", h.max_height_nm, Range::closed(1.0, 50_000.0, "nm"))?;
    Ok(())
}

/// `[strategy]`: every number in range, and the set point and safety limit on the side of the
/// baseline a push deflects to (`ζ_z > 0`, so the reading moves along the gain's sign).
fn validate_strategy(origin: &str, s: &SceneFile, hand_set: &HandSet) -> Result<(), SceneError> {
    let c = |field: &str, v: f64, r: Range| check(origin, &format!("strategy.{field}"), v, r);
    let st = &s.strategy;
    c("start_height_um", st.start_height_um, START_HEIGHT_UM)?;
    c(
        "approach_speed_um_per_s",
        st.approach_speed_um_per_s,
        Range::closed(0.01, 20.0, "µm/s"),
    )?;
    c(
        "travel_speed_um_per_s",
        st.travel_speed_um_per_s,
        Range::closed(0.01, 100.0, "µm/s"),
    )?;
    c(
        "substrate_threshold_mv",
        st.substrate_threshold_mv,
        Range::closed(1.0, 5000.0, "mV"),
    )?;
    c("step_um", st.step_um, Range::closed(0.001, 10.0, "µm"))?;
    c("dwell_ms", st.dwell_ms, Range::closed(0.0, 1000.0, "ms"))?;
    c("set_point_v", st.set_point_v, Range::closed(-10.0, 10.0, "V"))?;
    c(
        "approach_distance_um",
        st.approach_distance_um,
        Range::closed(0.0, 50.0, "µm"),
    )?;
    c(
        "search_range_um",
        st.search_range_um,
        Range::open_closed(0.0, 100.0, "µm"),
    )?;
    c("safety_limit_v", st.safety_limit_v, Range::closed(-10.0, 10.0, "V"))?;
    c(
        "lost_threshold_mv",
        st.lost_threshold_mv,
        Range::closed(1.0, 5000.0, "mV"),
    )?;
    c("max_push_um", st.max_push_um, Range::open_closed(0.0, 100.0, "µm"))?;
    c("clearance_um", st.clearance_um, Range::closed(0.0, 10.0, "µm"))?;
    c(
        "phase_timeout_s",
        st.phase_timeout_s,
        Range::open_closed(0.0, 3600.0, "s"),
    )?;
    c("z_gain_nm_per_v", st.z_gain_nm_per_v, Range::closed(0.0, 100.0, "nm/V"))?;
    // The levels below are checked against the sensor when the scene gives them; otherwise the
    // plan derives them from the sensor and the model (`control::derive`).
    let given = |key: &str| hand_set.contains(key);
    // A push bends the lever up (ζ_z > 0): the reading moves from the baseline along the gain.
    let dir = s.sensor.gain_v_per_nm.signum();
    let base = s.sensor.baseline_v;
    let set = (st.set_point_v - base) * dir;
    let safety = (st.safety_limit_v - base) * dir;
    let side = if dir < 0.0 { "below" } else { "above" };
    if set <= 0.0 && given("strategy.set_point_v") {
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: "strategy.set_point_v".into(),
            message: format!(
                "{} V must be {side} the baseline {base} V: a push deflects the reading that way (sensor.gain_v_per_nm = {})",
                st.set_point_v, s.sensor.gain_v_per_nm
            ),
        });
    }
    if safety <= set && (given("strategy.set_point_v") || given("strategy.safety_limit_v")) {
        return Err(SceneError::Inconsistent {
            origin: origin.into(),
            field: "strategy.safety_limit_v".into(),
            message: format!(
                "{} V must lie beyond the set point {} V (further {side} the baseline {base} V)",
                st.safety_limit_v, st.set_point_v
            ),
        });
    }
    // The ADC saturates at its full scale: every level the strategy reads must lie inside it.
    let fs = s.sensor.full_scale_v;
    for (field, v) in [
        ("sensor.baseline_v", base),
        ("strategy.set_point_v", st.set_point_v),
        ("strategy.safety_limit_v", st.safety_limit_v),
    ] {
        if v.abs() >= fs && (field == "sensor.baseline_v" || given(field)) {
            return Err(SceneError::Inconsistent {
                origin: origin.into(),
                field: field.into(),
                message: format!(
                    "{v} V is outside the readout's range (-{fs}, {fs}) V (sensor.full_scale_v = {fs}): the ADC saturates there"
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_display() {
        assert_eq!(Range::open_closed(0.0, 5.0, "nm").to_string(), "(0, 5] nm");
        assert_eq!(Range::closed_open(0.0, 1.0, "").to_string(), "[0, 1)");
    }
}
