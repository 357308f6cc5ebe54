//! Every number of a scene and the range it must lie in, as tables in file order. A range may
//! depend on the scene (a particle's position on the stage's travel, a kinetic friction on its
//! static one); such a range is written with the scene's name `s`.

use super::{
    GAIN_V_PER_NM, HAMAKER, MAX_SCAN_PIXELS, MIN_SCAN_PIXELS, MODULUS, MU, POISSON, Range, START_HEIGHT_UM,
    STIFFNESS_N_PER_M,
};
use crate::scene::file::{ParticleFile, SceneFile};

/// A number of a scene: its field's name, how to read it, and its allowed range.
pub(super) struct Field {
    pub(super) name: &'static str,
    pub(super) value: fn(&SceneFile) -> f64,
    pub(super) range: fn(&SceneFile) -> Range,
}

/// A number of each `[[particles]]` entry (its name without the `particles[i].` prefix).
pub(super) struct ParticleField {
    pub(super) name: &'static str,
    pub(super) value: fn(&ParticleFile) -> f64,
    pub(super) range: fn(&SceneFile) -> Range,
}

/// `fields![ "name": s => value, range; … ]`: a table of [`Field`]s, each value and range an
/// expression of the scene `s`.
macro_rules! fields {
    ($($name:literal: $s:ident => $value:expr, $range:expr;)*) => {
        &[$(Field {
            name: $name,
            value: |$s: &SceneFile| $value,
            range: |$s: &SceneFile| {
                let _ = $s;
                $range
            },
        }),*]
    };
}

/// `[tip]`, `[cantilever]`, `[substrate]`, `[stage]`.
pub(super) const INSTRUMENT: &[Field] = fields![
    "tip.radius_nm": s => s.tip.radius_nm, Range::closed(1.0, 1000.0, "nm");
    "tip.youngs_modulus_gpa": s => s.tip.youngs_modulus_gpa, MODULUS;
    "tip.poisson_ratio": s => s.tip.poisson_ratio, POISSON;
    "tip.hamaker_zj": s => s.tip.hamaker_zj, HAMAKER;
    "cantilever.stiffness_n_per_m": s => s.cantilever.stiffness_n_per_m, STIFFNESS_N_PER_M;
    "cantilever.width_um": s => s.cantilever.width_um, Range::closed(1.0, 1000.0, "µm");
    "cantilever.length_um": s => s.cantilever.length_um, Range::closed(5.0, 5000.0, "µm");
    "cantilever.tip_height_um": s => s.cantilever.tip_height_um, Range::closed(0.5, 100.0, "µm");
    "cantilever.thickness_um": s => s.cantilever.thickness_um, Range::closed(0.05, 50.0, "µm");
    "cantilever.resonance_khz": s => s.cantilever.resonance_khz, Range::closed(1.0, 10000.0, "kHz");
    "cantilever.quality_factor": s => s.cantilever.quality_factor, Range::closed(0.5, 100000.0, "");
    "cantilever.tilt_deg": s => s.cantilever.tilt_deg, Range::closed(0.0, 75.0, "degrees");
    "substrate.youngs_modulus_gpa": s => s.substrate.youngs_modulus_gpa, MODULUS;
    "substrate.poisson_ratio": s => s.substrate.poisson_ratio, POISSON;
    "substrate.hamaker_zj": s => s.substrate.hamaker_zj, HAMAKER;
    "substrate.tilt_x_mrad": s => s.substrate.tilt_x_mrad, TILT;
    "substrate.tilt_y_mrad": s => s.substrate.tilt_y_mrad, TILT;
    "substrate.roughness_rms_nm": s => s.substrate.roughness_rms_nm, Range::closed(0.0, 100.0, "nm");
    "substrate.roughness_wavelength_um": s => s.substrate.roughness_wavelength_um, Range::closed(0.1, 1000.0, "µm");
    "stage.resonance_hz": s => s.stage.resonance_hz, Range::closed(1.0, 100000.0, "Hz");
    "stage.quality_factor": s => s.stage.quality_factor, Range::closed(0.5, 1000.0, "");
    "stage.moving_mass_g": s => s.stage.moving_mass_g, Range::closed(0.1, 100000.0, "g");
    "stage.range_um": s => s.stage.range_um, Range::open_closed(0.0, 1000.0, "µm");
];

const TILT: Range = Range::closed(-100.0, 100.0, "mrad");

/// Each `[[particles]]` entry.
pub(super) const PARTICLE: &[ParticleField] = &[
    ParticleField {
        name: "radius_nm",
        value: |p| p.radius_nm,
        range: |_| Range::closed(2.0, 10000.0, "nm"),
    },
    ParticleField {
        name: "x_um",
        value: |p| p.x_um,
        range: travel,
    },
    ParticleField {
        name: "y_um",
        value: |p| p.y_um,
        range: travel,
    },
    ParticleField {
        name: "youngs_modulus_gpa",
        value: |p| p.youngs_modulus_gpa,
        range: |_| MODULUS,
    },
    ParticleField {
        name: "poisson_ratio",
        value: |p| p.poisson_ratio,
        range: |_| POISSON,
    },
    ParticleField {
        name: "density_kg_per_m3",
        value: |p| p.density_kg_per_m3,
        range: |_| Range::closed(100.0, 25000.0, "kg/m³"),
    },
    ParticleField {
        name: "hamaker_zj",
        value: |p| p.hamaker_zj,
        range: |_| HAMAKER,
    },
];

/// A position on the stage.
fn travel(s: &SceneFile) -> Range {
    Range::closed(0.0, s.stage.range_um, "µm (the stage range)")
}

/// `[environment]`, `[friction]`, and `[push]`'s numbers.
pub(super) const CONTACT: &[Field] = fields![
    "environment.relative_humidity": s => s.environment.relative_humidity, Range::closed_open(0.0, 1.0, "(P/Pₛ)");
    "environment.surface_tension_mj_per_m2": s => s.environment.surface_tension_mj_per_m2, Range::closed(0.0, 500.0, "mJ/m²");
    "environment.solid_liquid_energy_mj_per_m2": s => s.environment.solid_liquid_energy_mj_per_m2, Range::closed(0.0, 500.0, "mJ/m²");
    "environment.medium_hamaker_zj": s => s.environment.medium_hamaker_zj, Range::closed(0.0, 1000.0, "zJ");
    "environment.interatomic_cutoff_nm": s => s.environment.interatomic_cutoff_nm, Range::closed(0.1, 0.5, "nm");
    "environment.tip_particle_voltage_v": s => s.environment.tip_particle_voltage_v, VOLTS;
    "environment.particle_substrate_voltage_v": s => s.environment.particle_substrate_voltage_v, VOLTS;
    "environment.tip_substrate_voltage_v": s => s.environment.tip_substrate_voltage_v, VOLTS;
    "friction.particle_substrate_static": s => s.friction.particle_substrate_static, MU;
    "friction.particle_substrate_kinetic": s => s.friction.particle_substrate_kinetic,
        Range::closed(0.0, s.friction.particle_substrate_static, "(at most the static coefficient)");
    "friction.tip_particle_static": s => s.friction.tip_particle_static, MU;
    "friction.tip_particle_kinetic": s => s.friction.tip_particle_kinetic,
        Range::closed(0.0, s.friction.tip_particle_static, "(at most the static coefficient)");
    "friction.contact_damping_ratio": s => s.friction.contact_damping_ratio, Range::closed(0.0, 10.0, "");
    "push.contact_angle_deg": s => s.push.contact_angle_deg, Range::closed(1.0, 89.0, "degrees");
    "push.speed_um_per_s": s => s.push.speed_um_per_s, Range::open_closed(0.0, 1000.0, "µm/s");
];

const VOLTS: Range = Range::closed(-10.0, 10.0, "V");

/// `[sensor]`'s levels (the gain must not be 0 either, checked after them).
pub(super) const SENSOR_LEVELS: &[Field] = fields![
    "sensor.baseline_v": s => s.sensor.baseline_v, VOLTS;
    "sensor.gain_v_per_nm": s => s.sensor.gain_v_per_nm, GAIN_V_PER_NM;
];

/// `[sensor]`'s noise and full scale.
pub(super) const SENSOR_READOUT: &[Field] = fields![
    "sensor.noise_rms_mv": s => s.sensor.noise_rms_mv, Range::closed(0.0, 1000.0, "mV");
    "sensor.full_scale_v": s => s.sensor.full_scale_v, Range::closed(1.0, 100.0, "V");
];

/// `[strategy]`.
pub(super) const STRATEGY: &[Field] = fields![
    "strategy.start_height_um": s => s.strategy.start_height_um, START_HEIGHT_UM;
    "strategy.approach_speed_um_per_s": s => s.strategy.approach_speed_um_per_s, Range::closed(0.01, 20.0, "µm/s");
    "strategy.travel_speed_um_per_s": s => s.strategy.travel_speed_um_per_s, Range::closed(0.01, 100.0, "µm/s");
    "strategy.substrate_threshold_mv": s => s.strategy.substrate_threshold_mv, Range::closed(1.0, 5000.0, "mV");
    "strategy.step_um": s => s.strategy.step_um, Range::closed(0.001, 10.0, "µm");
    "strategy.dwell_ms": s => s.strategy.dwell_ms, Range::closed(0.0, 1000.0, "ms");
    "strategy.set_point_v": s => s.strategy.set_point_v, VOLTS;
    "strategy.approach_distance_um": s => s.strategy.approach_distance_um, Range::closed(0.0, 50.0, "µm");
    "strategy.search_range_um": s => s.strategy.search_range_um, Range::open_closed(0.0, 100.0, "µm");
    "strategy.safety_limit_v": s => s.strategy.safety_limit_v, VOLTS;
    "strategy.lost_threshold_mv": s => s.strategy.lost_threshold_mv, Range::closed(0.0, 5000.0, "mV");
    "strategy.max_push_um": s => s.strategy.max_push_um, Range::open_closed(0.0, 100.0, "µm");
    "strategy.clearance_um": s => s.strategy.clearance_um, Range::closed(0.0, 10.0, "µm");
    "strategy.phase_timeout_s": s => s.strategy.phase_timeout_s, Range::open_closed(0.0, 3600.0, "s");
    "strategy.z_gain_nm_per_v": s => s.strategy.z_gain_nm_per_v, Range::closed(0.0, 100.0, "nm/V");
];

/// `[sensor]`'s periodic perturbation.
pub(super) const SENSOR_PERTURBATION: &[Field] = fields![
    "sensor.perturbation_mv": s => s.sensor.perturbation_mv, Range::closed(0.0, 1000.0, "mV");
    "sensor.perturbation_hz": s => s.sensor.perturbation_hz,
        Range::open_closed(0.0, 500.0, "Hz (below the 1 kHz sampling's Nyquist limit)");
];

/// `[scan]`: each value in range, and the scanned square inside the stage's travel.
pub(super) const SCAN: &[Field] = fields![
    "scan.size_um": s => s.scan.size_um, Range::open_closed(0.0, s.stage.range_um, "µm (the stage range)");
    "scan.centre_x_um": s => s.scan.centre_x_um, scan_centre(s);
    "scan.centre_y_um": s => s.scan.centre_y_um, scan_centre(s);
    "scan.pixels": s => s.scan.pixels as f64,
        Range::closed(MIN_SCAN_PIXELS as f64, MAX_SCAN_PIXELS as f64, "pixels");
    "scan.line_rate_hz": s => s.scan.line_rate_hz, Range::closed(0.01, 100.0, "Hz");
    "scan.noise_rms_nm": s => s.scan.noise_rms_nm, Range::closed(0.0, 100.0, "nm");
    "scan.drift_x_nm_per_s": s => s.scan.drift_x_nm_per_s, DRIFT;
    "scan.drift_y_nm_per_s": s => s.scan.drift_y_nm_per_s, DRIFT;
    "scan.drift_z_nm_per_s": s => s.scan.drift_z_nm_per_s, DRIFT;
    "scan.hysteresis_percent": s => s.scan.hysteresis_percent, Range::closed(0.0, 20.0, "%");
    "scan.tip_half_angle_deg": s => s.scan.tip_half_angle_deg, Range::closed(0.0, 60.0, "degrees");
];

const DRIFT: Range = Range::closed(-100.0, 100.0, "nm/s");

/// Where the scanned square's centre may be: the square within the stage's travel.
fn scan_centre(s: &SceneFile) -> Range {
    let half = 0.5 * s.scan.size_um;
    Range::closed(
        half,
        s.stage.range_um - half,
        "µm (the square must stay within the stage range)",
    )
}

/// `[haptic]`.
pub(super) const HAPTIC: &[Field] = fields![
    "haptic.nm_per_mm": s => s.haptic.nm_per_mm, Range::closed(0.01, 1000.0, "nm/mm");
    "haptic.pull_off_at_hand_n": s => s.haptic.pull_off_at_hand_n, Range::closed(0.01, 10.0, "N");
    "haptic.park_gap_nm": s => s.haptic.park_gap_nm, Range::closed(1.0, 10_000.0, "nm");
    "haptic.max_speed_nm_per_s": s => s.haptic.max_speed_nm_per_s, Range::closed(1.0, 100_000.0, "nm/s");
    "haptic.max_height_nm": s => s.haptic.max_height_nm, Range::closed(1.0, 50_000.0, "nm");
];
