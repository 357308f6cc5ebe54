//! Assemblies against the simulated AFM, checked against the truth.

use super::*;
use crate::afm::Afm;
use crate::assembly::pattern::Pattern;
use crate::scene::Scene;

const UM: f64 = 1e-6;

/// The shipped assembly scene cut to four particles around (50, 50) µm, scanned 40 µm wide at
/// 128 pixels (a debug build scans slowly).
fn small_scene() -> Scene {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/assembly-latex.toml")).unwrap();
    let mut scene = Scene::parse("assembly-latex", &text).unwrap();
    let keep = [(44.0, 47.0), (57.0, 45.0), (50.0, 58.0), (38.0, 56.0)];
    scene.file.particles.truncate(keep.len());
    for (p, (x, y)) in scene.file.particles.iter_mut().zip(keep) {
        p.x_um = x;
        p.y_um = y;
    }
    scene.file.push.particle_id = 1;
    scene.file.scan.size_um = 40.0;
    scene.file.scan.pixels = 128;
    Scene::parse("small", &toml::to_string(&scene.file).unwrap()).unwrap()
}

/// Three sites of a line filled from four particles: every site filled within its tolerance
/// by the truth, every move a single push or two, nothing pushed through anything.
#[test]
fn a_line_of_three_is_filled_within_tolerance_by_the_truth() {
    let scene = small_scene();
    let mut afm = Afm::from_scene(&scene, 30.0 * UM, 30.0 * UM, 1e-3);
    let pattern = Pattern::generate("line:n=3,spacing_um=3", (50.0 * UM, 51.0 * UM)).unwrap();
    let mut events = Vec::new();
    let run = assemble(
        &scene,
        &mut afm,
        &pattern,
        &AssemblyOptions::default(),
        &mut |e| {
            events.push(match e {
                Event::Planned { .. } => "planned",
                Event::MoveStarted { .. } => "started",
                Event::MoveEnded { .. } => "ended",
                Event::SiteFilled { .. } => "filled",
                Event::Replanned { .. } => "replanned",
            })
        },
        &|| false,
    );
    assert_eq!(run.outcome, Outcome::Filled, "{:?}", run.sites);
    assert!(run.violations.is_empty(), "{:?}", run.violations);
    for s in &run.sites {
        assert_eq!(s.status, "filled");
        let e = s.error.expect("the truth's error");
        assert!(e <= s.tolerance, "true error {e:e} beyond {:e}", s.tolerance);
    }
    assert_eq!(events.first(), Some(&"planned"));
    assert_eq!(events.iter().filter(|e| **e == "filled").count(), 3, "{events:?}");
    assert_eq!(run.moves.len(), 3, "{:?}", run.moves);
    assert!(run.push_time > 0.0 && run.scan_time > 0.0);
}

/// A stop asked before the first move ends the assembly stopped, with nothing moved and the
/// sites judged by the last full frame.
#[test]
fn a_stop_before_the_first_move_moves_nothing() {
    let scene = small_scene();
    let mut afm = Afm::from_scene(&scene, 30.0 * UM, 30.0 * UM, 1e-3);
    let before: Vec<(f64, f64)> = afm.particles().iter().map(|p| (p.x, p.y)).collect();
    let pattern = Pattern::generate("line:n=3,spacing_um=3", (50.0 * UM, 51.0 * UM)).unwrap();
    let run = assemble(
        &scene,
        &mut afm,
        &pattern,
        &AssemblyOptions::default(),
        &mut |_| {},
        &|| true,
    );
    assert_eq!(run.outcome, Outcome::Stopped);
    assert!(run.moves.is_empty());
    let after: Vec<(f64, f64)> = afm.particles().iter().map(|p| (p.x, p.y)).collect();
    assert_eq!(before, after);
    assert_eq!(run.push_time, 0.0);
}

/// A pattern off the stage is refused before anything moves, saying which site and the range.
#[test]
fn a_pattern_off_the_stage_is_refused_before_anything_moves() {
    let scene = small_scene();
    let mut afm = Afm::from_scene(&scene, 30.0 * UM, 30.0 * UM, 1e-3);
    let pattern = Pattern::generate("line:n=3,spacing_um=3", (99.0 * UM, 51.0 * UM)).unwrap();
    let run = assemble(
        &scene,
        &mut afm,
        &pattern,
        &AssemblyOptions::default(),
        &mut |_| {},
        &|| false,
    );
    assert_eq!(run.outcome, Outcome::Refused);
    assert!(run.moves.is_empty());
    let why = run.refusal.unwrap();
    assert!(
        why.starts_with("site 2 at (102.000, 51.000) µm is off the stage"),
        "{why}"
    );
    assert!(why.contains("allowed: [0.5"), "{why}");
}
