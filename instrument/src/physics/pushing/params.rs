//! The SI parameter set of the pushing model, assembled from a scene (see `scene::Scene::model`).

use crate::numerics::dual::Real;
use crate::physics::cantilever::Cantilever;
use crate::physics::contact::jkr::Jkr;
use crate::physics::forces::capillary::{Capillary, Meniscus};
use crate::physics::forces::electrostatic::Electrostatic;
use crate::physics::forces::vdw;
use crate::physics::stage::Stage;

/// How a mechanical degree of freedom enters the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dof {
    /// Position and velocity are states; Newton's law with the DOF's inertia.
    Dynamic,
    /// Inertia left out: the position is an algebraic state held at force balance (a DAE row
    /// with zero mass), which removes its (1e-9..1e-12 s) time scale from the problem.
    QuasiStatic,
    /// Left out entirely: not in the state vector, frozen at its initial value.
    Off,
}

/// The long-range (non-contact) forces of one pair; a term the scene leaves out is `None` and is
/// never evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LongRange {
    /// Hamaker constant of the pair (J) when van der Waals is included.
    pub hamaker: Option<f64>,
    /// The capillary pair when capillary forces are included.
    pub capillary: Option<Capillary>,
    /// The electrostatic pair when electrostatics are included.
    pub electrostatic: Option<Electrostatic>,
}

/// The two long-range pairs of the pushing geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interactions {
    /// Tip-particle (sphere-sphere, Eq 1 / Eq 3 with R̃ / Eq 4 with 4πR̃r₁).
    pub tip_particle: LongRange,
    /// Particle-substrate (sphere-plane, Eq 2 / Eq 3 with Rₐ, 2γ_L / Eq 4 with 4πRₐr₁).
    pub particle_substrate: LongRange,
    /// Tip radius `Rₜ` (m).
    pub r_t: f64,
    /// Particle radius `Rₐ` (m).
    pub r_a: f64,
    /// Interatomic cut-off `a₀` (m).
    pub a0: f64,
}

/// One source of an adhesion: a long-range term, or the solids' JKR work of adhesion. Names the
/// scene's field that sets it, so a refusal caused by an adhesion names what to change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Attraction {
    /// Van der Waals (Eqs 1-2): the Hamaker constants.
    VanDerWaals,
    /// The meniscus (Eq 3): the humidity.
    Capillary,
    /// The work-function voltage (Eq 4).
    Electrostatic,
    /// The JKR pull-off `(3/2)πRw` of the solid contact: the solid-liquid energy.
    Contact,
}

impl Attraction {
    /// The terms among `terms` (each the attraction it contributes, N, positive = pulling) that
    /// pull at least a quarter as hard as the strongest, strongest first; empty when none pulls.
    pub fn ranked(terms: impl IntoIterator<Item = (Attraction, f64)>) -> Vec<Attraction> {
        let mut pulling: Vec<_> = terms.into_iter().filter(|(_, f)| f.is_finite() && *f > 0.0).collect();
        pulling.sort_by(|a, b| b.1.total_cmp(&a.1));
        let strongest = pulling.first().map_or(0.0, |t| t.1);
        pulling
            .into_iter()
            .filter(|t| t.1 >= 0.25 * strongest)
            .map(|t| t.0)
            .collect()
    }
}

impl LongRange {
    /// Sum of the included terms between two spheres `Rₜ`, `Rₐ` at gap `h` (N, negative =
    /// attractive): Eq 1 + Eq 3 + Eq 4.
    pub fn sphere_sphere<T: Real>(&self, r_t: f64, r_a: f64, h: T, meniscus: Meniscus, a0: f64) -> T {
        let mut f = T::cst(0.0);
        if let Some(hm) = self.hamaker {
            f += vdw::sphere_sphere_force(hm, r_t, r_a, h, a0);
        }
        self.add_capillary_electrostatic(f, h, meniscus)
    }

    /// Sum of the included terms between a sphere `R` and a plane at gap `h` (N): Eq 2 + Eq 3
    /// (substrate form) + Eq 4.
    pub fn sphere_plane<T: Real>(&self, r: f64, h: T, meniscus: Meniscus, a0: f64) -> T {
        let mut f = T::cst(0.0);
        if let Some(hm) = self.hamaker {
            f += vdw::sphere_plane_force(hm, r, h, a0);
        }
        self.add_capillary_electrostatic(f, h, meniscus)
    }

    /// This pair with only the term `a` kept (the others left out).
    fn only(&self, a: Attraction) -> LongRange {
        LongRange {
            hamaker: self.hamaker.filter(|_| a == Attraction::VanDerWaals),
            capillary: self.capillary.filter(|_| a == Attraction::Capillary),
            electrostatic: self.electrostatic.filter(|_| a == Attraction::Electrostatic),
        }
    }

    /// Each included term's attraction (N, positive = pulling) at gap `h` between two spheres,
    /// or between a sphere `r_t` and a plane when `r_a` is `None`.
    pub fn terms(&self, r_t: f64, r_a: Option<f64>, h: f64, meniscus: Meniscus, a0: f64) -> Vec<(Attraction, f64)> {
        [
            Attraction::VanDerWaals,
            Attraction::Capillary,
            Attraction::Electrostatic,
        ]
        .into_iter()
        .map(|a| {
            let one = self.only(a);
            let f = match r_a {
                Some(r_a) => one.sphere_sphere(r_t, r_a, h, meniscus, a0),
                None => one.sphere_plane(r_t, h, meniscus, a0),
            };
            (a, -f)
        })
        .collect()
    }

    fn add_capillary_electrostatic<T: Real>(&self, mut f: T, h: T, meniscus: Meniscus) -> T {
        if let Some(c) = &self.capillary {
            f += c.force(meniscus, h);
        }
        if let Some(e) = &self.electrostatic {
            f += e.force(h);
        }
        f
    }
}

impl Interactions {
    /// Sum of the included tip-particle long-range forces at gap `h` (N, negative = attractive).
    pub fn tip_particle_force<T: Real>(&self, h: T, meniscus: Meniscus) -> T {
        self.tip_particle
            .sphere_sphere(self.r_t, self.r_a, h, meniscus, self.a0)
    }

    /// Sum of the included particle-substrate long-range forces at gap `h` (N); the particle sits
    /// on the substrate, so its meniscus is always formed when capillary forces are included.
    pub fn particle_substrate_force<T: Real>(&self, h: T) -> T {
        self.particle_substrate
            .sphere_plane(self.r_a, h, Meniscus::Formed, self.a0)
    }
}

/// Which degrees of freedom the model carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dofs {
    /// Particle position along the push (never `Off`: it is what is pushed).
    pub particle_y: Dof,
    /// Particle vertical position (indentation into the substrate).
    pub particle_z: Dof,
    /// Particle rotation (rolling).
    pub particle_rotation: Dof,
    /// Cantilever y/z deflection (never `Off`: the tip must move to measure ζ_z).
    pub cantilever: Dof,
    /// Stage: `Dynamic` follows Eq 13; `Off` is an ideal stage at constant speed `V`.
    pub stage: Dof,
}

/// Every SI parameter the pushing model needs (Sec 2.4, 2.5, 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushParams {
    /// Tip radius `Rₜ` (m).
    pub r_t: f64,
    /// Particle radius `Rₐ` (m).
    pub r_a: f64,
    /// Particle mass `mₐ` (kg).
    pub m_a: f64,
    /// The cantilever (stiffness, geometry, `f_r`, `Q_c`, tilt `α`).
    pub cantilever: Cantilever,
    /// Tip-particle contact angle `β` (rad): the tip centre sits at `β` above the horizontal
    /// through the particle centre.
    pub beta: f64,
    /// The piezo stage (Eq 13).
    pub stage: Stage,
    /// Stage speed `V` (m/s).
    pub speed: f64,
    /// Particle-substrate tangential contact stiffness `k_as* = 8RₐG*` (N/m).
    pub k_as_t: f64,
    /// Tip-particle tangential contact stiffness `k_ta* = 8R̃G*_ta` (N/m).
    pub k_ta_t: f64,
    /// Particle-substrate damping `b_as` (N·s/m), on the contact's normal and tangential rates.
    pub b_as: f64,
    /// Tip-particle contact damping `b_ta` (N·s/m), on the contact's normal and tangential
    /// rates. The paper neglects it; without it the rolling mode of a free particle (tip
    /// tangential spring against the particle's inertia, ~25 ns) would ring for ever.
    pub b_ta: f64,
    /// Static / kinetic friction coefficients, particle-substrate and tip-particle.
    pub mu_as_s: f64,
    /// Kinetic particle-substrate friction coefficient.
    pub mu_as_k: f64,
    /// Static tip-particle friction coefficient.
    pub mu_ta_s: f64,
    /// Kinetic tip-particle friction coefficient.
    pub mu_ta_k: f64,
    /// Particle-substrate JKR contact (Eq 5).
    pub jkr_as: Jkr,
    /// Tip-particle JKR contact (Eq 5, effective radius R̃).
    pub jkr_ta: Jkr,
    /// Liquid surface energy `γ_L` (J/m²), for the paper's `A_as`, `A_ta`.
    pub gamma_l: f64,
    /// Long-range forces.
    pub interactions: Interactions,
    /// Degrees of freedom.
    pub dofs: Dofs,
}

impl PushParams {
    /// No friction at either contact: every `μ` zero.
    pub fn frictionless(&self) -> bool {
        [self.mu_as_s, self.mu_as_k, self.mu_ta_s, self.mu_ta_k]
            .iter()
            .all(|&m| m == 0.0)
    }

    /// `R̃ = RₜRₐ/(Rₜ + Rₐ)` (m).
    pub fn r_eff(&self) -> f64 {
        self.r_t * self.r_a / (self.r_t + self.r_a)
    }
    /// `I₀ = 2mₐRₐ²/5` (kg·m²).
    pub fn inertia(&self) -> f64 {
        0.4 * self.m_a * self.r_a * self.r_a
    }
    /// The paper's `A_as = 4πRₐγ_L` (N), Eq 6.
    pub fn paper_adhesion_as(&self) -> f64 {
        4.0 * std::f64::consts::PI * self.r_a * self.gamma_l
    }
    /// The paper's `A_ta = 2πR̃γ_L` (N), Eq 7.
    pub fn paper_adhesion_ta(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.r_eff() * self.gamma_l
    }
    /// The adhesion that the particle-substrate friction sees (Eq 6's `A_as`), from the terms the
    /// scene includes: the long-range attraction at contact plus the JKR pull-off `(3/2)πRₐw`.
    /// Equals the paper's `4πRₐγ_L` for a capillary-only scene.
    pub fn adhesion_as(&self) -> f64 {
        -self.interactions.particle_substrate_force(self.interactions.a0) - self.jkr_as.pull_off_load()
    }
    /// The long-range part of [`Self::adhesion_as`]: the included attraction at contact (N).
    pub fn attraction_as(&self) -> f64 {
        -self.interactions.particle_substrate_force(self.interactions.a0)
    }
    /// The tip-particle adhesion (Eq 7's `A_ta`) from the included terms, at contact with the
    /// meniscus formed: `2πR̃γ_L` for a capillary-only scene.
    pub fn adhesion_ta(&self) -> f64 {
        -self
            .interactions
            .tip_particle_force(self.interactions.a0, Meniscus::Formed)
            - self.jkr_ta.pull_off_load()
    }
    /// The terms of [`Self::adhesion_ta`] that pull hardest ([`Attraction::ranked`]).
    pub fn adhesion_ta_sources(&self) -> Vec<Attraction> {
        let i = &self.interactions;
        let mut terms = i.tip_particle.terms(i.r_t, Some(i.r_a), i.a0, Meniscus::Formed, i.a0);
        terms.push((Attraction::Contact, -self.jkr_ta.pull_off_load()));
        Attraction::ranked(terms)
    }
}

#[cfg(test)]
mod tests {
    //! The derived parameters by hand, from the default scene's numbers (Sec 5: Rₜ = 30 nm,
    //! Rₐ = 1 µm, γ_L = 72 mJ/m², polystyrene at 1050 kg/m³).
    use crate::scene::{DEFAULT_SCENE, Scene};
    use std::f64::consts::PI;

    fn params(text: &str) -> super::PushParams {
        Scene::parse("test", text).unwrap().push_params()
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    #[test]
    fn effective_radius_inertia_and_the_papers_adhesions_by_hand() {
        let p = params(DEFAULT_SCENE);
        // R̃ = 30·1000/1030 nm.
        assert!(rel(p.r_eff(), 30e-9 * 1000.0 / 1030.0) < 1e-12, "{}", p.r_eff());
        // mₐ = ρ·4πRₐ³/3 = 4.3982e-15 kg; I₀ = 2mₐRₐ²/5 = 1.7593e-27 kg·m².
        let m_a = 1050.0 * 4.0 / 3.0 * PI * 1e-18;
        assert!(rel(p.m_a, m_a) < 1e-12);
        assert!(rel(p.inertia(), 0.4 * m_a * 1e-12) < 1e-12, "{}", p.inertia());
        assert!(rel(p.inertia(), 1.7593e-27) < 1e-4);
        // Eq 6: A_as = 4πRₐγ_L = 904.78 nN; Eq 7: A_ta = 2πR̃γ_L = 13.176 nN.
        assert!(
            rel(p.paper_adhesion_as(), 904.78e-9) < 1e-5,
            "{}",
            p.paper_adhesion_as()
        );
        assert!(
            rel(p.paper_adhesion_ta(), 13.1765e-9) < 1e-5,
            "{}",
            p.paper_adhesion_ta()
        );
    }

    /// With capillary forces alone and Hertz contacts (γ_SL = 0 in the default scene: no JKR
    /// pull-off) the adhesions the friction sees are the paper's, Eq 6 and 7, and all of the
    /// substrate's is the long-range attraction. Van der Waals adds to both.
    #[test]
    fn a_capillary_only_scene_has_the_papers_adhesions() {
        let wet = DEFAULT_SCENE.replace("van_der_waals = true", "van_der_waals = false");
        let p = params(&wet);
        assert_eq!(p.jkr_as.pull_off_load(), 0.0);
        assert!(
            rel(p.adhesion_as(), p.paper_adhesion_as()) < 1e-9,
            "{} vs {}",
            p.adhesion_as(),
            p.paper_adhesion_as()
        );
        assert!(
            rel(p.adhesion_ta(), p.paper_adhesion_ta()) < 1e-9,
            "{} vs {}",
            p.adhesion_ta(),
            p.paper_adhesion_ta()
        );
        assert_eq!(p.attraction_as(), p.adhesion_as());
        let q = params(DEFAULT_SCENE);
        assert!(q.adhesion_as() > p.adhesion_as() && q.adhesion_ta() > p.adhesion_ta());
        assert_eq!(q.attraction_as(), q.adhesion_as());
    }

    /// A JKR contact (γ_SL > 0) adds its pull-off `(3/2)πRw` to the adhesion but not to the
    /// long-range attraction.
    #[test]
    fn a_jkr_contact_adds_its_pull_off_to_the_adhesion_only() {
        let sticky = DEFAULT_SCENE.replace(
            "solid_liquid_energy_mj_per_m2 = 0.0",
            "solid_liquid_energy_mj_per_m2 = 20.0",
        );
        let p = params(&sticky);
        let (as_pull, ta_pull) = (-p.jkr_as.pull_off_load(), -p.jkr_ta.pull_off_load());
        assert!(as_pull > 0.0 && ta_pull > 0.0);
        assert!(rel(p.adhesion_as() - p.attraction_as(), as_pull) < 1e-9);
        let hertz = params(DEFAULT_SCENE);
        assert!(
            rel(p.adhesion_ta() - hertz.adhesion_ta(), ta_pull) < 1e-9,
            "the tip's adhesion gains the pull-off"
        );
        let dry = params(
            &DEFAULT_SCENE
                .replace(
                    "solid_liquid_energy_mj_per_m2 = 0.0",
                    "solid_liquid_energy_mj_per_m2 = 20.0",
                )
                .replace("capillary = true", "capillary = false"),
        );
        assert!(
            dry.adhesion_ta() > -dry.jkr_ta.pull_off_load(),
            "van der Waals adds to the pull-off"
        );
        assert!(p.adhesion_ta() > dry.adhesion_ta(), "the meniscus adds to the adhesion");
    }

    #[test]
    fn frictionless_means_every_coefficient_zero() {
        let p = params(DEFAULT_SCENE);
        assert!(!p.frictionless());
        let mut text = DEFAULT_SCENE.to_string();
        for key in [
            "particle_substrate_kinetic",
            "particle_substrate_static",
            "tip_particle_kinetic",
            "tip_particle_static",
        ] {
            assert!(!params(&text).frictionless(), "{key} still nonzero");
            text = text
                .replace(&format!("{key} = 0.3 "), &format!("{key} = 0.0 "))
                .replace(&format!("{key} = 0.2 "), &format!("{key} = 0.0 "));
        }
        assert!(params(&text).frictionless());
    }
}
