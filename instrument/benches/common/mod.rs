//! What the benchmarks share: a shipped scene's push, warmed up to where a benchmark measures.

use std::path::Path;

use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::{PushModel, Simulation};
use nanopush_instrument::scene::Scene;

/// The shipped scene `name` (`scenes/NAME.toml`).
pub fn shipped_scene(name: &str) -> Scene {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    Scene::from_path(&dir.join(format!("{name}.toml"))).expect("shipped scene")
}

/// The scene's push (Rodas4 at rtol 1e-6), advanced 20 ms: past the approach, in contact.
#[allow(dead_code)] // each bench compiles this module; the dual bench needs only the scene
pub fn warmed_up(name: &str) -> Simulation {
    let mut sim = Simulation::new(
        PushModel::new(shipped_scene(name).push_params()),
        Method::Rodas4,
        Options::with_rtol(1e-6),
    );
    sim.advance_to(20e-3).expect("warm-up");
    sim
}
