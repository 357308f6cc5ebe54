//! `nanopush push`: a whole manipulation from the command line — the Fig 9 contact step, the
//! distance reached, a planned multi-push move, the files written, and bad arguments refused.

use std::path::PathBuf;

use nanopush_e2e::{run, text};
use serde_json::Value;

fn tmp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nanopush-e2e-push-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn json(args: &[&str]) -> Value {
    let out = run("nanopush", args, None);
    assert!(out.status.success(), "nanopush {args:?} failed: {}", text(&out).1);
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn a_12_um_push_with_a_stop_reaches_its_target_and_writes_figs_9_and_15() {
    let dir = tmp("fig15");
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
    let still = pushing.windows(2).filter(|w| w[0][3] == w[1][3]).count();
    assert!(
        still >= 400,
        "{still} ticks without stage motion during the 500 ms stop"
    );
    let v: Vec<f64> = pushing.iter().map(|r| r[6].parse().unwrap()).collect();
    let rolling = v[v.len() / 4];
    let min = v.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(min < rolling - 0.3, "peak {min} V against rolling {rolling} V");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_far_target_is_planned_as_several_pushes() {
    // 25 µm in legs of at most 20 µm (the scene's strategy.max_push_um): two pushes.
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
    let err = r["final_error"].as_f64().unwrap();
    assert!(err < 60e-9, "final error {err:e} m over two legs");
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
    ] {
        let out = run("nanopush", &args, None);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let (_, err) = text(&out);
        assert!(err.contains(expect), "{args:?}: {err}");
    }
}
