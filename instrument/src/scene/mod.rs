//! Scenes: one experiment described in a TOML file (user units, the unit in each field's name),
//! validated once and converted to SI once.
//!
//! The default scene, embedded in the binary, is `scenes/paper-default.toml`: the paper's
//! Section 5 parameters, with literature values (and their sources, in comments) for what the
//! paper does not give.

mod error;
pub mod file;
pub mod hand_set;
mod ranges;

pub use error::{SceneError, SceneWarning};
pub use file::SceneFile;
pub use ranges::{
    GAIN_V_PER_NM, MAX_PARTICLES, MAX_SCAN_PIXELS, MIN_SCAN_PIXELS, Range, START_HEIGHT_UM, STIFFNESS_N_PER_M,
};

/// The largest scene file read (bytes): 4 MiB.
pub const MAX_SCENE_BYTES: u64 = 4 << 20;

use crate::physics::cantilever::Cantilever;
use crate::physics::contact::jkr::{Jkr, contact_modulus};
use crate::physics::force_curve::TipSample;
use crate::physics::forces::capillary::{Capillary, kelvin_radius};
use crate::physics::forces::electrostatic::Electrostatic;
use crate::physics::forces::vdw::combined_hamaker;
use crate::physics::friction;
use crate::physics::pushing::{Dof, Dofs, Interactions, LongRange, PushParams};
use crate::physics::sensor::{Readout, Sensor};
use crate::physics::stage::Stage;
use crate::physics::topography::Topography;
use file::{DofFile, ParticleFile};

/// The embedded default scene (the paper's Section 5).
pub const DEFAULT_SCENE: &str = include_str!("../../../scenes/paper-default.toml");

/// A validated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The scene as written (user units).
    pub file: SceneFile,
    /// Where it came from (a path, or `<default scene>`).
    pub origin: String,
    /// What a valid scene does that may not work as intended.
    pub warnings: Vec<SceneWarning>,
    /// The strategy settings the file gives by hand (the planner derives the others).
    pub hand_set: hand_set::HandSet,
}

const NM: f64 = 1e-9;
const UM: f64 = 1e-6;
const GPA: f64 = 1e9;
const ZJ: f64 = 1e-21;
const MJ_M2: f64 = 1e-3;

fn dof(d: DofFile) -> Dof {
    match d {
        DofFile::Dynamic => Dof::Dynamic,
        DofFile::QuasiStatic => Dof::QuasiStatic,
        DofFile::Off => Dof::Off,
    }
}

/// `G = E/(2(1+ν))` (Pa).
fn shear_modulus(e: f64, nu: f64) -> f64 {
    e / (2.0 * (1.0 + nu))
}

/// `G* = ((2−ν₁)/G₁ + (2−ν₂)/G₂)⁻¹` (Sec 2.5).
fn tangential_modulus(e1: f64, nu1: f64, e2: f64, nu2: f64) -> f64 {
    1.0 / ((2.0 - nu1) / shear_modulus(e1, nu1) + (2.0 - nu2) / shear_modulus(e2, nu2))
}

impl Scene {
    /// Parses and validates a scene from TOML text.
    pub fn parse(origin: &str, text: &str) -> Result<Scene, SceneError> {
        let parse_error = |e: toml::de::Error| SceneError::Parse {
            origin: origin.into(),
            message: e.to_string().trim_end().to_string(),
        };
        let table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        let hand_set = hand_set::HandSet::from_table(&table);
        let file: SceneFile = table.try_into().map_err(parse_error)?;
        Scene::from_file_with(origin, file, hand_set)
    }

    /// Validates a scene that is already parsed (e.g. a sweep's copy with one field changed).
    /// Every strategy setting counts as hand-set (see [`Scene::hand_set`]).
    pub fn from_file(origin: &str, file: SceneFile) -> Result<Scene, SceneError> {
        Scene::from_file_with(origin, file, hand_set::HandSet::all())
    }

    /// Validates a parsed scene whose hand-set strategy settings are `hand_set` (the others are
    /// the plan's to derive, and are not checked against the sensor).
    pub fn from_file_with(origin: &str, file: SceneFile, hand_set: hand_set::HandSet) -> Result<Scene, SceneError> {
        ranges::validate(origin, &file, &hand_set)?;
        let mut scene = Scene {
            file,
            origin: origin.into(),
            warnings: Vec::new(),
            hand_set,
        };
        scene.warnings = scene.check_feasibility();
        Ok(scene)
    }

    /// Reads, parses and validates a scene file (at most [`MAX_SCENE_BYTES`]).
    pub fn from_path(path: &std::path::Path) -> Result<Scene, SceneError> {
        let io = |error| SceneError::Io {
            path: path.display().to_string(),
            error,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let mut text = String::new();
        std::io::Read::read_to_string(&mut std::io::Read::take(file, MAX_SCENE_BYTES + 1), &mut text).map_err(io)?;
        if text.len() as u64 > MAX_SCENE_BYTES {
            return Err(SceneError::Inconsistent {
                origin: path.display().to_string(),
                field: "the file".into(),
                message: format!(
                    "larger than {MAX_SCENE_BYTES} bytes; allowed: at most {MAX_SCENE_BYTES} bytes ({MAX_PARTICLES} particles with comments take under 1 MiB)"
                ),
            });
        }
        Scene::parse(&path.display().to_string(), &text)
    }

    /// The embedded default scene.
    pub fn default_scene() -> Scene {
        Scene::parse("<default scene>", DEFAULT_SCENE).expect("the embedded default scene is valid (tested)")
    }

    /// The particle the model pushes.
    pub fn pushed_particle(&self) -> &ParticleFile {
        let id = self.file.push.particle_id;
        self.file
            .particles
            .iter()
            .find(|p| p.id == id)
            .expect("validated: push.particle_id exists")
    }

    fn a0(&self) -> f64 {
        self.file.environment.interatomic_cutoff_nm * NM
    }

    /// Hamaker constant of a pair, across the water layer when the air is humid (Sec 2.2.1).
    fn hamaker(&self, h1_zj: f64, h2_zj: f64) -> f64 {
        let e = &self.file.environment;
        let medium = if e.relative_humidity > 0.0 {
            e.medium_hamaker_zj
        } else {
            0.0
        };
        combined_hamaker(h1_zj * ZJ, h2_zj * ZJ, medium * ZJ)
    }

    /// The cantilever, SI.
    pub fn cantilever(&self) -> Cantilever {
        let c = &self.file.cantilever;
        Cantilever {
            k_c: c.stiffness_n_per_m,
            l_x: c.width_um * UM,
            l_y: c.length_um * UM,
            l_z: c.tip_height_um * UM,
            t_c: c.thickness_um * UM,
            f_r: c.resonance_khz * 1e3,
            q_c: c.quality_factor,
            tilt: c.tilt_deg.to_radians(),
        }
    }

    /// The deflection sensor, SI.
    pub fn sensor(&self) -> Sensor {
        let s = &self.file.sensor;
        Sensor {
            baseline: s.baseline_v,
            gain: s.gain_v_per_nm / NM,
            noise_rms: s.noise_rms_mv * 1e-3,
        }
    }

    /// The sensor readout: noise, periodic perturbation, seed.
    pub fn readout(&self) -> Readout {
        let s = &self.file.sensor;
        Readout::new(self.sensor(), s.perturbation_mv * 1e-3, s.perturbation_hz, s.noise_seed)
            .with_full_scale(s.full_scale_v)
    }

    /// The substrate's topography (tilt and roughness).
    pub fn topography(&self) -> Topography {
        let s = &self.file.substrate;
        Topography::new(
            s.tilt_x_mrad * 1e-3,
            s.tilt_y_mrad * 1e-3,
            s.roughness_rms_nm * NM,
            s.roughness_wavelength_um * UM,
            s.roughness_seed,
        )
    }

    /// The pushing model's parameters for the pushed particle, converted to SI once.
    pub fn push_params(&self) -> PushParams {
        self.push_params_for(self.pushed_particle())
    }

    /// The pushing model's parameters for any particle of the scene (its radius, material).
    pub fn push_params_for(&self, part: &ParticleFile) -> PushParams {
        let f = &self.file;
        let (tip, sub, env, ph) = (&f.tip, &f.substrate, &f.environment, &f.physics);
        let a0 = self.a0();
        let r_t = tip.radius_nm * NM;
        let r_a = part.radius_nm * NM;
        let r_eff = r_t * r_a / (r_t + r_a);
        let (e_t, e_a, e_s) = (
            tip.youngs_modulus_gpa * GPA,
            part.youngs_modulus_gpa * GPA,
            sub.youngs_modulus_gpa * GPA,
        );
        let (nu_t, nu_a, nu_s) = (tip.poisson_ratio, part.poisson_ratio, sub.poisson_ratio);
        let w = env.solid_liquid_energy_mj_per_m2 * MJ_M2;
        let gamma_l = env.surface_tension_mj_per_m2 * MJ_M2;
        let rh = env.relative_humidity;
        let jkr_as = Jkr::new(r_a, contact_modulus(e_a, nu_a, e_s, nu_s), w);
        let jkr_ta = Jkr::new(r_eff, contact_modulus(e_t, nu_t, e_a, nu_a), w);
        let r1 = kelvin_radius(rh);
        let m_a = part.density_kg_per_m3 * 4.0 / 3.0 * std::f64::consts::PI * r_a.powi(3);
        let k_as_t = 8.0 * r_a * tangential_modulus(e_a, nu_a, e_s, nu_s);
        let k_ta_t = 8.0 * r_eff * tangential_modulus(e_t, nu_t, e_a, nu_a);
        let tip_particle = LongRange {
            hamaker: ph.van_der_waals.then(|| self.hamaker(tip.hamaker_zj, part.hamaker_zj)),
            capillary: ph
                .capillary
                .then(|| Capillary::new(r_eff, gamma_l, rh, jkr_ta.meniscus_breaking_length(gamma_l), a0)),
            electrostatic: ph.electrostatic.then_some(Electrostatic {
                voltage: env.tip_particle_voltage_v,
                area: 4.0 * std::f64::consts::PI * r_eff * r1,
                a0,
            }),
        };
        let particle_substrate = LongRange {
            hamaker: ph.van_der_waals.then(|| self.hamaker(part.hamaker_zj, sub.hamaker_zj)),
            capillary: ph.capillary.then(|| {
                Capillary::new(
                    r_a,
                    2.0 * gamma_l,
                    rh,
                    jkr_as.meniscus_breaking_length(2.0 * gamma_l),
                    a0,
                )
            }),
            electrostatic: ph.electrostatic.then_some(Electrostatic {
                voltage: env.particle_substrate_voltage_v,
                area: 4.0 * std::f64::consts::PI * r_a * r1,
                a0,
            }),
        };
        PushParams {
            r_t,
            r_a,
            m_a,
            cantilever: self.cantilever(),
            beta: f.push.contact_angle_deg.to_radians(),
            stage: Stage {
                f_y: f.stage.resonance_hz,
                q_y: f.stage.quality_factor,
                mass: f.stage.moving_mass_g * 1e-3,
            },
            speed: f.push.speed_um_per_s * UM,
            k_as_t,
            k_ta_t,
            b_as: 2.0 * f.friction.contact_damping_ratio * (k_as_t * m_a).sqrt(),
            b_ta: 2.0 * f.friction.contact_damping_ratio * (k_ta_t * m_a).sqrt(),
            mu_as_s: f.friction.particle_substrate_static,
            mu_as_k: f.friction.particle_substrate_kinetic,
            mu_ta_s: f.friction.tip_particle_static,
            mu_ta_k: f.friction.tip_particle_kinetic,
            jkr_as,
            jkr_ta,
            gamma_l,
            interactions: Interactions {
                tip_particle,
                particle_substrate,
                r_t,
                r_a,
                a0,
            },
            dofs: Dofs {
                particle_y: dof(ph.particle_y),
                particle_z: dof(ph.particle_z),
                particle_rotation: dof(ph.particle_rotation),
                cantilever: dof(ph.cantilever),
                stage: dof(ph.stage),
            },
        }
    }

    /// The tip facing the bare substrate, for the force curve of Fig 3.
    pub fn tip_sample(&self) -> TipSample {
        let f = &self.file;
        let (tip, sub, env, ph) = (&f.tip, &f.substrate, &f.environment, &f.physics);
        let a0 = self.a0();
        let r_t = tip.radius_nm * NM;
        let gamma_l = env.surface_tension_mj_per_m2 * MJ_M2;
        let jkr = Jkr::new(
            r_t,
            contact_modulus(
                tip.youngs_modulus_gpa * GPA,
                tip.poisson_ratio,
                sub.youngs_modulus_gpa * GPA,
                sub.poisson_ratio,
            ),
            env.solid_liquid_energy_mj_per_m2 * MJ_M2,
        );
        let long_range = LongRange {
            hamaker: ph.van_der_waals.then(|| self.hamaker(tip.hamaker_zj, sub.hamaker_zj)),
            capillary: ph.capillary.then(|| {
                Capillary::new(
                    r_t,
                    2.0 * gamma_l,
                    env.relative_humidity,
                    jkr.meniscus_breaking_length(2.0 * gamma_l),
                    a0,
                )
            }),
            electrostatic: ph.electrostatic.then_some(Electrostatic {
                voltage: env.tip_substrate_voltage_v,
                area: 4.0 * std::f64::consts::PI * r_t * kelvin_radius(env.relative_humidity),
                a0,
            }),
        };
        TipSample {
            r_t,
            k_c: f.cantilever.stiffness_n_per_m,
            jkr,
            long_range,
            a0,
        }
    }

    /// Warnings for a valid scene: the Eq 16 feasibility window and Eq 8.
    fn check_feasibility(&self) -> Vec<SceneWarning> {
        let f = &self.file;
        let part = self.pushed_particle();
        let c = self.cantilever();
        let r_t = f.tip.radius_nm * NM;
        let r_a = part.radius_nm * NM;
        let beta = f.push.contact_angle_deg.to_radians();
        let mu = f.friction.particle_substrate_static;
        let fz = friction::feasibility(mu, r_a, r_t, beta, c.k_y(), c.k_z(), c.tilt);
        let mut w = Vec::new();
        // At the bound itself (to rounding) Eq 15's denominator vanishes and y* diverges.
        if mu >= fz.upper * (1.0 - 1e-9) {
            w.push(SceneWarning(format!(
                "friction.particle_substrate_static = {mu} is {} the Eq 16 upper bound {:.4} (k_y cot α + k_z tan α)/(k_y − k_z): the particle cannot be pushed, the tip's load never exceeds the static friction (Eq 15's denominator is ≤ 0: no shearing point y*)",
                if mu > fz.upper * (1.0 + 1e-9) { "above" } else { "at" },
                fz.upper
            )));
        }
        if mu < fz.lower {
            w.push(SceneWarning(format!(
                "friction.particle_substrate_static = {mu} is below the Eq 9 lower bound {:.4} = cos β/(2(1+Rₐ/Rₜ)): the push is not reliable (Eq 16 window [{:.4}, {:.4}])",
                fz.lower, fz.lower, fz.upper
            )));
        }
        let tallest = f.particles.iter().map(|p| 2.0 * p.radius_nm * 1e-3).fold(0.0, f64::max);
        // A derived start height clears it (the plan's rule): only a hand-set one is warned about.
        if self.hand_set.contains("strategy.start_height_um") && f.strategy.start_height_um <= tallest {
            w.push(SceneWarning(format!(
                "strategy.start_height_um = {} µm does not clear the tallest particle ({tallest} µm): moves at the start height would run into it",
                f.strategy.start_height_um
            )));
        }
        let r1 = kelvin_radius(f.environment.relative_humidity);
        if f.physics.electrostatic && r1 < self.a0() {
            let rh = crate::words::shown(f.environment.relative_humidity);
            w.push(SceneWarning(if r1 <= 0.0 {
                format!(
                    "physics.electrostatic is on, but at environment.relative_humidity = {rh} there is no meniscus, so the shared area S = 4πR r₁ of Eq 4 is zero and the electrostatic force vanishes"
                )
            } else {
                // Eq 4 still takes its shared area from r₁: the force does not vanish (a refusal
                // in the same output may count a 1240 nN electrostatic pull).
                format!(
                    "physics.electrostatic is on, but at environment.relative_humidity = {rh} the Kelvin radius r₁ = {:.3} nm is below a₀: no meniscus forms, and Eq 4's shared area S = 4πR r₁ rests on a radius smaller than an atom (the electrostatic force scales with it; it vanishes only when dry)",
                    r1 * 1e9
                )
            }));
        }
        if !friction::no_sticking_to_tip(r_a, r_t * r_a / (r_t + r_a), beta) {
            w.push(SceneWarning(
                "Eq 8 fails (Rₐ ≤ 0.5 R̃ sin β): the particle may stick to the tip".into(),
            ));
        }
        w
    }
}

#[cfg(test)]
mod tests;
