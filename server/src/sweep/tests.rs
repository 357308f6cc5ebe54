use super::*;
use crate::report::model_report;

fn base() -> Scene {
    Scene::default_scene()
}

#[test]
fn parse_names_and_lists_ranges_on_error() {
    for p in Param::ALL {
        assert_eq!(Param::parse(p.name()), Ok(p));
    }
    let e = Param::parse("gamma").unwrap_err().to_string();
    for needle in ["gamma", "alpha [0, 75] deg", "beta [1, 89] deg", "mu_as [0, 5]", "radius [2, 10000] nm"] {
        assert!(e.contains(needle), "{e}");
    }
}

#[test]
fn apply_sets_the_field_and_keeps_the_rest() {
    let b = base();
    let s = Param::Alpha.apply(&b, 20.0).unwrap();
    assert_eq!(s.file.cantilever.tilt_deg, 20.0);
    assert_eq!(s.file.push, b.file.push);
    let s = Param::Beta.apply(&b, 45.0).unwrap();
    assert_eq!(s.file.push.contact_angle_deg, 45.0);
    let s = Param::Radius.apply(&b, 500.0).unwrap();
    assert_eq!(s.pushed_particle().radius_nm, 500.0);
    assert_eq!(s.file.cantilever, b.file.cantilever);
}

#[test]
fn mu_as_keeps_the_scene_ratio_of_kinetic_to_static() {
    // The paper's 0.2/0.3: μ_as^s = 0.6 gives μ_as^k = 0.4; the tip coefficients stay.
    let s = Param::MuAs.apply(&base(), 0.6).unwrap();
    assert_eq!(s.file.friction.particle_substrate_static, 0.6);
    assert!((s.file.friction.particle_substrate_kinetic - 0.4).abs() < 1e-15);
    assert_eq!(s.file.friction.tip_particle_static, 0.3);
    assert_eq!(s.file.friction.tip_particle_kinetic, 0.2);
}

#[test]
fn ranges_are_the_scene_validation_ranges() {
    // Each end is accepted by the scene, and a step beyond it gets the scene's own error.
    let b = base();
    for p in Param::ALL {
        let (lo, hi) = p.range();
        assert!(p.apply(&b, lo).is_ok(), "{} = {lo}", p.name());
        assert!(p.apply(&b, hi).is_ok(), "{} = {hi}", p.name());
        for bad in [lo - 1e-6 * hi.max(1.0), hi * (1.0 + 1e-6)] {
            let e = p.apply(&b, bad).unwrap_err().to_string();
            assert!(e.contains("out of range") && e.contains(p.name()), "{e}");
        }
    }
}

#[test]
fn bounds_are_checked() {
    let p = Param::Alpha;
    assert!(p.check_bounds(0.0, 30.0, 31).is_ok());
    assert!(p.check_bounds(10.0, 10.0, 1).is_ok());
    assert!(matches!(p.check_bounds(30.0, 0.0, 5), Err(SweepError::Bounds { .. })));
    assert!(matches!(p.check_bounds(0.0, 30.0, 0), Err(SweepError::Steps(0))));
    assert!(matches!(p.check_bounds(0.0, 30.0, 1), Err(SweepError::Bounds { .. })));
    let e = p.check_bounds(0.0, 80.0, 5).unwrap_err().to_string();
    assert_eq!(e, "--to 80 is out of range for alpha; allowed: [0, 75] deg");
    assert!(p.check_bounds(f64::NAN, 10.0, 5).is_err());
}

#[test]
fn grid_ends_exactly_at_the_bounds() {
    let g = grid(0.1, 0.9, 9);
    assert_eq!(g.len(), 9);
    assert_eq!(g[0], 0.1);
    assert_eq!(g[8], 0.9);
    assert!(g.windows(2).all(|w| w[1] > w[0]));
    assert_eq!(grid(5.0, 5.0, 1), vec![5.0]);
}

#[test]
fn shards_cover_the_index_range_exactly_once_in_order() {
    for points in [0usize, 1, 2, 7, 31, 100] {
        for count in 1..=9 {
            let mut next = 0;
            for index in 0..count {
                let r = Shard { index, count }.range(points);
                assert_eq!(r.start, next, "N = {points}, shard {index}/{count}");
                assert!(r.len() <= points / count + 1);
                next = r.end;
            }
            assert_eq!(next, points, "N = {points}, n = {count}");
        }
    }
}

#[test]
fn shard_parse_rejects_what_a_scheduler_should_not_send() {
    assert_eq!(Shard::parse("2/4"), Ok(Shard { index: 2, count: 4 }));
    for (given, needle) in [
        ("3/2", "allowed: 0 to 1"),
        ("0/0", "at least 1"),
        ("1", "expected i/n"),
        ("-1/2", "not a non-negative integer"),
        ("a/b", "not a non-negative integer"),
    ] {
        let e = Shard::parse(given).unwrap_err().to_string();
        assert!(e.contains(needle), "{given}: {e}");
    }
}

#[test]
fn default_point_agrees_with_eq18_of_the_model_report() {
    // The sweep's Eq 18 at the paper's α = 15° is `nanopush model`'s steady state.
    let b = base();
    let report = model_report(&b).steady_state.expect("Eq 18 has a steady state in the paper scene");
    let opts = PointOptions {
        duration: 0.05,
        ..PointOptions::default()
    };
    let p = compute_point(&b, Param::Alpha, 3, 15.0, &opts);
    let s = p.eq18_ok().expect("Eq 18 state");
    assert_eq!(p.index, 3);
    assert_eq!(s.y, report.y);
    assert_eq!(s.zeta_z, report.zeta_z);
    let d = p.dynamic.as_ref().expect("the push runs");
    assert!(d.y.mean.is_finite() && d.zeta_z.mean.is_finite());
    assert!(d.y.min <= d.y.mean && d.y.mean <= d.y.max);
}

#[test]
fn an_invalid_value_is_a_failed_row_not_a_panic() {
    let p = compute_point(&base(), Param::Beta, 0, 95.0, &PointOptions::default());
    assert!(p.eq18.is_none());
    let e = p.dynamic.as_ref().unwrap_err();
    assert!(e.contains("push.contact_angle_deg = 95 is out of range"), "{e}");
    let row = csv_row(&p);
    assert!(row.starts_with("0,95,,,,,,,,,,,,\"scene <default scene> with beta = 95: "), "{row}");
}

#[test]
fn csv_quotes_fields_with_commas() {
    assert_eq!(csv_text("a, b"), "\"a, b\"");
    assert_eq!(csv_text("say \"x\""), "say \"x\"");
    assert_eq!(csv_text("plain"), "plain");
}
