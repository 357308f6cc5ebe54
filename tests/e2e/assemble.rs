//! `nanopush assemble`: particles pushed into a pattern from the command line — the sites filled
//! by the truth, the files written, a pattern off the stage refused before anything moves,
//! bad arguments named with their ranges, and random cases checked against the truth.

use nanopush_e2e::{run, text, workspace};
use serde_json::Value;

use crate::util::tmp;

/// The shipped assembly scene cut to four particles near the middle, scanned 40 µm wide at 128
/// pixels (the tests run a debug build), written into `dir`.
fn small_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(workspace().join("scenes/assembly-latex.toml")).unwrap();
    let head = &text[..text.find("[[particles]]").unwrap()];
    let rest = &text[text.find("[environment]").unwrap()..];
    let first = &text[text.find("[[particles]]").unwrap()..];
    let block = &first[..first[1..].find("[[particles]]").unwrap() + 1];
    let mut particles = String::new();
    for (k, (x, y)) in [(44.0, 47.0), (57.0, 45.0), (50.0, 58.0), (38.0, 56.0)]
        .iter()
        .enumerate()
    {
        let mut b = block.replacen("id = 1", &format!("id = {}", k + 1), 1);
        b = replace_line(&b, "x_um", &format!("x_um = {x}"));
        b = replace_line(&b, "y_um", &format!("y_um = {y}"));
        particles.push_str(&b);
    }
    let rest = replace_line(
        &replace_line(rest, "size_um", "size_um = 40.0"),
        "pixels",
        "pixels = 128",
    );
    let path = dir.join("small.toml");
    std::fs::write(&path, format!("{head}{particles}{rest}")).unwrap();
    path
}

/// `text` with the line starting `key =` replaced by `line`.
fn replace_line(text: &str, key: &str, line: &str) -> String {
    text.lines()
        .map(|l| {
            if l.trim_start().starts_with(&format!("{key} =")) {
                line.to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

fn summary(dir: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn a_line_is_assembled_within_tolerance_and_its_files_written() {
    let dir = tmp("assemble-line");
    let scene = small_scene(&dir);
    let out = dir.join("out");
    let o = run(
        "nanopush",
        &[
            "assemble",
            "--scene",
            scene.to_str().unwrap(),
            "--pattern",
            "line:n=3,spacing_um=3",
            "--at-um",
            "50,51",
            "--out",
            out.to_str().unwrap(),
        ],
        None,
    );
    let (stdout, stderr) = text(&o);
    assert_eq!(o.status.code(), Some(0), "{stdout}{stderr}");
    assert!(stdout.starts_with("filled: 3 of 3 sites filled"), "{stdout}");
    assert!(
        stderr.contains("planned: 4 particles found, 3 of 3 sites fillable"),
        "{stderr}"
    );
    let s = summary(&out);
    assert_eq!(s["schema"], "nanopush.assembly");
    assert_eq!(s["outcome"], "filled");
    for site in s["sites"].as_array().unwrap() {
        assert_eq!(site["status"], "filled", "{site}");
        let (e, tol) = (site["error"].as_f64().unwrap(), site["tolerance"].as_f64().unwrap());
        assert!(e <= tol, "true error {e:e} beyond {tol:e}: {site}");
        assert!(site["particle"].as_u64().is_some());
    }
    assert_eq!(s["moves"].as_array().unwrap().len(), 3);
    assert!(s["push_time"].as_f64().unwrap() > 0.0);
    assert_eq!(s["violations"].as_array().unwrap().len(), 0);
    for f in ["plan.png", "final.png", "final.gsf"] {
        let len = out.join(f).metadata().map(|m| m.len()).unwrap_or(0);
        assert!(len > 1000, "{f}: {len} bytes");
    }
    // The picture is the first frame's size, scaled up: 128 pixels to 1024.
    let png = std::fs::read(out.join("plan.png")).unwrap();
    assert_eq!(&png[16..24], &[0, 0, 4, 0, 0, 0, 4, 0], "1024 × 1024");
}

#[test]
fn a_pattern_off_the_stage_is_refused_before_anything_moves() {
    let dir = tmp("assemble-off");
    let scene = small_scene(&dir);
    let pattern = dir.join("edge.toml");
    std::fs::write(
        &pattern,
        "[[site]]\nx_um = 50\ny_um = 50\n[[site]]\nx_um = 99.8\ny_um = 50\n",
    )
    .unwrap();
    let out = dir.join("out");
    let o = run(
        "nanopush",
        &[
            "assemble",
            "--scene",
            scene.to_str().unwrap(),
            "--pattern",
            pattern.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ],
        None,
    );
    let (stdout, stderr) = text(&o);
    assert_eq!(o.status.code(), Some(2), "{stdout}{stderr}");
    let s: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(s["outcome"], "refused");
    let why = s["refusal"].as_str().unwrap();
    assert!(
        why.starts_with("site 1 at (99.800, 50.000) µm is off the stage"),
        "{why}"
    );
    assert_eq!(s["moves"].as_array().unwrap().len(), 0);
    assert_eq!(summary(&out), s);
}

#[test]
fn bad_arguments_name_what_is_wrong_and_the_allowed_range() {
    let dir = tmp("assemble-bad");
    let d = dir.to_str().unwrap();
    let cases: [(&[&str], &str); 9] = [
        (
            &["--pattern", "star:n=3"],
            "unknown shape \"star\"; allowed: line, grid, ring, text",
        ),
        (
            &["--pattern", "line:n=3,spacing_um=-1"],
            "spacing_um = -1 is out of range; allowed: (0, 1000] µm",
        ),
        (
            &["--pattern", "line:n=3,spacing_um=3", "--tolerance-nm", "0.5"],
            "--tolerance-nm 0.5 is out of range; allowed: [1, 100000] nm",
        ),
        (
            &["--pattern", "line:n=3,spacing_um=3", "--attempts", "11"],
            "--attempts 11 is out of range; allowed: [1, 10]",
        ),
        (&["--pattern", "line:n=3,spacing_um=3", "--at-um", "x,1"], "--at-um"),
        (&["--pattern", "no-such-file.toml"], "no-such-file.toml"),
        (
            &["--pattern", "no/such/sites"],
            "no/such/sites: No such file or directory",
        ),
        (
            &["--random", "0"],
            "--random 0 is out of range; allowed: [1, 100000] cases",
        ),
        (
            &["--random", "2", "--seed", "18446744073709551615"],
            "--seed 18446744073709551615 is out of range for --random 2",
        ),
    ];
    for (args, says) in cases {
        let mut all = vec!["assemble", "--out", d];
        all.extend_from_slice(args);
        let o = run("nanopush", &all, None);
        let (stdout, stderr) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {stdout}{stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    let o = run("nanopush", &["assemble", "--out", d], None);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("--pattern"), "{}", text(&o).1);
}

/// `nanopush assemble ARGS --out DIR --json` for random cases: its directory and its JSON report,
/// the run having exited 0.
fn random_cases(tag: &str, args: &[&str]) -> (std::path::PathBuf, Value) {
    let dir = tmp(tag);
    let mut all = vec!["assemble"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", dir.to_str().unwrap(), "--json"]);
    let o = run("nanopush", &all, None);
    let (stdout, stderr) = text(&o);
    assert_eq!(o.status.code(), Some(0), "{stdout}{stderr}");
    (dir, serde_json::from_str(&stdout).unwrap())
}

/// Two random cases nobody tuned, checked against the truth: seed 13 (a ring of 3 sites, 4
/// particles, 3 of them inside it) and seed 15 (a 2 × 2 grid, 7 particles), picked by the shard.
#[test]
fn random_cases_are_assembled_and_checked_against_the_truth() {
    let (dir, s) = random_cases("assemble-random", &["--random", "3", "--seed", "13", "--shard", "0/2"]);
    assert_eq!(s["cases"], 2);
    assert_eq!(s["unsound"], 0);
    assert_eq!(s["falsely_filled"], 0);
    assert_eq!(s["sites_of_accepted"], 7);
    assert_eq!(s["truly_filled"], 7, "{s}");
    let csv = std::fs::read_to_string(dir.join("random-assemblies.csv")).unwrap();
    let mut rows: Vec<&str> = csv.lines().skip(1).collect();
    rows.sort();
    assert!(rows[0].starts_with("13,filled,4,3,3,3,3,"), "{csv}");
    assert!(rows[1].starts_with("15,filled,7,4,0,4,4,"), "{csv}");
    assert!(dir.join("scenes/seed-13.toml").exists());
}

/// Random seed 7: a 2 × 2 grid with three of its eleven particles inside it. Filled most central
/// first, one of them was walled in by the sites around it (unreachable); those inside go first.
#[test]
fn particles_inside_the_pattern_are_not_walled_in() {
    let (dir, s) = random_cases("assemble-inside", &["--random", "1", "--seed", "7"]);
    assert_eq!(
        (s["sites_of_accepted"].as_u64(), s["truly_filled"].as_u64()),
        (Some(4), Some(4)),
        "{s}"
    );
    let csv = std::fs::read_to_string(dir.join("random-assemblies.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().starts_with("7,filled,11,4,3,4,4,"), "{csv}");
}
