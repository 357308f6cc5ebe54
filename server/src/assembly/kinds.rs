//! The push strategy of each kind of particle (size and material), derived once from the scene's
//! model and reused for every particle of that kind, as `nanopush assemble` does.

use nanopush_instrument::control::derive::{DerivedStrategy, derive};
use nanopush_instrument::scene::Scene;
use nanopush_instrument::scene::file::ParticleFile;

use crate::app_state::AppState;

/// A kind: the scene's numbers that make a particle's model (radius, modulus, Poisson ratio,
/// density, Hamaker constant), as bits.
type Key = [u64; 5];

fn key(p: &ParticleFile) -> Key {
    [
        p.radius_nm.to_bits(),
        p.youngs_modulus_gpa.to_bits(),
        p.poisson_ratio.to_bits(),
        p.density_kg_per_m3.to_bits(),
        p.hamaker_zj.to_bits(),
    ]
}

/// A kind's strategy: derived, and applied to the scene.
#[derive(Debug, Clone)]
pub(super) struct Kind {
    /// The scene with the kind's strategy (hand-set values win).
    pub scene: Scene,
    /// The derived strategy, for the push's corrections to reuse.
    pub derived: DerivedStrategy,
}

/// The kinds met so far.
#[derive(Debug, Default)]
pub(super) struct Kinds {
    derived: Vec<(Key, Result<DerivedStrategy, String>)>,
}

impl Kinds {
    /// The strategy for particle `id`'s kind, derived for `tolerance` the first time the kind is
    /// sent; or why the strategy refuses the kind (or the scene has no such particle).
    pub fn strategy(&mut self, st: &AppState, id: u32, tolerance: f64) -> Result<Kind, String> {
        let part = particle(st, id).ok_or_else(|| format!("the scene has no particle {id}"))?;
        let k = key(part);
        let outcome = match self.derived.iter().find(|(kk, _)| *kk == k) {
            Some((_, o)) => o.clone(),
            None => {
                let o = derive(&st.scene, id, tolerance)
                    .map_err(|e| format!("the strategy refuses particles of its kind: {e}"));
                self.derived.push((k, o.clone()));
                o
            }
        };
        let derived = outcome?;
        let mut scene = st.scene.clone();
        derived.apply(&mut scene);
        Ok(Kind { scene, derived })
    }

    /// Whether particles `a` and `b` of the scene are of one kind.
    pub fn same_kind(&self, st: &AppState, a: u32, b: u32) -> bool {
        match (particle(st, a), particle(st, b)) {
            (Some(a), Some(b)) => key(a) == key(b),
            _ => false,
        }
    }
}

fn particle(st: &AppState, id: u32) -> Option<&ParticleFile> {
    st.scene.file.particles.iter().find(|p| p.id == id)
}

/// Gives particle `id` at `tolerance` its kind's strategy in the server's plans, so that the
/// push's corrections (`push::judge`) use it rather than deriving their own.
pub(super) fn lend(st: &AppState, id: u32, tolerance: f64, derived: &DerivedStrategy) {
    if let Ok(mut plans) = st.activity.plans.lock() {
        if plans.len() >= crate::push::launch::PLANS_KEPT {
            plans.clear();
        }
        plans.insert((id, tolerance.to_bits()), Ok(derived.clone()));
    }
}
