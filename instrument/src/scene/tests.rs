//! Scene loading and validation: every kind of bad input gets its own message.

use super::*;

fn with(replace: &str, by: &str) -> Result<Scene, SceneError> {
    assert!(
        DEFAULT_SCENE.contains(replace),
        "test setup: {replace:?} not in the default scene"
    );
    Scene::parse("test.toml", &DEFAULT_SCENE.replacen(replace, by, 1))
}

fn err(replace: &str, by: &str) -> String {
    with(replace, by).expect_err("scene must be rejected").to_string()
}

#[test]
fn default_scene_is_valid_and_feasible() {
    let s = Scene::default_scene();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!(s.file.name, "paper-default");
}

#[test]
fn shipped_scenes_are_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let s = Scene::from_path(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(s.warnings.is_empty(), "{}: {:?}", path.display(), s.warnings);
            let p = s.push_params();
            assert!(p.m_a > 0.0 && p.k_as_t > 0.0 && p.b_as >= 0.0);
            n += 1;
        }
    }
    assert!(n >= 5, "expected the five shipped scenes, found {n}");
}

#[test]
fn embedded_default_matches_the_shipped_file() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/paper-default.toml");
    assert_eq!(std::fs::read_to_string(path).unwrap(), DEFAULT_SCENE);
}

#[test]
fn unknown_key_is_named() {
    let e = err("radius_nm = 30.0", "radius_nm = 30.0\nradius_um = 0.03");
    assert!(e.contains("unknown field `radius_um`"), "{e}");
    assert!(e.contains("test.toml"), "{e}");
}

#[test]
fn missing_field_is_named() {
    let e = err("quality_factor = 100.0      # not given: typical Q", "# no Q");
    assert!(e.contains("missing field `quality_factor`"), "{e}");
}

#[test]
fn wrong_type_is_reported() {
    let e = err("radius_nm = 30.0", "radius_nm = \"thirty\"");
    assert!(e.contains("radius_nm") || e.contains("invalid type"), "{e}");
}

#[test]
fn negative_and_zero_sizes() {
    let e = err("radius_nm = 1000.0", "radius_nm = -5.0");
    assert!(
        e.contains("particles[0].radius_nm = -5") && e.contains("[2, 10000] nm"),
        "{e}"
    );
    let e = err("stiffness_n_per_m = 8.0", "stiffness_n_per_m = 0.0");
    assert!(
        e.contains("cantilever.stiffness_n_per_m = 0") && e.contains("[0.01, 500] N/m"),
        "{e}"
    );
    let e = err("range_um = 100.0", "range_um = 0.0");
    assert!(e.contains("stage.range_um = 0") && e.contains("(0, 1000] µm"), "{e}");
}

#[test]
fn nan_and_infinity() {
    let e = err("radius_nm = 30.0", "radius_nm = nan");
    assert!(e.contains("tip.radius_nm = NaN is not a finite number"), "{e}");
    let e = err("speed_um_per_s = 1.0", "speed_um_per_s = inf");
    assert!(e.contains("push.speed_um_per_s = inf is not a finite number"), "{e}");
}

#[test]
fn humidity_outside_zero_one() {
    let e = err("relative_humidity = 0.73", "relative_humidity = 1.0");
    assert!(
        e.contains("environment.relative_humidity = 1") && e.contains("[0, 1)"),
        "{e}"
    );
    let e = err("relative_humidity = 0.73", "relative_humidity = -0.1");
    assert!(e.contains("relative_humidity = -0.1"), "{e}");
    assert!(with("relative_humidity = 0.73", "relative_humidity = 0.0").is_ok());
    assert!(with("relative_humidity = 0.73", "relative_humidity = 0.999").is_ok());
}

#[test]
fn angles_out_of_range() {
    let e = err("tilt_deg = 15.0", "tilt_deg = 95.0");
    assert!(
        e.contains("cantilever.tilt_deg = 95") && e.contains("[0, 75] degrees"),
        "{e}"
    );
    let e = err("contact_angle_deg = 30.0", "contact_angle_deg = 0.0");
    assert!(
        e.contains("push.contact_angle_deg = 0") && e.contains("[1, 89] degrees"),
        "{e}"
    );
}

/// docs/validation.md, "Which is right, and why they differ": the scenes' 1 mm/s limit on the
/// stage speed, `(0, 1000] µm/s`: 1000 µm/s is accepted, 1000.001 µm/s and 0 are refused, naming
/// the range.
#[test]
fn the_stage_speed_is_limited_to_1_mm_per_s() {
    assert!(with("speed_um_per_s = 1.0", "speed_um_per_s = 1000.0").is_ok());
    for bad in ["1000.001", "0.0"] {
        let e = err("speed_um_per_s = 1.0", &format!("speed_um_per_s = {bad}"));
        assert!(e.contains("push.speed_um_per_s") && e.contains("(0, 1000] µm/s"), "{e}");
    }
}

#[test]
fn kinetic_above_static_friction() {
    let e = err("particle_substrate_kinetic = 0.2", "particle_substrate_kinetic = 0.4");
    assert!(
        e.contains("friction.particle_substrate_kinetic = 0.4") && e.contains("at most the static"),
        "{e}"
    );
}

#[test]
fn mu_above_eq16_is_a_warning() {
    let s = with("particle_substrate_static = 0.3", "particle_substrate_static = 4.0").unwrap();
    assert_eq!(s.warnings.len(), 1);
    let w = s.warnings[0].to_string();
    assert!(
        w.contains("Eq 16 upper bound 3.75") && w.contains("cannot be pushed"),
        "{w}"
    );
}

/// With μ_as exactly at the Eq 16 bound the push is infeasible and warned about (not feasible
/// with y* = 1.5·10⁷ m).
#[test]
fn mu_at_the_eq16_bound_is_a_warning_and_infeasible() {
    let s = Scene::default_scene();
    let c = s.cantilever();
    let upper = crate::physics::friction::mu_upper_bound(c.k_y(), c.k_z(), c.tilt);
    let at = with(
        "particle_substrate_static = 0.3",
        &format!("particle_substrate_static = {upper:.17}"),
    )
    .unwrap();
    let w: Vec<String> = at.warnings.iter().map(|w| w.to_string()).collect();
    assert!(w.iter().any(|w| w.contains("is at the Eq 16 upper bound")), "{w:?}");
    // The model report's verdict on the same scene is checked in nanopush-study's `report`
    // tests (mu_at_the_eq16_bound_is_reported_infeasible).
}

#[test]
fn mu_below_eq9_is_a_warning() {
    let text = DEFAULT_SCENE
        .replacen("particle_substrate_static = 0.3", "particle_substrate_static = 0.01", 1)
        .replacen(
            "particle_substrate_kinetic = 0.2",
            "particle_substrate_kinetic = 0.005",
            1,
        );
    let s = Scene::parse("test.toml", &text).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.0.contains("Eq 9 lower bound")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn unknown_particle_and_duplicate_ids() {
    let e = err("particle_id = 1", "particle_id = 7");
    assert!(
        e.contains("push.particle_id") && e.contains("no particle has id 7"),
        "{e}"
    );
    let dup = DEFAULT_SCENE.to_string()
        + "\n[[particles]]\nid = 1\nmaterial = \"x\"\nradius_nm = 10.0\nx_um = 10.0\ny_um = 10.0\nyoungs_modulus_gpa = 3.0\npoisson_ratio = 0.3\ndensity_kg_per_m3 = 1000.0\nhamaker_zj = 60.0\n";
    // Appended after [physics], the array-of-tables still belongs to the root.
    let e = Scene::parse("dup.toml", &dup).unwrap_err().to_string();
    assert!(e.contains("particles[1].id") && e.contains("already used"), "{e}");
}

#[test]
fn particle_outside_stage_range() {
    let e = err("x_um = 50.0", "x_um = 150.0");
    assert!(
        e.contains("particles[0].x_um = 150") && e.contains("stage range"),
        "{e}"
    );
}

#[test]
fn dof_choices_are_checked() {
    let e = err("particle_y = \"quasi_static\"", "particle_y = \"off\"");
    assert!(
        e.contains("physics.particle_y") && e.contains("allowed: dynamic, quasi_static"),
        "{e}"
    );
    let e = err("stage = \"dynamic\"", "stage = \"quasi_static\"");
    assert!(
        e.contains("physics.stage") && e.contains("allowed: dynamic, off"),
        "{e}"
    );
    let e = err("stage = \"dynamic\"", "stage = \"wobbly\"");
    assert!(e.contains("unknown variant `wobbly`"), "{e}");
}

#[test]
fn zero_sensor_gain() {
    let e = err("gain_v_per_nm = -0.8", "gain_v_per_nm = 0.0");
    assert!(e.contains("sensor.gain_v_per_nm = 0"), "{e}");
}

#[test]
fn unreadable_file() {
    let e = Scene::from_path(std::path::Path::new("/nonexistent/scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot read scene file /nonexistent/scene.toml"), "{e}");
}

#[test]
fn units_convert_once_to_si() {
    let p = Scene::default_scene().push_params();
    assert!((p.r_t - 30e-9).abs() < 1e-21);
    assert!((p.r_a - 1e-6).abs() < 1e-18);
    assert!((p.cantilever.l_y - 155e-6).abs() < 1e-18);
    assert!((p.beta - 30f64.to_radians()).abs() < 1e-15);
    assert!((p.speed - 1e-6).abs() < 1e-18);
    assert!((p.gamma_l - 0.072).abs() < 1e-15);
    // Mass of a 1 µm latex sphere: 4.40e-15 kg.
    assert!((p.m_a - 4.398e-15).abs() < 0.01e-15, "{}", p.m_a);
}

#[test]
fn left_out_terms_are_absent() {
    let s = Scene::from_path(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/minimal.toml")).unwrap();
    let p = s.push_params();
    assert!(p.interactions.tip_particle.hamaker.is_some());
    assert!(p.interactions.tip_particle.capillary.is_none());
    assert!(p.interactions.tip_particle.electrostatic.is_none());
    assert!(p.interactions.particle_substrate.capillary.is_none());
}

#[test]
fn repulsive_van_der_waals_is_rejected() {
    let e = err("hamaker_zj = 65.0", "hamaker_zj = 10.0");
    assert!(
        e.contains("particles[0].hamaker_zj = 10") && e.contains("above environment.medium_hamaker_zj = 37 zJ"),
        "{e}"
    );
    // Dry, there is no water layer in the combining rule: allowed.
    let dry = DEFAULT_SCENE
        .replacen("hamaker_zj = 65.0", "hamaker_zj = 10.0", 1)
        .replacen("relative_humidity = 0.73", "relative_humidity = 0.0", 1);
    assert!(Scene::parse("dry.toml", &dry).is_ok());
}

#[test]
fn dry_electrostatics_is_a_warning() {
    let text = DEFAULT_SCENE
        .replacen("relative_humidity = 0.73", "relative_humidity = 0.0", 1)
        .replacen("electrostatic = false", "electrostatic = true", 1);
    let s = Scene::parse("dry.toml", &text).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.0.contains("electrostatic force vanishes")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn tangential_stiffness_and_damping_by_hand() {
    // k_as* = 8RₐG*, G* = ((2−νₐ)/Gₐ + (2−ν_s)/G_s)⁻¹, G = E/(2(1+ν)): latex on silicon,
    // Gₐ = 1.2687 GPa, G_s = 66.54 GPa → G* = 0.7494 GPa → k_as* = 5995 N/m.
    let p = Scene::default_scene().push_params();
    assert!((p.k_as_t - 5995.0).abs() < 1.0, "{}", p.k_as_t);
    // b_as = 2ζ sqrt(k_as* mₐ) with ζ = 0.05.
    assert!((p.b_as - 0.1 * (5994.88 * 4.3982e-15f64).sqrt()).abs() < 1e-3 * p.b_as);
}

#[test]
fn strategy_values_are_checked_against_the_sensor() {
    // A push lowers the reading (negative gain). A set point at the −0.2 V baseline is no
    // contact; one above it reads the contact on the pull side, with its safety limit beyond it
    // there, not at the push side's −4 V.
    let e = err("set_point_v = -1.5", "set_point_v = -0.2");
    assert!(
        e.contains("strategy.set_point_v") && e.contains("is the baseline"),
        "{e}"
    );
    let e = err("set_point_v = -1.5", "set_point_v = 0.5");
    assert!(
        e.contains("strategy.safety_limit_v") && e.contains("further above the baseline -0.2 V"),
        "{e}"
    );
    let pull = DEFAULT_SCENE
        .replacen("set_point_v = -1.5", "set_point_v = 0.5", 1)
        .replacen("safety_limit_v = -4.0", "safety_limit_v = 3.0", 1);
    let s = Scene::parse("pull.toml", &pull).expect("a contact read on the pull side");
    assert_eq!(
        s.strategy_params(1e-3).contact_side,
        crate::control::estimator::ContactSide::Pull
    );
    let e = err("safety_limit_v = -4.0", "safety_limit_v = -1.0");
    assert!(
        e.contains("strategy.safety_limit_v") && e.contains("beyond the set point -1.5 V"),
        "{e}"
    );
    assert!(
        with("safety_limit_v = -4.0", "safety_limit_v = -6.0").is_ok(),
        "a −6 V limit is inside the default ±10 V"
    );
    let e = err("noise_rms_mv = 5.0", "noise_rms_mv = 5.0\nfull_scale_v = 3.0");
    assert!(
        e.contains("strategy.safety_limit_v") && e.contains("outside the readout's range (-3, 3) V"),
        "{e}"
    );
    let e = err("noise_rms_mv = 5.0", "noise_rms_mv = 5.0\nfull_scale_v = 0.5");
    assert!(e.contains("sensor.full_scale_v") && e.contains("[1, 100] V"), "{e}");
    let e = err("step_um = 0.1", "step_um = 0.0");
    assert!(e.contains("strategy.step_um") && e.contains("[0.001, 10] µm"), "{e}");
    let e = err("step_um = 0.1", "step_um = 0.1\nsearch_rang_um = 5.0");
    assert!(e.contains("search_rang_um"), "{e}");
    // The paper's Δ and ζ_set (the default scene writes them out; they are the defaults too).
    let s = Scene::default_scene();
    assert_eq!(s.file.strategy.step_um, 0.1);
    assert_eq!(s.file.strategy.set_point_v, -1.5);
}

/// A particle a scan cannot find is refused at load, naming the field and the
/// threshold.
#[test]
fn a_particle_below_the_scan_noise_is_refused() {
    let mut f = Scene::default_scene().file.clone();
    // 1 nm of scan noise: the threshold is 6σ = 6 nm, so a particle must be 12 nm high.
    f.scan.noise_rms_nm = 1.0;
    f.particles[0].radius_nm = 5.5;
    let e = Scene::from_file("test", f.clone()).expect_err("refused").to_string();
    assert!(
        e.contains("particles[0].radius_nm") && e.contains("cannot resolve") && e.contains("6.000 nm"),
        "{e}"
    );
    f.particles[0].radius_nm = 6.0;
    let ok = Scene::from_file("test", f);
    assert!(
        !ok.as_ref().is_err_and(|e| e.to_string().contains("cannot resolve")),
        "{:?}",
        ok.err()
    );
}

/// docs/model.md's table of shipped scenes ("Scenes"): gold-latex has three particles of 0.5 µm
/// radius pushed at 2 µm/s; gold-14nm a 14 nm (diameter) colloid under a 10 nm tip, electrostatics
/// on, its strategy (steps, set point, β, V) derived from the model; minimal van der Waals only, dry,
/// β derived (45°).
#[test]
fn the_shipped_scenes_are_what_the_docs_table_says() {
    let load = |name: &str| {
        Scene::from_path(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../scenes")
                .join(name),
        )
        .unwrap()
    };
    let latex = load("gold-latex-500nm.toml");
    assert_eq!(latex.file.particles.len(), 3);
    assert!(latex.file.particles.iter().all(|p| p.radius_nm == 500.0));
    assert_eq!(latex.file.push.speed_um_per_s, 2.0);
    let gold = load("gold-14nm.toml");
    assert_eq!(2.0 * gold.pushed_particle().radius_nm, 14.0);
    assert_eq!(gold.file.tip.radius_nm, 10.0);
    assert!(gold.file.physics.electrostatic);
    assert_eq!(gold.hand_set.keys().count(), 0, "gold-14nm sets no strategy by hand");
    let minimal = load("minimal.toml");
    let plan = crate::control::derive::derive(&minimal, 1, 25e-9).expect("a plan");
    assert_eq!(plan.contact_angle_deg, 45.0);
    let minimal = minimal.file;
    let ph = &minimal.physics;
    assert!(ph.van_der_waals && !ph.capillary && !ph.electrostatic);
    assert_eq!(minimal.environment.relative_humidity, 0.0);
}

fn shipped(name: &str) -> Scene {
    Scene::from_path(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(name),
    )
    .unwrap()
}

/// docs/manipulation.md's paragraph on the sensor gains ("Sensor gains and the shipped scenes"):
/// −0.8 V/nm in paper-default and gold-14nm, −0.4 V/nm in gold-latex-500nm, −0.2 V/nm in minimal,
/// every baseline at −0.2 V; so `ζ_set = −1.5 V` is `(ζ_set − baseline)/gain` = 1.625 nm of
/// deflection in paper-default and 3.25 nm in gold-latex-500nm.
#[test]
fn the_shipped_sensor_gains_and_set_points_are_documented() {
    for (name, gain) in [
        ("paper-default.toml", -0.8),
        ("gold-latex-500nm.toml", -0.4),
        ("gold-14nm.toml", -0.8),
        ("minimal.toml", -0.2),
    ] {
        let s = shipped(name);
        assert_eq!(s.file.sensor.gain_v_per_nm, gain, "{name}");
        assert_eq!(s.file.sensor.baseline_v, -0.2, "{name}");
    }
    assert_eq!(Scene::default_scene().file, shipped("paper-default.toml").file);
    for (name, readme_nm) in [("paper-default.toml", 1.625), ("gold-latex-500nm.toml", 3.25)] {
        let s = shipped(name);
        assert_eq!(s.file.strategy.set_point_v, -1.5, "{name}");
        let nm = s.sensor().deflection(s.file.strategy.set_point_v) / 1e-9;
        assert!(
            (nm - readme_nm).abs() <= 0.0005,
            "{name}: ζ_set is {nm} nm of deflection"
        );
    }
}

/// docs/manipulation.md on gold-latex-500nm ("Measured pushes", "Figs 9 and 15", "Scans
/// (`nanopush scan`)"): its substrate rises 6 mrad along x, and its reading carries a periodic
/// perturbation of 20 mV at 3 Hz.
#[test]
fn gold_latex_has_a_tilted_substrate_and_a_perturbed_reading() {
    let f = shipped("gold-latex-500nm.toml").file;
    assert_eq!((f.substrate.tilt_x_mrad, f.substrate.tilt_y_mrad), (6.0, 0.0));
    assert_eq!((f.sensor.perturbation_mv, f.sensor.perturbation_hz), (20.0, 3.0));
}

fn particle_toml(id: u32, x_um: f64, y_um: f64, radius_nm: f64) -> String {
    format!(
        "\n[[particles]]\nid = {id}\nmaterial = \"x\"\nradius_nm = {radius_nm}\nx_um = {x_um}\ny_um = {y_um}\nyoungs_modulus_gpa = 3.0\npoisson_ratio = 0.3\ndensity_kg_per_m3 = 1000.0\nhamaker_zj = 60.0\n"
    )
}

/// A 10 MB scene would take 70-86 s and 173 MB for one push (every scan images every
/// particle). A scene holds at most
/// 2000 particles (a push of 2000 takes 5 s: docs/manipulation.md), and its file at most 4 MiB.
#[test]
fn a_scene_is_refused_past_its_particle_and_file_size_limits() {
    assert_eq!((MAX_PARTICLES, MAX_SCENE_BYTES), (2000, 4 << 20));
    let grid = |n: u32| -> String {
        let mut text = DEFAULT_SCENE.to_string();
        for k in 0..n {
            text += &particle_toml(
                k + 2,
                1.0 + f64::from(k % 45) * 2.0,
                1.0 + f64::from(k / 45) * 2.0,
                50.0,
            );
        }
        text
    };
    // On odd micrometres: clear of the default particle at (50, 50).
    let ok = Scene::parse("max.toml", &grid(1999)).unwrap();
    assert_eq!(ok.file.particles.len(), 2000);
    let e = Scene::parse("over.toml", &grid(2000)).unwrap_err().to_string();
    assert_eq!(
        e,
        "scene over.toml: particles: 2001 particles; allowed: at most 2000 (every scan images each particle at every pixel: 4705 took 11.5 s a push)"
    );
    let dir = std::env::temp_dir().join(format!("nanopush-big-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("big.toml");
    std::fs::write(&path, DEFAULT_SCENE.to_string() + &"# padding\n".repeat(500_000)).unwrap();
    let e = Scene::from_path(&path).unwrap_err().to_string();
    assert!(
        e.contains("the file: larger than 4194304 bytes; allowed: at most 4194304 bytes"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

proptest::proptest! {
    /// The sweep finds the clash every pair would: the same pair, in file order, the id checked
    /// before the overlap.
    #[test]
    fn the_clash_check_agrees_with_every_pair(
        ps in proptest::collection::vec((0u32..6, 0.0f64..3.0, 0.0f64..3.0, 2.0f64..400.0), 1..25)
    ) {
        let parts: Vec<file::ParticleFile> = ps
            .iter()
            .map(|&(id, x, y, r)| {
                let mut p = Scene::default_scene().file.particles[0].clone();
                (p.id, p.x_um, p.y_um, p.radius_nm) = (id, x, y, r);
                p
            })
            .collect();
        let mut every_pair = None;
        'outer: for (i, p) in parts.iter().enumerate() {
            for (j, q) in parts.iter().enumerate().take(i) {
                if q.id == p.id {
                    every_pair = Some((i, j, true));
                    break 'outer;
                }
                let d_nm = ((p.x_um - q.x_um).powi(2) + (p.y_um - q.y_um).powi(2)).sqrt() * 1e3;
                if d_nm < p.radius_nm + q.radius_nm {
                    every_pair = Some((i, j, false));
                    break 'outer;
                }
            }
        }
        proptest::prop_assert_eq!(ranges::first_clash(&parts), every_pair);
    }
}

/// `radius_nm = 1e308` is shown in scientific notation, not as 309 digits.
#[test]
fn a_huge_value_is_shown_in_scientific_notation() {
    let e = err("radius_nm = 1000.0", "radius_nm = 1e308");
    assert!(e.contains("particles[0].radius_nm = 1e308 is out of range"), "{e}");
    assert!(e.len() < 200, "{e}");
}

/// The start height clearing the tallest particle is the plan's to derive: a scene that does
/// not give it is not warned about the default it will not use; a hand-set one that does not clear it
/// still is.
#[test]
fn only_a_hand_set_start_height_is_warned_about_the_tallest_particle() {
    let tall = DEFAULT_SCENE.replacen("radius_nm = 1000.0", "radius_nm = 2000.0", 1);
    let warned = |s: &Scene| {
        s.warnings
            .iter()
            .any(|w| w.0.contains("does not clear the tallest particle"))
    };
    let hand = Scene::parse("t", &tall).unwrap();
    assert!(warned(&hand), "{:?}", hand.warnings);
    let derived = Scene::parse("t", &tall.replacen("start_height_um = 3.0", "", 1)).unwrap();
    assert!(!derived.hand_set.contains("strategy.start_height_um"));
    assert!(!warned(&derived), "{:?}", derived.warnings);
}

/// At a humidity whose Kelvin radius is below a₀ but not zero, the warning says Eq 4's area
/// rests on that radius (the force does not vanish, as Eq 4 counts it); at 0 % it does vanish.
#[test]
fn a_sub_atomic_kelvin_radius_is_not_said_to_zero_the_electrostatic_force() {
    let text = DEFAULT_SCENE
        .replacen("relative_humidity = 0.73", "relative_humidity = 0.001", 1)
        .replacen("electrostatic = false", "electrostatic = true", 1);
    let s = Scene::parse("nearly-dry.toml", &text).unwrap();
    let w: Vec<&str> = s
        .warnings
        .iter()
        .map(|w| w.0.as_str())
        .filter(|w| w.contains("physics.electrostatic"))
        .collect();
    assert_eq!(w.len(), 1, "{:?}", s.warnings);
    assert!(
        w[0].contains("r₁ = 0.078 nm is below a₀") && !w[0].contains("force vanishes"),
        "{}",
        w[0]
    );
}
