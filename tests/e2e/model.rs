//! `nanopush model`.

use nanopush_e2e::{run, text};
use serde_json::Value;

use crate::util::{nanopush_json as json, tmp};

#[test]
fn default_scene_json_has_the_paper_figures() {
    let v = json(&["model", "--json"]);
    assert_eq!(v["schema"], "nanopush.model");
    assert_eq!(v["version"], 1);
    assert_eq!(v["scene"], "paper-default");
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} missing"));
    assert!((f("k_y") - 1427.0).abs() < 1.0);
    assert!((f("k_yz") - 123.4).abs() < 0.1);
    assert!((f("a_as") - 905e-9).abs() < 1e-9);
    assert!((f("y_star") - 0.22e-9).abs() < 0.005e-9);
    assert!((f("mu_upper_bound") - 3.75).abs() < 0.01);
    assert_eq!(v["mu_feasible"], true);
    assert_eq!(v["state_dimension"], 7);
    assert!(v["steady_state"]["zeta_z"].is_f64());
}

#[test]
fn readable_table_uses_engineering_units() {
    let o = run("nanopush", &["model"], None);
    let (out, _) = text(&o);
    assert!(o.status.success());
    assert!(out.contains("1.4272 kN/m"), "{out}");
    assert!(out.contains("221.4546 pm"), "{out}");
    assert!(out.contains("Eq 16"));
}

#[test]
fn minimal_scene_leaves_out_dofs() {
    let v = json(&["model", "--scene", "scenes/minimal.toml", "--json"]);
    assert_eq!(v["state_dimension"], 3);
    assert_eq!(v["states"], serde_json::json!(["zeta_y", "zeta_z", "particle_y"]));
    assert_eq!(v["r1"], 0.0);
}

#[test]
fn every_shipped_scene_runs() {
    for s in [
        "paper-default",
        "paper-full-dynamics",
        "gold-latex-500nm",
        "gold-14nm",
        "minimal",
    ] {
        let path = format!("scenes/{s}.toml");
        let v = json(&["model", "--scene", &path, "--json"]);
        assert_eq!(v["scene"], s);
        assert!(v["warnings"].as_array().unwrap().is_empty(), "{s}: {}", v["warnings"]);
    }
}

#[test]
fn force_curve_shows_hysteresis() {
    let v = json(&["model", "--force-curve", "--json", "--steps", "300"]);
    assert_eq!(v["schema"], "nanopush.force_curve");
    let approach = v["approach"].as_array().unwrap();
    let retraction = v["retraction"].as_array().unwrap();
    assert_eq!(approach.len(), 301);
    assert_eq!(retraction.len(), 301);
    let pull_off = v["pull_off_force"].as_f64().unwrap();
    assert!(pull_off < -10e-9, "pull-off {pull_off}");
    assert!(v["pull_off_distance"].as_f64().unwrap() > v["snap_in_distance"].as_f64().unwrap());
}

#[test]
fn bad_scene_gets_one_clear_error_and_no_panic() {
    let dir = tmp("model-bad-scene");
    let good = std::fs::read_to_string(nanopush_e2e::workspace().join("scenes/paper-default.toml")).unwrap();
    let cases = [
        (
            "radius_nm = 30.0",
            "radius_nm = -1.0",
            "tip.radius_nm = -1 is out of range; allowed: [1, 1000] nm",
        ),
        (
            "relative_humidity = 0.73",
            "relative_humidity = 1.5",
            "environment.relative_humidity = 1.5 is out of range; allowed: [0, 1)",
        ),
        (
            "tilt_deg = 15.0",
            "tilt_deg = nan",
            "cantilever.tilt_deg = NaN is not a finite number",
        ),
        (
            "radius_nm = 30.0",
            "radius_nm = 30.0\ncolour = \"red\"",
            "unknown field `colour`",
        ),
    ];
    for (i, (from, to, expected)) in cases.iter().enumerate() {
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, good.replacen(from, to, 1)).unwrap();
        let o = run("nanopush", &["model", "--scene", path.to_str().unwrap()], None);
        let (out, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(out.is_empty());
        assert!(err.contains(expected), "expected {expected:?} in: {err}");
        assert!(!err.contains("panicked"), "{err}");
        if i == 1 {
            // docs/model.md's example ("Scenes"), whole: the file's name once, the unit last.
            let p = path.display();
            let line = format!(
                "error: scene {p}: environment.relative_humidity = 1.5 is out of range; allowed: [0, 1) (P/Pₛ)"
            );
            assert!(err.lines().any(|l| l == line), "expected the line {line:?} in: {err}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_missing_scene_file_is_named_in_the_error() {
    let o = run("nanopush", &["model", "--scene", "/no/such/scene.toml"], None);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2));
    assert!(err.contains("cannot read scene file /no/such/scene.toml"), "{err}");
}

#[test]
fn infeasible_friction_is_a_warning() {
    let dir = tmp("mu");
    let good = std::fs::read_to_string(nanopush_e2e::workspace().join("scenes/paper-default.toml")).unwrap();
    let path = dir.join("mu.toml");
    std::fs::write(
        &path,
        good.replacen("particle_substrate_static = 0.3", "particle_substrate_static = 4.5", 1),
    )
    .unwrap();
    let o = run(
        "nanopush",
        &["model", "--scene", path.to_str().unwrap(), "--json"],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning:") && err.contains("cannot be pushed"), "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["mu_feasible"], false);
    assert!(v["y_star"].is_null());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn out_of_range_steps_is_refused_by_the_cli() {
    let o = run("nanopush", &["model", "--force-curve", "--steps", "3"], None);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2));
    assert!(err.contains("--steps") && err.contains("10..=100000"), "{err}");
}
