//! `nanopush simulate` and `nanopush accuracy`.

use nanopush_e2e::{run, text};

use crate::util::{nanopush_json, tmp};

#[test]
fn simulate_minimal_scene_shears_and_writes_a_trace() {
    let dir = tmp("sim");
    let csv = dir.join("trace.csv");
    let v = nanopush_json(&[
        "simulate",
        "--scene",
        "scenes/minimal.toml",
        "--duration",
        "0.02",
        "--sample",
        "1e-3",
        "--out",
        csv.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(v["schema"], "nanopush.simulate");
    // The minimal scene shears after a few nm of travel and then slides with the stage.
    let t_star = v["shearing_time"].as_f64().expect("it shears");
    assert!(t_star > 0.0 && t_star < 0.02);
    assert_eq!(v["final_phase"], "slip");
    assert!(v["final_particle_y"].as_f64().unwrap() > 5e-9);
    assert!(v["steps"].as_u64().unwrap() > 0);
    assert!(v["real_time_factor"].as_f64().unwrap() > 0.0);
    assert!(v["estimated_error_y"].as_f64().expect("the rerun succeeds at 1e-8") < 1e-12);
    let trace = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = trace.lines().collect();
    assert!(lines[0].starts_with("t_s,stage_y_m,particle_y_m,particle_z_m,theta_rad,zeta_y_m,zeta_z_m"));
    assert_eq!(lines.len(), 1 + 21);
    assert_eq!(v["trace_rows"], 21);
    assert!(lines[1..].iter().all(|l| l.split(',').count() == 12));
    assert!(!dir.join("trace.csv.partial").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn simulate_rejects_bad_arguments_clearly() {
    for (args, expected) in [
        (
            vec!["simulate", "--method", "euler"],
            "--method euler: unknown; allowed: rodas4, rodas5p, trbdf2, implicit-euler",
        ),
        (
            vec!["simulate", "--duration", "0"],
            "--duration 0 s is out of range; allowed: (0, 100] s",
        ),
        (vec!["simulate", "--rtol", "NaN"], "--rtol NaN is out of range"),
        (
            vec!["simulate", "--duration", "1", "--sample", "2"],
            "--sample 2 s is out of range",
        ),
    ] {
        let o = run("nanopush", &args, None);
        let (_, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: expected {expected:?} in {err}");
        assert!(!err.contains("panicked"));
    }
}

#[test]
fn accuracy_report_writes_table_csv_and_plots() {
    let dir = tmp("acc");
    let v = nanopush_json(&[
        "accuracy",
        "--scene",
        "scenes/minimal.toml",
        "--duration",
        "0.002",
        "--reps",
        "1",
        "--min-rtol",
        "1e-4",
        "--no-full-model",
        "--out",
        dir.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(v["schema"], "nanopush.accuracy");
    let points = v["points"].as_array().unwrap();
    // Ours: 4 methods x 3 tolerances x 3 problems; peers: 4 solvers x 3 tolerances x 2 problems.
    assert_eq!(points.len(), 36 + 24);
    assert_eq!(v["equal_error"].as_array().unwrap().len(), 6);
    // Rodas4 on Robertson: the error falls with the tolerance.
    let rob: Vec<f64> = points
        .iter()
        .filter(|p| p["problem"] == "robertson" && p["method"] == "rodas4")
        .map(|p| p["final_error"].as_f64().unwrap())
        .collect();
    assert!(rob.windows(2).all(|w| w[1] < w[0]), "{rob:?}");
    // The estimate (difference from the next finer tolerance) tracks the true error.
    for p in points
        .iter()
        .filter(|p| p["problem"] == "robertson" && p["method"] == "rodas4")
    {
        if let Some(est) = p["estimated_error"].as_f64() {
            let err = p["final_error"].as_f64().unwrap();
            assert!(
                est / err > 1.0 / 3.0 && est / err < 3.0,
                "estimate {est:e} vs error {err:e}"
            );
        }
    }
    for f in ["accuracy.csv", "push.svg", "van-der-pol.svg", "robertson.svg"] {
        let p = dir.join(f);
        assert!(p.exists() && std::fs::metadata(&p).unwrap().len() > 100, "{f} missing");
    }
    let svg = std::fs::read_to_string(dir.join("robertson.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("rodas4"));
    std::fs::remove_dir_all(&dir).ok();
}
