//! `nanopush push`: a whole manipulation from the command line — the Fig 9 contact step, the
//! distance reached, a planned multi-push move, the files written, and bad arguments refused.

use nanopush_e2e::{run, text};

use crate::util::{nanopush_json as json, tmp};

/// docs/manipulation.md's push table ("Measured pushes"), row 1, and its Figs 9 and 15: `nanopush push --scene
/// scenes/gold-latex-500nm.toml --distance-um 12 --pause-at-um 6 --out DIR` touches at step 43,
/// ends 14.3 nm short after 15.6 s of simulated time, and its trace shows the 500 ms stop at
/// 6 µm and, at the restart, a static-friction peak of −1.78 V against a rolling level of about
/// −1.1 V.
#[test]
fn a_long_push_with_a_stop_ends_as_documented_and_writes_its_figures() {
    let dir = tmp("push-fig15");
    let d = dir.to_str().unwrap();
    let r = json(&[
        "push",
        "--scene",
        "scenes/gold-latex-500nm.toml",
        "--distance-um",
        "12",
        "--pause-at-um",
        "6",
        "--out",
        d,
        "--json",
    ]);
    assert_eq!(r["schema"], "push");
    let leg = &r["legs"][0];
    assert_eq!(leg["outcome"], "ok", "{leg}");
    assert_eq!(leg["contact_step"], 43);
    assert_eq!(leg["retracted"], true);
    let err = r["final_error"].as_f64().unwrap();
    assert!(err < 25e-9, "final error {err:e} m");
    // docs/manipulation.md's figures, to their last digit: the error along the push, the simulated time.
    let along = leg["true_distance"].as_f64().unwrap() - 12e-6;
    assert!(
        (along / 1e-9 + 14.3).abs() <= 0.05,
        "distance error {along:e} m (docs/manipulation.md: −14.3 nm)"
    );
    let simulated = r["simulated_time"].as_f64().unwrap();
    assert!(
        (simulated - 15.6).abs() <= 0.05,
        "simulated {simulated} s (docs/manipulation.md: 15.6 s)"
    );
    for f in [
        "contact.csv",
        "contact.svg",
        "push.csv",
        "push.svg",
        "scan-before.gsf",
        "scan-after.gsf",
        "scan-before.png",
        "summary.json",
    ] {
        let p = dir.join(f);
        assert!(
            p.metadata().map(|m| m.len() > 0).unwrap_or(false),
            "{} missing",
            p.display()
        );
    }
    // Fig 9: the baseline until step 43, then the set point.
    let contact = std::fs::read_to_string(dir.join("contact.csv")).unwrap();
    let last = contact.lines().last().unwrap();
    assert!(last.starts_with("43,"), "{last}");
    // Fig 15: the stop shows in the trace as a stretch where the stage stands still, and the
    // static-friction peak when it resumes goes beyond the rolling level.
    let push = std::fs::read_to_string(dir.join("push.csv")).unwrap();
    let rows: Vec<Vec<&str>> = push.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let pushing: Vec<&Vec<&str>> = rows.iter().filter(|r| r[2] == "push").collect();
    let still: Vec<usize> = (1..pushing.len())
        .filter(|&i| pushing[i - 1][3] == pushing[i][3])
        .collect();
    // docs/manipulation.md's "500 ms stop at 6 µm" (`--pause-ms` 500 by default): 500 ticks of 1 ms in
    // one stretch, from the tick the estimate of the distance pushed passes 6 µm.
    assert_eq!(still.len(), 500, "ticks without stage motion during the 500 ms stop");
    assert_eq!(still[still.len() - 1] - still[0], 499, "one stretch: {still:?}");
    let at: f64 = pushing[still[0]][7].parse().unwrap();
    assert!((6.0..6.01).contains(&at), "the stop began at an estimate of {at} µm");
    let v: Vec<f64> = pushing.iter().map(|r| r[6].parse().unwrap()).collect();
    // The rolling level before the stop (the mean of the rolling samples), and the peak after it.
    let (stop, restart) = (still[0], still[still.len() - 1]);
    let rolling: Vec<f64> = (0..stop).filter(|&i| pushing[i][10] == "roll").map(|i| v[i]).collect();
    let rolling = rolling.iter().sum::<f64>() / rolling.len() as f64;
    let peak = v[restart..].iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(peak < rolling - 0.3, "peak {peak} V against rolling {rolling} V");
    assert!(
        (peak + 1.78).abs() <= 0.005,
        "restart peak {peak} V (docs/manipulation.md: −1.78 V)"
    );
    assert!(
        (rolling + 1.1).abs() <= 0.05,
        "rolling level {rolling} V (docs/manipulation.md: about −1.1 V)"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// docs/manipulation.md's push table ("Measured pushes"), row 4: `nanopush push --scene scenes/gold-latex-500nm.toml --to-um
/// 40,55`, 25 µm in legs of at most 20 µm (the scene's `strategy.max_push_um`): two pushes of
/// 12.5 µm, each from where a local scan finds the particle, touching at step 43, ending 0.4 nm and
/// 0.7 nm short, 0.7 nm from the target.
#[test]
fn a_far_target_is_reached_in_two_pushes_as_documented() {
    let r = json(&[
        "push",
        "--scene",
        "scenes/gold-latex-500nm.toml",
        "--to-um",
        "40,55",
        "--json",
    ]);
    let legs = r["legs"].as_array().unwrap();
    assert_eq!(legs.len(), 2, "{r}");
    assert!(legs.iter().all(|l| l["outcome"] == "ok" && l["retracted"] == true));
    for (leg, readme_nm) in legs.iter().zip([-0.4, -0.7]) {
        assert_eq!(leg["contact_step"], 43, "{leg}");
        let xy = |k: &str| (leg[k][0].as_f64().unwrap(), leg[k][1].as_f64().unwrap());
        let (from, to) = (xy("from"), xy("to"));
        let asked = (to.0 - from.0).hypot(to.1 - from.1);
        assert!((asked - 12.5e-6).abs() < 1e-9, "a leg of {asked:e} m");
        let error = leg["true_distance"].as_f64().unwrap() - asked;
        assert!(
            (error / 1e-9 - readme_nm).abs() <= 0.05,
            "leg error {error:e} m (docs/manipulation.md: {readme_nm} nm)"
        );
    }
    let err = r["final_error"].as_f64().unwrap();
    assert!(
        (err / 1e-9 - 0.7).abs() <= 0.05,
        "final error {err:e} m (docs/manipulation.md: 0.7 nm)"
    );
}

#[test]
fn bad_arguments_are_refused_with_the_allowed_range() {
    for (args, expect) in [
        (vec!["push", "--distance-um", "0"], "allowed: (0, 100] µm"),
        (vec!["push", "--distance-um", "NaN"], "allowed: (0, 100] µm"),
        (
            vec!["push", "--distance-um", "1", "--direction-deg", "400"],
            "[-360, 360]",
        ),
        (vec!["push", "--to-um", "150,10"], "allowed: [0, 100] µm"),
        (vec!["push", "--to-um", "abc"], "X_UM,Y_UM"),
        (vec!["push"], "--distance-um D"),
        (
            vec!["push", "--distance-um", "1", "--particle", "9"],
            "no such particle",
        ),
        (
            vec!["push", "--distance-um", "1", "--control", "w"],
            "allowed: xy, z, xyz",
        ),
        (
            vec!["push", "--distance-um", "1", "--pause-at-um", "1", "--pause-ms=-5"],
            "(0, 10000] ms",
        ),
        // Told the range, not u32's.
        (
            vec!["push", "--distance-um", "1", "--attempts", "-1"],
            "--attempts -1 is out of range; allowed: [1, 10]",
        ),
        (
            vec!["push", "--distance-um", "1", "--attempts", "11"],
            "allowed: [1, 10]",
        ),
        (
            vec!["push", "--distance-um", "1", "--attempts", "1.5"],
            "allowed: [1, 10]",
        ),
    ] {
        let out = run("nanopush", &args, None);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let (_, err) = text(&out);
        assert!(err.contains(expect), "{args:?}: {err}");
    }
}

/// `--json` callers get the refusal as JSON on stdout (they got nothing), with the exit status 2
/// and the error on stderr; `plan` refuses what `push` refuses.
#[test]
fn a_refusal_is_json_for_json_callers_and_plan_refuses_as_push_does() {
    let dir = tmp("refusal");
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/");
    let scene = std::fs::read_to_string(format!("{scenes}gold-latex-500nm.toml")).unwrap();
    let from = scene.lines().find(|l| l.starts_with("start_height_um")).unwrap();
    let low = dir.join("low.toml");
    std::fs::write(&low, scene.replacen(from, "start_height_um = 0.05", 1)).unwrap();
    let low = low.to_str().unwrap();
    for args in [
        vec!["plan", "--scene", low, "--json"],
        vec!["push", "--scene", low, "--distance-um", "1", "--json"],
    ] {
        let out = run("nanopush", &args, None);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let (stdout, stderr) = text(&out);
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{args:?}: {e}: {stdout}"));
        assert_eq!(v["schema"], args[0]);
        assert_eq!(v["outcome"], "refused");
        assert_eq!(v["code"], "geometry");
        assert_eq!(v["field"], "strategy.start_height_um");
        assert!(stderr.contains("no strategy can push particle"), "{stderr}");
    }
    let dynamic = format!("{scenes}paper-full-dynamics.toml");
    let out = run("nanopush", &["plan", "--scene", &dynamic, "--json"], None);
    let v: serde_json::Value = serde_json::from_str(&text(&out).0).unwrap();
    assert_eq!((v["code"].as_str(), out.status.code()), (Some("model"), Some(2)));
}

/// A particle that rolls on in front of the tip (lab campaign seed 9, the scene the plan's unit
/// test derives from): `nanopush plan --json` chooses no lost-particle test and says why, and
/// `nanopush push --distance-um 1` moves it in three pushes, following the substrate's slope, to
/// within 5 nm (2.2 nm);
/// with `--control z` the push is refused before anything moves.
#[test]
fn a_rolling_particle_is_planned_without_a_lost_test_and_pushed_ok() {
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../instrument/src/control/derive/scenes/lab-seed-9.toml"
    );
    let plan = json(&["plan", "--scene", scene, "--json"]);
    let lost = plan["choices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == "strategy.lost_threshold_mv")
        .unwrap();
    assert_eq!(lost["value"], 0.0, "{lost}");
    // A switch is written as the scene file takes it.
    let follow = plan["choices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == "strategy.follow_slope")
        .unwrap();
    assert_eq!(follow["value"], true, "{follow}");
    assert!(
        lost["why"].as_str().unwrap().starts_with("no lost-particle test: "),
        "{lost}"
    );
    assert!(
        plan["summary"].as_str().unwrap().contains("then no lost-particle test"),
        "{plan}"
    );
    let r = json(&["push", "--scene", scene, "--distance-um", "1", "--json"]);
    assert_eq!(r["outcome"], "ok", "{r}");
    let legs = r["legs"].as_array().unwrap();
    assert_eq!(legs.len(), 3, "{r}");
    assert!(legs.iter().all(|l| l["outcome"] == "ok"), "{r}");
    let err = r["final_error"].as_f64().unwrap();
    assert!(err < 5e-9, "final error {err:e} m");
    // The z loop would hold a reading that is not the contact's: the push is refused, naming xy.
    let out = run(
        "nanopush",
        &[
            "push",
            "--scene",
            scene,
            "--distance-um",
            "1",
            "--control",
            "z",
            "--json",
        ],
        None,
    );
    assert_eq!(out.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_str(&text(&out).0).unwrap();
    assert_eq!(v["code"], "unreadable", "{v}");
    assert!(
        v["field"].as_str().unwrap().starts_with("strategy.control = \"xy\""),
        "{v}"
    );
}
