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
    let f = &base().file.friction;
    assert_eq!((f.particle_substrate_kinetic, f.particle_substrate_static), (0.2, 0.3));
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
    // sweep sets up the same scene), and it is docs/model.md's figure, 9.47 nm and ζz −24.2 nm
    // ("The paper's figures", Fig 7, item 5): Eq 18 itself is checked against a linear solve of the
    // paper's lines in `physics::pushing::steady::tests`.
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
// does not reproduce is in docs/model.md ("The paper's figures").

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
    // |ζz| grow from 0° to the pole of its linear system at 18.5°, then change sign.
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

/// docs/model.md's Eq 18 figures for Figs 10, 12 and 13 ("The paper's figures"; default scene, its
/// digits): `y` and `ζ_z` at α = 0°, 15°, 18° and past the pole at 19.5°; `y` at μ_as^s = 0.1 and
/// 0.7; `y` at Rₐ = 100 nm and 3 µm.
#[test]
fn the_documented_eq18_figures() {
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

/// Where Eq 18's `y` changes sign between `lo` and `hi` (one sign change there), by bisection
/// to a millionth of the bracket (closer, a pole's denominator is refused as singular).
fn eq18_sign_change(param: Param, mut lo: f64, mut hi: f64) -> f64 {
    let positive = |v: f64| eq18_at(param, v).unwrap().y > 0.0;
    let at_lo = positive(lo);
    assert_ne!(at_lo, positive(hi), "no sign change in [{lo}, {hi}]");
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if positive(mid) == at_lo { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// docs/model.md's pole of Eq 18 in α ("The paper's figures", Fig 10): `1 − a_y P − a_z Q = 0` at
/// α = 18.5°, where `y` goes through infinity (above 1 µm a thousandth of a degree either side) and
/// changes sign.
#[test]
fn fig10_eq18_has_a_pole_in_alpha() {
    let pole = eq18_sign_change(Param::Alpha, 18.0, 19.0);
    assert!((pole - 18.5).abs() < 0.05, "pole at {pole}°");
    assert!(eq18_at(Param::Alpha, pole - 1e-3).unwrap().y > 1e-6);
    assert!(eq18_at(Param::Alpha, pole + 1e-3).unwrap().y < -1e-6);
}

/// docs/model.md's Eq 18 in β ("The paper's figures", Fig 11): a pole at β = 23.2° (`y` through
/// infinity), which is the `y_argmin` of the Fig 11 sweep (23°, on its 31-point grid from 5° to
/// 65°), not an optimum; and no kinetic steady state from β = 67.4° on, where
/// `cos β/(1+sin β) ≤ μ_as^k(μ_ta^k cos β + sin β)` (the particle jams under the tip).
#[test]
fn fig11_eq18_pole_in_beta_is_the_sweeps_argmin_and_steep_beta_jams() {
    let pole = eq18_sign_change(Param::Beta, 22.0, 24.0);
    assert!((pole - 23.2).abs() < 0.05, "pole at {pole}°");
    assert!(eq18_at(Param::Beta, pole - 1e-3).unwrap().y < -1e-6);
    assert!(eq18_at(Param::Beta, pole + 1e-3).unwrap().y > 1e-6);
    let argmin = grid(5.0, 65.0, 31)
        .into_iter()
        .filter_map(|b| eq18_at(Param::Beta, b).map(|s| (b, s.y)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    assert_eq!(argmin.0, 23.0, "{argmin:?}");
    let (mut lo, mut hi) = (60.0, 75.0);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if eq18_at(Param::Beta, mid).is_some() {
            lo = mid
        } else {
            hi = mid
        }
    }
    assert!((lo - 67.4).abs() < 0.05, "jams from {lo}°");
    let jam = eq18(&Param::Beta.apply(&base(), 67.5).unwrap().push_params());
    assert!(matches!(jam, Err(SteadyError::Jammed { .. })), "{jam:?}");
}

/// docs/model.md's jam ("The paper's figures", Fig 12) "at 0.577 if μ_as and μ_ta were varied
/// together with μᵏ = μˢ": with one μ for all four coefficients the jam
/// `cos β/(1+sin β) = μ(μ cos β + sin β)` at β = 30° is `0.866μ² + 0.5μ = 0.577`, whose root is
/// 1/√3 = 0.577; the model's Eq 18 has a steady state at 0.577 and none at 0.578.
#[test]
fn fig12_jams_where_one_mu_sets_both_contacts() {
    let (sb, cb) = 30f64.to_radians().sin_cos();
    let lhs = cb / (1.0 + sb);
    let root = (-sb + (sb * sb + 4.0 * cb * lhs).sqrt()) / (2.0 * cb);
    assert!((root - 0.577).abs() < 0.0005, "{root}");
    assert!((root - 1.0 / 3f64.sqrt()).abs() < 1e-12);
    let at = |mu: f64| {
        let mut p = base().push_params();
        (p.mu_as_s, p.mu_as_k, p.mu_ta_s, p.mu_ta_k) = (mu, mu, mu, mu);
        eq18(&p)
    };
    assert!(at(0.577).is_ok());
    assert!(matches!(at(0.578), Err(SteadyError::Jammed { .. })));
}

/// The dynamic model's settled point as `nanopush sweep` computes it (0.2 s push, the last
/// quarter), with or without the particle's rotation.
fn dynamic_at(param: Param, value: f64, pure_sliding: bool) -> Result<Settled, String> {
    let opts = PointOptions {
        pure_sliding,
        ..PointOptions::default()
    };
    assert_eq!(opts.duration, 0.2);
    compute_point(&base(), param, 0, value, &opts).dynamic
}

/// Settled `y` and `ζ_z` (nm) of a point that moves steadily (not stuck, not unstable).
fn settled_nm(param: Param, value: f64, pure_sliding: bool) -> (f64, f64) {
    let d = dynamic_at(param, value, pure_sliding).unwrap_or_else(|e| panic!("{param:?} = {value}: {e}"));
    assert!(!d.stuck && !d.unstable, "{param:?} = {value}: {d:?}");
    (d.y.mean * 1e9, d.zeta_z.mean * 1e9)
}

fn near(got: f64, want: f64, tol: f64) -> bool {
    (got - want).abs() <= tol
}

/// docs/model.md's dynamic model in Fig 10 ("The paper's figures"; 0.2 s pushes, as the sweep):
/// sliding, `y` falls from 9.98 nm at α = 0° to 4.26 nm at 12° and rises again to 9.15 nm at 45°
/// (12° is a minimum: `y` is larger at its neighbours 10.5° and 13.5° on the Fig 10 sweep's grid);
/// rolling, over that grid (0° to 45° in 1.5° steps), it falls from 1.20 nm at 0° to its least,
/// 0.235 nm, at 42°, and is 0.244 nm at 45°.
#[test]
fn fig10_dynamic_y_sliding_and_rolling_is_as_documented() {
    for (alpha, y, tol) in [(0.0, 9.98, 0.005), (12.0, 4.26, 0.005), (45.0, 9.15, 0.005)] {
        let (got, _) = settled_nm(Param::Alpha, alpha, true);
        assert!(near(got, y, tol), "sliding, α = {alpha}°: y {got} nm");
    }
    let y12 = settled_nm(Param::Alpha, 12.0, true).0;
    for alpha in [10.5, 13.5] {
        let (got, _) = settled_nm(Param::Alpha, alpha, true);
        assert!(
            got > y12,
            "sliding, α = {alpha}°: y {got} nm, not above {y12} nm at 12°"
        );
    }
    let rolling: Vec<(f64, f64)> = grid(0.0, 45.0, 31)
        .into_iter()
        .map(|a| (a, settled_nm(Param::Alpha, a, false).0))
        .collect();
    assert!(near(rolling[0].1, 1.20, 0.005), "{rolling:?}");
    let least = rolling.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    assert!(least.0 == 42.0 && near(least.1, 0.235, 0.0005), "{least:?}");
    assert!(near(rolling[30].1, 0.244, 0.0005), "{rolling:?}");
}

/// docs/model.md's dynamic model in Fig 11 ("The paper's figures"; 0.2 s pushes). Without rotation
/// the settled `y` is least, 4.41 nm, at β = 33° (less than at 32°, at 34° and at every point of
/// the Fig 11 sweep), with `ζ_z` = −2.07 nm there, which the default scene's −0.8 V/nm sensor reads
/// as 1.66 V; it is 4.52 nm at 5° and 27.8 nm at 51°; at 34° the tip friction has reversed: 6.2 nm,
/// `ζ_z` = +2.2 nm. Rolling, `y` only grows with β over the Fig 11 sweep's grid (5° to 65° in
/// 2° steps), from 0.04 nm at 5° to 3.4 nm at 49°. The particle is `stuck` (the tip never shears
/// it within the run) from 51° rolling (50° still rolls) and from 56° sliding (54° still
/// slides); at 55° sliding the tip's contact breaks at t = 0.11 s (to ±0.005 s, read from the
/// error's `t = … s`), an error row.
#[test]
fn fig11_dynamic_y_has_its_documented_least_and_stuck_angles() {
    let (y33, z33) = settled_nm(Param::Beta, 33.0, true);
    assert!(
        near(y33, 4.41, 0.005) && near(z33, -2.07, 0.005),
        "β = 33°: {y33} nm, ζ_z {z33} nm"
    );
    let volts = base().sensor().gain * z33 * 1e-9;
    assert!(near(volts, 1.66, 0.005), "{volts} V");
    for b in grid(5.0, 65.0, 31)
        .into_iter()
        .filter(|&b| b != 33.0)
        .chain([32.0, 34.0])
    {
        if let Ok(d) = dynamic_at(Param::Beta, b, true) {
            assert!(d.y.mean * 1e9 > y33, "β = {b}°: {:e} m", d.y.mean);
        }
    }
    let (y34, z34) = settled_nm(Param::Beta, 34.0, true);
    assert!(
        near(y34, 6.2, 0.05) && near(z34, 2.2, 0.05),
        "β = 34°: {y34} nm, ζ_z {z34} nm"
    );
    for (beta, y, tol) in [(5.0, 4.52, 0.005), (51.0, 27.8, 0.05)] {
        let (got, _) = settled_nm(Param::Beta, beta, true);
        assert!(near(got, y, tol), "sliding, β = {beta}°: y {got} nm");
    }
    for (beta, y, tol) in [(5.0, 0.04, 0.005), (49.0, 3.4, 0.05)] {
        let (got, _) = settled_nm(Param::Beta, beta, false);
        assert!(near(got, y, tol), "rolling, β = {beta}°: y {got} nm");
    }
    let rolling: Vec<(f64, f64)> = grid(5.0, 49.0, 23)
        .into_iter()
        .map(|b| (b, settled_nm(Param::Beta, b, false).0))
        .collect();
    assert_eq!(rolling.last().unwrap().0, 49.0);
    for w in rolling.windows(2) {
        assert!(
            w[1].1 > w[0].1,
            "rolling y does not grow from β = {}° to {}°: {rolling:?}",
            w[0].0,
            w[1].0
        );
    }
    let stuck = |beta: f64, pure_sliding: bool| dynamic_at(Param::Beta, beta, pure_sliding).unwrap().stuck;
    assert!(!stuck(50.0, false) && stuck(51.0, false), "rolling");
    assert!(!stuck(54.0, true) && stuck(56.0, true), "sliding");
    let e = dynamic_at(Param::Beta, 55.0, true).unwrap_err();
    assert!(e.contains("contact with the particle broke"), "{e}");
    let t: f64 = e
        .split_once("t = ")
        .and_then(|(_, rest)| rest.split_once(" s"))
        .and_then(|(t, _)| t.parse().ok())
        .unwrap_or_else(|| panic!("no `t = … s` in {e}"));
    assert!(near(t, 0.11, 0.005), "the contact breaks at t = {t} s: {e}");
}

/// docs/model.md's dynamic model in Fig 12 ("The paper's figures"; 0.2 s pushes over the Fig 12
/// sweep's grid, μ_as^s from 0.1 to 1.5): no stick-slip and no stuck point anywhere; sliding, `y`
/// grows linearly from 1.8 nm to 18.4 nm (the middle point within 1 % of the chord); rolling, it
/// does not depend on μ_as at all: 0.669 nm and `ζ_z` 1.259 nm at every point.
#[test]
fn fig12_sliding_y_grows_with_mu_and_rolling_y_does_not_depend_on_it() {
    let mus = grid(0.1, 1.5, 29);
    let sliding: Vec<f64> = mus.iter().map(|&mu| settled_nm(Param::MuAs, mu, true).0).collect();
    assert!(
        near(sliding[0], 1.8, 0.05) && near(sliding[28], 18.4, 0.05),
        "{sliding:?}"
    );
    let chord = 0.5 * (sliding[0] + sliding[28]);
    assert!(
        (sliding[14] / chord - 1.0).abs() < 0.01,
        "μ = {}: {} nm",
        mus[14],
        sliding[14]
    );
    for &mu in &mus {
        let (y, z) = settled_nm(Param::MuAs, mu, false);
        assert!(
            near(y, 0.669, 0.0005) && near(z, 1.259, 0.0005),
            "rolling, μ = {mu}: {y}, {z} nm"
        );
    }
}

/// docs/model.md's dynamic model in Fig 13 ("The paper's figures"; 0.2 s pushes): sliding, `y` from
/// 0.75 nm at Rₐ = 100 nm to 10.1 nm at 3 µm; rolling, nearly flat over the Fig 13 sweep's grid
/// (100 nm to 3 µm in 100 nm steps): from 0.645 nm (100 nm) to at most 0.670 nm.
#[test]
fn fig13_sliding_y_grows_with_the_radius_and_rolling_y_is_nearly_flat() {
    for (r, y, tol) in [(100.0, 0.75, 0.005), (3000.0, 10.1, 0.05)] {
        let (got, _) = settled_nm(Param::Radius, r, true);
        assert!(near(got, y, tol), "sliding, Rₐ = {r} nm: y {got} nm");
    }
    let rolling: Vec<f64> = grid(100.0, 3000.0, 30)
        .into_iter()
        .map(|r| settled_nm(Param::Radius, r, false).0)
        .collect();
    let (lo, hi) = rolling
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &y| (lo.min(y), hi.max(y)));
    assert!(near(lo, 0.645, 0.0005) && lo == rolling[0], "{rolling:?}");
    assert!(near(hi, 0.670, 0.0005), "{rolling:?}");
}
