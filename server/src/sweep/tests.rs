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
    for needle in [
        "gamma",
        "alpha [0, 75] deg",
        "beta [1, 89] deg",
        "mu_as [0, 5]",
        "radius [2, 10000] nm",
    ] {
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
    // Rounded to 12 significant digits, so the CSV shows 0.4, not 0.3999999999999999.
    assert_eq!(grid(0.1, 1.5, 15)[3], 0.4);
    assert_eq!(grid(100.0, 3000.0, 12)[1], 363.636363636);
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
    // The sweep's Eq 18 at the paper's α = 15° is `nanopush model`'s steady state (plumbing: the
    // sweep sets up the same scene), and it is the README's figure, 9.47 nm and ζz −24.2 nm
    // (Fig 7, item 5): Eq 18 itself is checked against a linear solve of the paper's lines in
    // `physics::pushing::steady::tests`.
    let b = base();
    let report = model_report(&b)
        .steady_state
        .expect("Eq 18 has a steady state in the paper scene");
    let opts = PointOptions {
        duration: 0.05,
        ..PointOptions::default()
    };
    let p = compute_point(&b, Param::Alpha, 3, 15.0, &opts);
    let s = p.eq18_ok().expect("Eq 18 state");
    assert_eq!(p.index, 3);
    assert_eq!(s.y, report.y);
    assert_eq!(s.zeta_z, report.zeta_z);
    assert!((s.y - 9.47e-9).abs() < 0.005e-9, "y {:e}", s.y);
    assert!((s.zeta_z + 24.2e-9).abs() < 0.05e-9, "ζz {:e}", s.zeta_z);
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
    assert!(
        row.starts_with("0,95,,,,,,,,,,,,\"scene <default scene> with beta = 95: "),
        "{row}"
    );
}

#[test]
fn csv_quotes_fields_with_commas() {
    assert_eq!(csv_text("a, b"), "\"a, b\"");
    assert_eq!(csv_text("say \"x\""), "\"say \"\"x\"\"\"");
    assert_eq!(csv_text("plain"), "plain");
}

// The paper's Sec 5 trends, where this model reproduces them. Each names its figure; what it
// does not reproduce is in the README ("The paper's figures").

fn eq18_at(param: Param, value: f64) -> Option<SteadyState> {
    let s = param.apply(&base(), value).unwrap();
    eq18(&s.push_params()).ok()
}

fn sliding_at(param: Param, value: f64) -> Settled {
    let opts = PointOptions {
        duration: 0.05,
        pure_sliding: true,
        ..PointOptions::default()
    };
    let p = compute_point(&base(), param, 0, value, &opts);
    let d = p.dynamic.expect("the push runs");
    assert!(
        !d.stuck && !d.unstable && d.phase == "slip",
        "{param:?} = {value}: {d:?}"
    );
    d
}

#[test]
fn fig10_eq18_y_and_zeta_z_grow_with_alpha_up_to_its_pole() {
    // "within a limited range of α, ζz and y increase with the increased angle": Eq 18's y and
    // |ζz| grow from 0° to the pole of its linear system near 18.6°, then change sign.
    let ys: Vec<SteadyState> = [0.0, 5.0, 10.0, 15.0, 18.0]
        .map(|a| eq18_at(Param::Alpha, a).unwrap())
        .to_vec();
    for w in ys.windows(2) {
        assert!(w[1].y > w[0].y, "y: {} then {}", w[0].y, w[1].y);
        assert!(
            w[1].zeta_z < w[0].zeta_z && w[1].zeta_z < 0.0,
            "ζz: {} then {}",
            w[0].zeta_z,
            w[1].zeta_z
        );
    }
    let past = eq18_at(Param::Alpha, 19.0).unwrap();
    assert!(past.y < 0.0 && past.zeta_z > 0.0, "{past:?}");
}

#[test]
fn fig11_pure_sliding_has_an_optimum_beta_with_detectable_zeta_z() {
    // "optimum β can result in minimum y motion of the particle with a detectable range of ζz":
    // the dynamic model without rotation has its least y at β ≈ 33°, where |ζz| ≈ 2 nm (40 mV
    // at the scene's gain); y is larger both below and above.
    let at = |b: f64| sliding_at(Param::Beta, b);
    let best = at(33.0);
    for b in [5.0, 20.0, 30.0, 35.0, 45.0] {
        assert!(at(b).y.mean > best.y.mean, "β = {b}");
    }
    assert!(best.zeta_z.mean.abs() > 1e-9, "{:?}", best.zeta_z);
}

#[test]
fn fig12_eq18_y_grows_with_mu_as_until_the_particle_jams() {
    // Eq 18's y and |ζz| grow with μ_as^s and diverge where cos β/(1+sin β) = μ_as^k(μ_ta^k cos β
    // + sin β): μ_as^k = 0.8576, so μ_as^s = 1.2864 at the paper's 2/3 ratio. The paper's
    // instability is at 0.6-0.7: this is where the model has one.
    let (sb, cb) = 30f64.to_radians().sin_cos();
    let mu_k_jam = cb / (1.0 + sb) / (0.2 * cb + sb);
    let mu_s_jam = mu_k_jam * 1.5;
    assert!((mu_s_jam - 1.2864).abs() < 1e-4, "{mu_s_jam}");
    let mut last = 0.0;
    for mu in [0.1, 0.3, 0.6, 0.7, 1.0, 1.28] {
        let s = eq18_at(Param::MuAs, mu).unwrap();
        assert!(s.y > last, "μ = {mu}");
        last = s.y;
    }
    assert!(last > 3e-7, "y diverges near the jam: {last}");
    assert!(eq18_at(Param::MuAs, 1.29).is_none());
}

#[test]
fn fig13_y_and_zeta_z_grow_with_the_radius() {
    // Eq 18: y ∝ Rₐ (every force scales with the adhesion 4πRₐγ_L); the sliding dynamic model
    // grows too, more slowly.
    let small = eq18_at(Param::Radius, 250.0).unwrap();
    let large = eq18_at(Param::Radius, 1000.0).unwrap();
    assert!((large.y / small.y - 4.0).abs() < 0.1, "{} / {}", large.y, small.y);
    assert!(large.zeta_z < small.zeta_z && small.zeta_z < 0.0);
    let (ds, dl) = (sliding_at(Param::Radius, 250.0), sliding_at(Param::Radius, 1000.0));
    assert!(dl.y.mean > 1.5 * ds.y.mean && dl.zeta_z.mean < ds.zeta_z.mean);
}

/// The README's Eq 18 figures for Figs 10, 12 and 13 (default scene, the README's digits):
/// `y` and `ζ_z` at α = 0°, 15°, 18° and past the pole at 19.5°; `y` at μ_as^s = 0.1 and 0.7;
/// `y` at Rₐ = 100 nm and 3 µm.
#[test]
fn the_readmes_eq18_figures() {
    let nm = |v: f64| v * 1e9;
    let near = |got: f64, want: f64, tol: f64| (got - want).abs() <= tol;
    for (alpha, y, zeta_z, tol_y, tol_z) in [
        (0.0, 7.03, -4.6, 0.005, 0.05),
        (15.0, 9.47, -24.2, 0.005, 0.05),
        (18.0, 23.7, -178.0, 0.05, 0.5),
        (19.5, -1.1, 95.0, 0.05, 0.5),
    ] {
        let s = eq18_at(Param::Alpha, alpha).unwrap();
        assert!(
            near(nm(s.y), y, tol_y) && near(nm(s.zeta_z), zeta_z, tol_z),
            "α = {alpha}°: y {} nm, ζz {} nm",
            nm(s.y),
            nm(s.zeta_z)
        );
    }
    for (param, value, y, tol) in [
        (Param::MuAs, 0.1, 2.6, 0.05),
        (Param::MuAs, 0.7, 37.0, 0.5),
        (Param::Radius, 100.0, 0.97, 0.005),
        (Param::Radius, 3000.0, 28.4, 0.05),
    ] {
        let s = eq18_at(param, value).unwrap();
        assert!(near(nm(s.y), y, tol), "{param:?} = {value}: y {} nm", nm(s.y));
    }
}
