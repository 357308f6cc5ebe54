//! The SI parameter set of the pushing model, assembled from a scene (see `scene::Scene::model`).

use crate::physics::cantilever::Cantilever;
use crate::physics::contact::jkr::Jkr;
use crate::physics::forces::capillary::{Capillary, Meniscus};
use crate::physics::forces::electrostatic::Electrostatic;
use crate::physics::forces::vdw;
use crate::physics::real::Real;
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
}
