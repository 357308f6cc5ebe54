//! `nanopush scan`: the GSF it writes is read by Gwyddion itself, and bad arguments are refused.

use std::path::Path;
use std::process::Command;

use nanopush_e2e::{run, text};
use serde_json::Value;

use crate::util::{nanopush_json, tmp};

/// Width and height from a PNG's signature and IHDR chunk; panics if it is not a PNG.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    assert!(b.len() > 33, "{} is too short for a PNG", path.display());
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{} has no PNG signature", path.display());
    assert_eq!(&b[12..16], b"IHDR");
    assert_eq!(&b[b.len() - 8..b.len() - 4], b"IEND", "{} is truncated", path.display());
    let be = |k: usize| u32::from_be_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
    (be(16), be(20))
}

/// The GSF's header keys and its total size against XRes × YRes.
fn check_gsf(path: &Path, pixels: usize) {
    let b = std::fs::read(path).unwrap();
    assert!(b.starts_with(b"Gwyddion Simple Field 1.0\n"));
    let nul = b.iter().position(|&c| c == 0).unwrap();
    let header = std::str::from_utf8(&b[..nul]).unwrap();
    for key in [
        format!("XRes = {pixels}"),
        format!("YRes = {pixels}"),
        "XReal = ".into(),
        "YReal = ".into(),
        "XYUnits = m".into(),
        "ZUnits = m".into(),
        "Title = nanopush scan of".into(),
    ] {
        assert!(header.contains(&key), "{key:?} not in the header:\n{header}");
    }
    let data_start = nul + (4 - nul % 4);
    assert_eq!(b.len() - data_start, pixels * pixels * 4);
}

/// `make test` installs Gwyddion (`.ci/setup`): its absence is a failure, not a skip.
fn thumbnail(gsf: &Path, png: &Path) {
    let o = Command::new("gwyddion-thumbnailer")
        .args(["gnome2", "128"])
        .arg(gsf)
        .arg(png)
        .output()
        .unwrap_or_else(|e| {
            panic!("running gwyddion-thumbnailer (Debian package gwyddion; `make setup` installs it): {e}")
        });
    assert!(
        o.status.success(),
        "gwyddion-thumbnailer failed on {}: {}",
        gsf.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let (w, h) = png_size(png);
    assert!(w == 128 || h == 128, "thumbnail is {w}×{h}");
}

#[test]
fn gwyddion_reads_the_scans_of_the_default_and_gold_latex_scenes() {
    let dir = tmp("scan-gwy");
    for (scene, n_particles) in [(None, 1), (Some("scenes/gold-latex-500nm.toml"), 3)] {
        let name = scene.map_or("default", |_| "gold");
        let gsf = dir.join(format!("{name}.gsf"));
        let mut args = vec!["scan", "--json", "--size", "128", "--out", gsf.to_str().unwrap()];
        if let Some(s) = scene {
            args.extend(["--scene", s]);
        }
        let v = nanopush_json(&args);
        assert_eq!(v["schema"], "nanopush.scan");
        assert_eq!(v["pixels"], 128);
        assert_eq!(v["found"].as_array().unwrap().len(), n_particles, "{v}");
        let pixel = v["pixel"].as_f64().unwrap();
        for c in v["particles"].as_array().unwrap() {
            let l = &c["located"];
            let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {c}"));
            assert!(
                (f(l, "x") - f(c, "x")).abs() <= pixel && (f(l, "y") - f(c, "y")).abs() <= pixel,
                "{c}"
            );
            assert!((f(l, "radius") / f(c, "radius") - 1.0).abs() < 0.02, "{c}");
        }
        check_gsf(&gsf, 128);
        assert_eq!(png_size(&gsf.with_extension("png")), (128, 128));
        thumbnail(&gsf, &dir.join(format!("{name}-thumb.png")));
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn summary_names_the_located_particle() {
    let dir = tmp("scan-summary");
    let gsf = dir.join("s.gsf");
    let o = run(
        "nanopush",
        &[
            "scan",
            "--size",
            "64",
            "--out",
            gsf.to_str().unwrap(),
            "--locate",
            "50.5,49.5",
        ],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(out.contains("64 × 64 pixels"), "{out}");
    assert!(out.contains("particles found in the image: 1"), "{out}");
    assert!(out.contains("--locate: ("), "{out}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_arguments_are_a_usage_error_naming_the_allowed_range() {
    let dir = tmp("scan-bad");
    let gsf = dir.join("bad.gsf");
    let g = gsf.to_str().unwrap();
    let cases: [(&[&str], &str); 7] = [
        (
            &["--size", "0"],
            "--size 0 pixels is out of range; allowed: [8, 4096] pixels",
        ),
        (
            &["--size", "100000"],
            "--size 100000 pixels is out of range; allowed: [8, 4096] pixels",
        ),
        (&["--locate", "abc"], "--locate \"abc\": expected X_UM,Y_UM"),
        (&["--locate", "50"], "expected X_UM,Y_UM"),
        (&["--locate", "90,50"], "allowed: x in [25, 75] µm, y in [25, 75] µm"),
        (
            &["--locate", "30,30", "--search-um", "1"],
            "--locate 30,30: no particle within 1 µm",
        ),
        (&["--search-um", "0"], "allowed: (0, 50] µm"),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["scan", "--out", g];
        if !extra.contains(&"--size") {
            args.extend(["--size", "16"]);
        }
        args.extend_from_slice(extra);
        let o = run("nanopush", &args, None);
        let (out, err) = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(out.is_empty(), "{out}");
        assert!(err.contains(expected), "{args:?}: expected {expected:?} in: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let o = run(
        "nanopush",
        &["scan", "--out", dir.join("x.png").to_str().unwrap()],
        None,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("must end in .gsf"));
    std::fs::remove_dir_all(&dir).ok();
}
