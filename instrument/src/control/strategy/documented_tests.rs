//! Pushes whose figures the docs quote: the long gold-latex push under each loop closure and
//! the paper's default push, to the digits the docs give.

use super::tests::{assert_retracted, default_scene, scene};
use crate::afm::Afm;
use crate::control::*;
use crate::scene::Scene;

const UM: f64 = 1e-6;

/// Drift of the reading over a push: the mean of the last 200 samples while rolling less the
/// mean of the first 200 (V).
pub(super) fn reading_drift(run: &StrategyRun) -> f64 {
    let v: Vec<f64> = run
        .trace
        .iter()
        .filter(|r| r.phase == "push" && r.contact == "roll")
        .map(|r| r.volts)
        .collect();
    assert!(v.len() > 1000, "{} rolling samples", v.len());
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    mean(&v[v.len() - 200..]) - mean(&v[..200])
}

/// A push as `nanopush push --distance-um D --control C` makes it (`push_cmd::run` for one leg,
/// without the overview scan, which only finds obstacles): the tip starts 8 µm behind the
/// scene's particle, a local scan locates it, the model prediction takes the located radius, and
/// the particle is pushed `distance` along +x from where it was located. Returns the run and the
/// simulated time at its end (s), docs/manipulation.md's push table's "simulated" ("Measured
/// pushes").
pub(super) fn push_as_the_cli_does(scene: &Scene, distance: f64) -> (StrategyRun, f64) {
    let p = scene.pushed_particle();
    let click = (p.x_um * UM, p.y_um * UM);
    let mut afm = Afm::from_scene(scene, (click.0 - 8.0 * UM).max(0.0), click.1, 1e-3);
    let (_, located) = crate::control::moves::locate::locate_near(
        &afm.surface(),
        crate::scan::Tip::from_scene(scene),
        crate::scan::ScanParams::from_scene(scene),
        click,
        p.radius_nm * 1e-9,
        scene.file.stage.range_um * UM,
    );
    let found = located.expect("the local scan finds the particle");
    let params = scene.strategy_params(1e-3);
    let prepared = Prepared::new(scene, p.id, found.radius, &params).unwrap();
    let request = prepared
        .request(
            p.id,
            (found.x, found.y),
            (found.x + distance, found.y),
            None,
            found.slope,
        )
        .unwrap();
    let run = prepared.run(&mut afm, &request, params).unwrap();
    (run, afm.time())
}

/// Asserts `value` is `readme` to docs/manipulation.md's last printed digit: within `half_unit`,
/// half a unit of that digit.
#[track_caller]
pub(super) fn assert_digits(what: &str, value: f64, readme: f64, half_unit: f64) {
    if std::env::var_os("NANOPUSH_PRINT_DIGITS").is_some() {
        eprintln!("DIGITS {what}: {value} (docs {readme})");
        return;
    }
    assert!(
        (value - readme).abs() <= half_unit,
        "{what}: {value} against the docs' {readme} (± {half_unit})"
    );
}

/// docs/manipulation.md's push table ("Measured pushes"), row "gold-latex, 6 µm, xy / z / xyz
/// control", and its reading-drift paragraph: `nanopush push --scene scenes/gold-latex-500nm.toml
/// --distance-um 6 --control C` (the same pushes, by [`push_as_the_cli_does`]). The scene's
/// substrate rises 6 nm per µm: with the height fixed the reading drifts toward the baseline as the
/// particle climbs (Fig 15, +0.129 V); the z loop holds it, −0.024 V under xyz and under z
/// control, and raises the tip 47 nm for it. xy and xyz end 14.3 nm short; z-only control stops
/// on stage travel planned with the predicted retraction drag (−0.544 µm, the estimator's
/// `retract_shift`) and ends 8.3 nm short (552 nm when its travel did not count the drag: a
/// correction could never make that up). The stick-phase peak the model predicts for these particles is 5.64 nm of `ζ_z`.
#[test]
fn a_long_gold_latex_push_ends_as_documented_under_each_control() {
    use crate::scene::file::ControlFile;
    let base = scene(&[]);
    let run_with = |control: ControlFile| {
        let mut f = base.file.clone();
        f.strategy.control = control;
        let s = Scene::from_file("gold-latex (control)", f).unwrap();
        push_as_the_cli_does(&s, 6.0 * UM).0
    };
    let xy = run_with(ControlFile::Xy);
    let xyz = run_with(ControlFile::Xyz);
    let z = run_with(ControlFile::Z);
    let error_nm = |run: &StrategyRun| (run.true_distance() - 6.0 * UM) / 1e-9;
    for (name, run, readme) in [("xy", &xy, -14.3), ("xyz", &xyz, -14.3)] {
        assert_eq!(run.summary.failure, None, "{name}");
        assert_eq!(run.summary.contact_step, Some(43), "{name}");
        assert_digits(&format!("{name} distance error (nm)"), error_nm(run), readme, 0.05);
    }
    assert_eq!(z.summary.failure, None);
    assert_eq!(z.summary.contact_step, Some(43));
    assert_digits("z distance error (nm)", error_nm(&z), -8.3, 0.05);
    // The drift of the reading, toward the baseline with the height fixed, held by the z loop.
    let (d_xy, d_xyz, d_z) = (reading_drift(&xy), reading_drift(&xyz), reading_drift(&z));
    assert_digits("xy reading drift (V)", d_xy, 0.129, 0.0005);
    assert_digits("xyz reading drift (V)", d_xyz, -0.024, 0.0005);
    assert_digits("z reading drift (V)", d_z, -0.024, 0.0005);
    // How far the z loop raised the tip over the push.
    let rise = |run: &StrategyRun| {
        let z: Vec<f64> = run
            .trace
            .iter()
            .filter(|r| r.phase == "push")
            .map(|r| r.stage[2])
            .collect();
        z[z.len() - 1] - z[0]
    };
    assert_eq!(rise(&xy), 0.0, "the height is fixed under xy control");
    assert_digits("xyz rise of the tip (nm)", rise(&xyz) / 1e-9, 47.0, 0.5);
    assert_digits("z rise of the tip (nm)", rise(&z) / 1e-9, 47.0, 0.5);
    // Both loops push the predicted drag back: z control within the settling lag of xy's.
    let drag = z.prediction.retract_shift;
    assert_digits("predicted retraction drag (µm)", drag / UM, -0.544, 0.0005);
    assert!(
        error_nm(&z).abs() < 25.0,
        "z control ends {:.1} nm off, the drag is {:.1} nm",
        error_nm(&z),
        drag * 1e9
    );
    assert_digits(
        "predicted stick-phase peak ζ_z (nm)",
        z.prediction.peak_deflection / 1e-9,
        5.64,
        0.005,
    );
}

/// docs/manipulation.md's push table ("Measured pushes"), row "paper default (1 µm, rolling),
/// 1 µm": `nanopush push --distance-um 1` (by [`push_as_the_cli_does`]) touches at step 43 and ends
/// 0.9 nm short after 12.9 s of simulated time; the estimator's model predicts a retraction drag of
/// −0.977 µm for the 1 µm particle and a stick-phase peak of 2.57 nm of `ζ_z`.
#[test]
fn the_paper_default_push_touches_ends_and_drags_as_documented() {
    let (run, simulated) = push_as_the_cli_does(&default_scene(&[]), 1.0 * UM);
    assert_eq!(run.summary.failure, None);
    assert_eq!(run.summary.contact_step, Some(43));
    assert_digits(
        "distance error (nm)",
        (run.true_distance() - 1.0 * UM) / 1e-9,
        -0.9,
        0.05,
    );
    assert_digits("simulated time (s)", simulated, 12.9, 0.05);
    assert_digits(
        "predicted retraction drag (µm)",
        run.prediction.retract_shift / UM,
        -0.977,
        0.0005,
    );
    assert_digits(
        "predicted stick-phase peak ζ_z (nm)",
        run.prediction.peak_deflection / 1e-9,
        2.57,
        0.005,
    );
    assert_retracted(&run);
}
