//! `nanopush-haptic render`, fed by `nanopush model --force-curve --json`.

use nanopush_e2e::{run, text};

#[test]
fn renders_a_force_curve_through_the_scaling() {
    let curve = run("nanopush", &["model", "--force-curve", "--json", "--steps", "50"], None);
    assert!(curve.status.success());
    let o = run("nanopush-haptic", &["render", "--peak-n", "2.0"], Some(&curve.stdout));
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "branch,handle_mm,hand_force_n,tip_force_nn");
    assert_eq!(lines.len(), 1 + 2 * 51);
    // The ~54 nN pull-off is 5.4 N at 0.1 N/nN: saturated at the 2 N peak.
    let forces: Vec<f64> = lines[1..]
        .iter()
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(forces.iter().all(|f| f.abs() <= 2.0));
    assert!(forces.contains(&-2.0));
}

#[test]
fn rejects_input_that_is_not_a_force_curve() {
    let o = run("nanopush-haptic", &["render"], Some(b"{\"schema\": 1}"));
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        err.contains("not the JSON of `nanopush model --force-curve --json`"),
        "{err}"
    );
    let o = run("nanopush-haptic", &["render", "--nm-per-mm=-1"], Some(b""));
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2));
    assert!(err.contains("position_gain") && err.contains("positive"), "{err}");
}
