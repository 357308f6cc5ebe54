//! Random valid scenes nobody tuned (`nanopush campaign`): a seeded generator draws every physical
//! parameter across the scene validator's ranges (log-uniformly where a range spans decades), sets
//! no strategy by hand, and keeps a draw only if the validator accepts it. Each scene is then
//! planned ([`nanopush_instrument::control::derive`]) and, when the plan accepts it, pushed whole
//! and judged as `nanopush push` judges ([`crate::judge::push_judged`]).

use nanopush_instrument::scene::Scene;
use nanopush_instrument::scene::file::{DofFile, SceneFile};
use nanopush_instrument::scene::hand_set::HandSet;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::judge::{Judged, push_judged};

/// Draws before the generator gives up on a seed (none has needed more than a few).
const MAX_DRAWS: u32 = 1000;

/// Which ranges the generator draws from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ranges {
    /// Every parameter across the scene validator's whole range: most such scenes cannot be
    /// pushed by any strategy (a 1 V-noise readout, a 1 Hz stage, a lever that adhesion bends
    /// past the rail), and the plan must say why.
    Validator,
    /// The ranges of the instruments and samples of a nanomanipulation lab (below).
    Lab,
}

impl Ranges {
    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Ranges::Validator => "validator",
            Ranges::Lab => "lab",
        }
    }
}

/// A random valid scene, its particle 1 at the stage's centre, and the push asked of it: a
/// distance (m) along a unit direction.
#[derive(Debug, Clone)]
pub struct RandomScene {
    /// The seed it was drawn from.
    pub seed: u64,
    /// The scene (nothing hand-set).
    pub scene: Scene,
    /// Distance to push (m).
    pub distance: f64,
    /// Unit direction.
    pub direction: (f64, f64),
    /// Draws the validator refused before this one.
    pub refused_draws: u32,
}

/// Log-uniform in `[lo, hi]`.
fn log_uniform(rng: &mut SmallRng, lo: f64, hi: f64) -> f64 {
    (rng.random_range(lo.ln()..=hi.ln())).exp()
}

/// One draw over the validator's ranges, from the default scene's file.
fn draw(rng: &mut SmallRng, base: &SceneFile) -> SceneFile {
    let mut f = base.clone();
    f.name = "random".into();
    let lu = |rng: &mut SmallRng, lo: f64, hi: f64| log_uniform(rng, lo, hi);
    // The tip and the lever.
    f.tip.radius_nm = lu(rng, 1.0, 1000.0);
    f.tip.youngs_modulus_gpa = lu(rng, 0.01, 1500.0);
    f.tip.poisson_ratio = rng.random_range(0.0..=0.5);
    let k = &mut f.cantilever;
    k.stiffness_n_per_m = lu(rng, 0.01, 500.0);
    k.tilt_deg = rng.random_range(0.0..=75.0);
    k.tip_height_um = lu(rng, 0.5, 100.0);
    k.width_um = lu(rng, 1.0, 1000.0);
    k.length_um = lu(rng, 5.0, 5000.0);
    k.thickness_um = lu(rng, 0.05, 50.0);
    k.resonance_khz = lu(rng, 1.0, 10_000.0);
    k.quality_factor = lu(rng, 0.5, 100_000.0);
    // The substrate.
    let s = &mut f.substrate;
    s.youngs_modulus_gpa = lu(rng, 0.01, 1500.0);
    s.poisson_ratio = rng.random_range(0.0..=0.5);
    s.tilt_x_mrad = rng.random_range(-100.0..=100.0);
    s.tilt_y_mrad = rng.random_range(-100.0..=100.0);
    s.roughness_rms_nm = if rng.random_bool(0.3) {
        0.0
    } else {
        lu(rng, 0.01, 100.0)
    };
    s.roughness_wavelength_um = lu(rng, 0.1, 1000.0);
    // The particle: one, at the centre.
    let p = &mut f.particles[0];
    p.radius_nm = lu(rng, 2.0, 10_000.0);
    p.youngs_modulus_gpa = lu(rng, 0.01, 1500.0);
    p.poisson_ratio = rng.random_range(0.0..=0.5);
    p.density_kg_per_m3 = lu(rng, 100.0, 25_000.0);
    f.particles.truncate(1);
    f.push.particle_id = f.particles[0].id;
    // The medium and the Hamaker constants, each above the medium's.
    let e = &mut f.environment;
    e.relative_humidity = rng.random_range(0.0..0.99);
    e.surface_tension_mj_per_m2 = rng.random_range(0.0..=500.0);
    e.solid_liquid_energy_mj_per_m2 = if rng.random_bool(0.5) {
        0.0
    } else {
        rng.random_range(0.0..=500.0)
    };
    e.medium_hamaker_zj = if rng.random_bool(0.3) { 0.0 } else { lu(rng, 1.0, 100.0) };
    e.interatomic_cutoff_nm = rng.random_range(0.1..=0.5);
    e.tip_particle_voltage_v = rng.random_range(-10.0..=10.0);
    e.particle_substrate_voltage_v = rng.random_range(-10.0..=10.0);
    e.tip_substrate_voltage_v = rng.random_range(-10.0..=10.0);
    let above = |rng: &mut SmallRng, medium: f64| lu(rng, (medium * 1.01).max(1.0), 1000.0);
    let medium = f.environment.medium_hamaker_zj;
    f.tip.hamaker_zj = above(rng, medium);
    f.substrate.hamaker_zj = above(rng, medium);
    f.particles[0].hamaker_zj = above(rng, medium);
    // Friction.
    let fr = &mut f.friction;
    fr.particle_substrate_static = rng.random_range(0.0..=5.0);
    fr.particle_substrate_kinetic = rng.random_range(0.0..=fr.particle_substrate_static);
    fr.tip_particle_static = rng.random_range(0.0..=5.0);
    fr.tip_particle_kinetic = rng.random_range(0.0..=fr.tip_particle_static);
    fr.contact_damping_ratio = rng.random_range(0.0..=10.0);
    // The stage and the readout.
    let st = &mut f.stage;
    st.resonance_hz = lu(rng, 1.0, 100_000.0);
    st.quality_factor = lu(rng, 0.5, 1000.0);
    st.moving_mass_g = lu(rng, 0.1, 100_000.0);
    let se = &mut f.sensor;
    se.full_scale_v = rng.random_range(1.0..=100.0);
    se.baseline_v = rng.random_range(-0.5..=0.5) * se.full_scale_v.min(10.0);
    let gain = lu(rng, 0.01, 10.0);
    se.gain_v_per_nm = if rng.random_bool(0.5) { gain } else { -gain };
    se.noise_rms_mv = lu(rng, 0.01, 1000.0);
    se.perturbation_mv = if rng.random_bool(0.5) {
        0.0
    } else {
        lu(rng, 0.01, 1000.0)
    };
    se.perturbation_hz = rng.random_range(0.1..=500.0);
    // The terms; the particle's and the lever's degrees of freedom quasi-static (a dynamic one
    // is refused for pushes before any planning: `Scene::pushable`).
    let ph = &mut f.physics;
    ph.van_der_waals = rng.random_bool(0.8);
    ph.capillary = rng.random_bool(0.6);
    ph.electrostatic = rng.random_bool(0.3);
    ph.particle_z = if rng.random_bool(0.8) {
        DofFile::QuasiStatic
    } else {
        DofFile::Off
    };
    ph.particle_rotation = if rng.random_bool(0.8) {
        DofFile::QuasiStatic
    } else {
        DofFile::Off
    };
    ph.stage = if rng.random_bool(0.8) {
        DofFile::Dynamic
    } else {
        DofFile::Off
    };
    f
}

/// One draw over a lab's ranges: AFM levers of 0.1-50 N/m with 2-50 nm tips, particles of
/// 5 nm-5 µm, piezo stages of 100 Hz-5 kHz, readouts of 0.1-2 V/nm with 0.5-20 mV of noise,
/// frictions of 0.05-1, humidity up to 90 %, substrates tilted by up to 10 mrad.
fn draw_lab(rng: &mut SmallRng, base: &SceneFile) -> SceneFile {
    let mut f = draw(rng, base);
    let lu = |rng: &mut SmallRng, lo: f64, hi: f64| log_uniform(rng, lo, hi);
    f.tip.radius_nm = lu(rng, 2.0, 50.0);
    f.tip.youngs_modulus_gpa = lu(rng, 50.0, 400.0);
    f.tip.poisson_ratio = rng.random_range(0.2..=0.35);
    let k = &mut f.cantilever;
    k.stiffness_n_per_m = lu(rng, 0.1, 50.0);
    k.tilt_deg = rng.random_range(0.0..=25.0);
    k.tip_height_um = rng.random_range(3.0..=20.0);
    k.width_um = rng.random_range(20.0..=60.0);
    k.length_um = rng.random_range(100.0..=450.0);
    k.thickness_um = rng.random_range(0.5..=8.0);
    k.resonance_khz = lu(rng, 10.0, 500.0);
    k.quality_factor = lu(rng, 10.0, 1000.0);
    let s = &mut f.substrate;
    s.youngs_modulus_gpa = lu(rng, 10.0, 400.0);
    s.poisson_ratio = rng.random_range(0.17..=0.35);
    s.tilt_x_mrad = rng.random_range(-10.0..=10.0);
    s.tilt_y_mrad = rng.random_range(-10.0..=10.0);
    s.roughness_rms_nm = if rng.random_bool(0.5) {
        0.0
    } else {
        rng.random_range(0.0..=1.0)
    };
    s.roughness_wavelength_um = lu(rng, 0.1, 10.0);
    let p = &mut f.particles[0];
    p.radius_nm = lu(rng, 5.0, 5000.0);
    p.youngs_modulus_gpa = lu(rng, 1.0, 200.0);
    p.poisson_ratio = rng.random_range(0.2..=0.45);
    p.density_kg_per_m3 = rng.random_range(500.0..=20_000.0);
    let e = &mut f.environment;
    e.relative_humidity = rng.random_range(0.0..=0.9);
    e.surface_tension_mj_per_m2 = rng.random_range(20.0..=75.0);
    e.solid_liquid_energy_mj_per_m2 = 0.0;
    e.medium_hamaker_zj = rng.random_range(0.0..=40.0);
    e.interatomic_cutoff_nm = rng.random_range(0.15..=0.2);
    e.tip_particle_voltage_v = rng.random_range(-1.0..=1.0);
    e.particle_substrate_voltage_v = rng.random_range(-1.0..=1.0);
    e.tip_substrate_voltage_v = rng.random_range(-1.0..=1.0);
    let medium = f.environment.medium_hamaker_zj;
    let above = |rng: &mut SmallRng| rng.random_range((medium * 1.2).max(10.0)..=(medium * 1.2).max(10.0) + 300.0);
    f.tip.hamaker_zj = above(rng);
    f.substrate.hamaker_zj = above(rng);
    f.particles[0].hamaker_zj = above(rng);
    let fr = &mut f.friction;
    fr.particle_substrate_static = rng.random_range(0.05..=1.0);
    fr.particle_substrate_kinetic = fr.particle_substrate_static * rng.random_range(0.5..=1.0);
    fr.tip_particle_static = rng.random_range(0.05..=1.0);
    fr.tip_particle_kinetic = fr.tip_particle_static * rng.random_range(0.5..=1.0);
    fr.contact_damping_ratio = rng.random_range(0.01..=0.5);
    let st = &mut f.stage;
    st.resonance_hz = lu(rng, 100.0, 5000.0);
    st.quality_factor = lu(rng, 1.0, 50.0);
    st.moving_mass_g = lu(rng, 10.0, 500.0);
    let se = &mut f.sensor;
    se.full_scale_v = 10.0;
    se.baseline_v = rng.random_range(-0.5..=0.5);
    let gain = lu(rng, 0.1, 2.0);
    se.gain_v_per_nm = if rng.random_bool(0.5) { gain } else { -gain };
    se.noise_rms_mv = lu(rng, 0.5, 20.0);
    se.perturbation_mv = if rng.random_bool(0.5) { 0.0 } else { lu(rng, 1.0, 30.0) };
    se.perturbation_hz = rng.random_range(1.0..=100.0);
    f
}

/// The random scene of `seed` drawn from `ranges`: the first draw the validator accepts, and a
/// push of 0.2-5 µm in a random direction.
pub fn random_scene(seed: u64, ranges: Ranges) -> RandomScene {
    let base = Scene::default_scene().file;
    let mut rng = SmallRng::seed_from_u64(seed);
    for refused_draws in 0..MAX_DRAWS {
        let f = match ranges {
            Ranges::Validator => draw(&mut rng, &base),
            Ranges::Lab => draw_lab(&mut rng, &base),
        };
        let distance = log_uniform(&mut rng, 0.2e-6, 5e-6);
        let angle = rng.random_range(0.0..std::f64::consts::TAU);
        if let Ok(scene) = Scene::from_file_with("<random scene>", f, HandSet::none()) {
            return RandomScene {
                seed,
                scene,
                distance,
                direction: (angle.cos(), angle.sin()),
                refused_draws,
            };
        }
    }
    panic!("no valid scene in {MAX_DRAWS} draws of seed {seed}: the generator is broken");
}

/// A random scene planned, pushed and judged.
#[derive(Debug, Clone)]
pub struct RandomCase {
    /// The seed.
    pub seed: u64,
    /// The scene's main parameters, for the table.
    pub summary: String,
    /// What happened.
    pub judged: Judged,
    /// When the plan refused and named a value it checked: that value applied to the scene,
    /// and the same move planned, pushed and judged again.
    pub advice: Option<AdviceRun>,
}

/// A refusal's checked value, applied: does the move then end `ok`?
#[derive(Debug, Clone)]
pub struct AdviceRun {
    /// The scene field changed.
    pub key: nanopush_instrument::control::derive::AdviceKey,
    /// Its new value as the scene file takes it (the field's unit; the gain with its sign).
    pub value: f64,
    /// The move with it.
    pub judged: Judged,
}

/// The first value `judged`'s refusal names that the plan checked, applied to `scene`, and the
/// same move pushed and judged again.
fn apply_advice(
    scene: &Scene,
    judged: &Judged,
    distance: f64,
    direction: (f64, f64),
    tolerance: f64,
) -> Option<AdviceRun> {
    let a = judged.advice.iter().find(|a| a.checked == Some(true))?;
    let applied = a.applied(scene, a.value)?;
    Some(AdviceRun {
        key: a.key,
        value: a.key.of(&applied),
        judged: push_judged(&applied, distance, direction, tolerance),
    })
}

/// Plans, pushes and judges the random scene of `seed` from `ranges` with `tolerance` (m).
pub fn run_random(seed: u64, ranges: Ranges, tolerance: f64) -> RandomCase {
    let r = random_scene(seed, ranges);
    let f = &r.scene.file;
    let p = &f.particles[0];
    let summary = format!(
        "Rₐ={:.3}µm Rₜ={:.0}nm k={:.3}N/m α={:.0}° RH={:.2} μas={:.2} μta={:.2} g={:.3}V/nm σ={:.1}mV f_y={:.0}Hz d={:.2}µm",
        p.radius_nm * 1e-3,
        f.tip.radius_nm,
        f.cantilever.stiffness_n_per_m,
        f.cantilever.tilt_deg,
        f.environment.relative_humidity,
        f.friction.particle_substrate_static,
        f.friction.tip_particle_static,
        f.sensor.gain_v_per_nm,
        f.sensor.noise_rms_mv,
        f.stage.resonance_hz,
        r.distance * 1e6
    );
    let judged = push_judged(&r.scene, r.distance, r.direction, tolerance);
    let advice = apply_advice(&r.scene, &judged, r.distance, r.direction, tolerance);
    RandomCase {
        seed,
        summary,
        judged,
        advice,
    }
}

/// The scene of `r` as a scene file that plans as the campaign planned it at `tolerance_nm`
/// (as the user gave it, in nm):
/// the derivable settings (`[strategy]`, `push.contact_angle_deg`, `push.speed_um_per_s`) are
/// left out, so a reload derives them all, and a comment says where it came from and gives the
/// commands (with the tolerance, which the plan depends on).
pub fn scene_text(r: &RandomScene, ranges: Ranges, tolerance_nm: f64) -> Result<String, String> {
    let mut table = toml::Table::try_from(&r.scene.file).map_err(|e| e.to_string())?;
    table.remove("strategy");
    if let Some(push) = table.get_mut("push").and_then(toml::Value::as_table_mut) {
        push.remove("contact_angle_deg");
        push.remove("speed_um_per_s");
    }
    table.insert(
        "description".into(),
        format!("random scene of seed {} ({} ranges)", r.seed, ranges.name()).into(),
    );
    let body = toml::to_string(&table).map_err(|e| e.to_string())?;
    let deg = r.direction.1.atan2(r.direction.0).to_degrees();
    let tol = nanopush_instrument::shown(tolerance_nm);
    Ok(format!(
        "# Random scene of seed {seed} ({ranges} ranges), drawn by\n\
         #   nanopush campaign --random 1 --seed {seed} --ranges {ranges} --tolerance-nm {tol}\n\
         # Nothing is hand-set: `nanopush plan --scene THIS --tolerance-nm {tol}` derives the plan\n\
         # the campaign used. The campaign pushed particle {id} by {d} µm at {deg} degrees from +x.\n\
         # The same push (its stage starts elsewhere and it scans first, so its numbers differ a\n\
         # little from the campaign's row, and near the tolerance its outcome may too):\n\
         #   nanopush push --scene THIS --distance-um {d} --direction-deg={deg} --tolerance-nm {tol}\n\n{body}",
        seed = r.seed,
        ranges = ranges.name(),
        id = r.scene.pushed_particle().id,
        d = r.distance * 1e6,
    ))
}

/// The seeds of shard `i` of `n` among `count` seeds from `first`: every n-th, so shards share
/// the work evenly.
pub fn shard_seeds(first: u64, count: u64, i: u64, n: u64) -> Vec<u64> {
    (0..count).filter(|k| k % n == i).map(|k| first + k).collect()
}

#[cfg(test)]
mod tests;
