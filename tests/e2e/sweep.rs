//! `nanopush sweep` (Figs 10-13) and `nanopush simulate --plot` (Fig 7).

use nanopush_e2e::{run, text};
use serde_json::Value;

use crate::util::tmp;

const SWEEP: [&str; 12] = [
    "sweep",
    "--param",
    "beta",
    "--from",
    "10",
    "--to",
    "60",
    "--steps",
    "7",
    "--duration",
    "0.02",
    "--pure-sliding",
];

#[test]
fn shard_csvs_concatenate_to_the_unsharded_csv_byte_for_byte() {
    let dir = tmp("sweep-shards");
    let out = dir.to_str().unwrap();
    let whole = run("nanopush", &[&SWEEP[..], &["--out", out]].concat(), None);
    assert!(whole.status.success(), "{}", text(&whole).1);
    let expected = std::fs::read(dir.join("sweep-beta.csv")).unwrap();
    assert!(dir.join("sweep-beta.svg").exists());
    // 7 points over 3 shards: blocks of 2, 2 and 3 rows.
    let mut joined = Vec::new();
    for i in 0..3 {
        let shard = format!("{i}/3");
        let o = run(
            "nanopush",
            &[&SWEEP[..], &["--out", out, "--shard", &shard]].concat(),
            None,
        );
        assert!(o.status.success(), "{}", text(&o).1);
        let part = std::fs::read(dir.join(format!("sweep-beta.shard-{i}-of-3.csv"))).unwrap();
        assert!(i == 0 || !part.starts_with(b"index,"), "only shard 0 writes the header");
        joined.extend(part);
    }
    assert_eq!(
        String::from_utf8(joined).unwrap(),
        String::from_utf8(expected.clone()).unwrap()
    );
    let csv = String::from_utf8(expected).unwrap();
    assert_eq!(csv.lines().count(), 8);
    // The rows are the global indices in order, and the point that fails is a row, not a gap.
    for (k, line) in csv.lines().skip(1).enumerate() {
        assert!(line.starts_with(&format!("{k},")), "{line}");
    }
    // Without --out the CSV goes to stdout, and equals the file.
    let o = run("nanopush", &SWEEP, None);
    assert_eq!(text(&o).0, csv);
}

#[test]
fn json_summary_names_the_trend_and_the_flags() {
    let o = run(
        "nanopush",
        &[
            "sweep",
            "--param",
            "mu_as",
            "--from",
            "0.3",
            "--to",
            "1.5",
            "--steps",
            "5",
            "--duration",
            "0.02",
            "--json",
        ],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains('\u{1b}'), "no escape codes on a pipe: {err:?}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["schema"], "nanopush.sweep");
    assert_eq!(v["figure"], 12);
    assert_eq!(v["points"], 5);
    // Eq 18 jams above μ_as^s = 1.2864 (at the paper's μk/μs = 2/3): 1.5 has no steady state.
    assert_eq!(v["eq18_missing"], serde_json::json!([1.5]));
    assert_eq!(v["eq18"]["y_argmin"], 0.3);
    assert!(v["eq18"]["y_max"].as_f64().unwrap() > v["eq18"]["y_min"].as_f64().unwrap());
    assert_eq!(v["dynamic"]["points"], 5);
    assert!(v["failed"].as_array().unwrap().is_empty());
    assert!(v["wall_time"].as_f64().unwrap() > 0.0);
}

#[test]
fn bad_arguments_are_a_usage_error_naming_the_value_and_the_range() {
    let cases: [(&[&str], &str); 6] = [
        (
            &["--param", "gamma", "--from", "0", "--to", "1", "--steps", "2"],
            "--param gamma: unknown; allowed: alpha [0, 75] deg (α), beta [1, 89] deg (β), mu_as [0, 5] (μ_as^s), radius [2, 10000] nm (Rₐ)",
        ),
        (
            &["--param", "alpha", "--from", "30", "--to", "10", "--steps", "3"],
            "--from must not be above --to",
        ),
        (
            &["--param", "alpha", "--from", "0", "--to", "10", "--steps", "0"],
            "--steps 0 is out of range; allowed: [1, 100000]",
        ),
        (
            &[
                "--param", "alpha", "--from", "0", "--to", "10", "--steps", "3", "--shard", "3/2",
            ],
            "--shard 3/2: shard index 3 is out of range; allowed: 0 to 1",
        ),
        (
            &["--param", "alpha", "--from", "0", "--to", "80", "--steps", "3"],
            "--to 80 is out of range for alpha; allowed: [0, 75] deg",
        ),
        (
            &[
                "--param", "radius", "--from", "100", "--to", "200", "--steps", "3", "--shard", "0/0",
            ],
            "the shard count must be at least 1",
        ),
    ];
    for (args, message) in cases {
        let o = run("nanopush", &[&["sweep"][..], args].concat(), None);
        let (out, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(out.is_empty());
        assert!(err.contains(message), "{args:?}: {err}");
    }
}

#[test]
fn simulate_plot_draws_fig7() {
    let dir = tmp("fig7");
    let svg = dir.join("fig7.svg");
    let o = run(
        "nanopush",
        &[
            "simulate",
            "--duration",
            "0.02",
            "--sample",
            "1e-3",
            "--plot",
            svg.to_str().unwrap(),
        ],
        None,
    );
    assert!(o.status.success(), "{}", text(&o).1);
    let s = std::fs::read_to_string(&svg).unwrap();
    assert!(s.starts_with("<svg") && s.contains("Fig 7") && s.contains("particle offset behind the stage"));
}
