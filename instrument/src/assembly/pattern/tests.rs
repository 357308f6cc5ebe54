//! Patterns: the file's form and its errors, the generators' shapes.

use super::*;

const UM: f64 = 1e-6;

fn close(a: (f64, f64), b: (f64, f64)) -> bool {
    (a.0 - b.0).hypot(a.1 - b.1) < 1e-12
}

#[test]
fn a_file_gives_its_sites_in_si_with_their_tolerances() {
    let p = Pattern::parse(
        "p.toml",
        r#"
name = "two"
radius_nm = 500
tolerance_nm = 40
[[site]]
x_um = 10
y_um = 20.5
[[site]]
x_um = 30
y_um = 20.5
tolerance_nm = 30
"#,
    )
    .unwrap();
    assert_eq!(p.name, "two");
    assert_eq!(p.radius, Some(500e-9));
    assert_eq!(p.sites.len(), 2);
    assert!(close((p.sites[0].x, p.sites[0].y), (10.0 * UM, 20.5 * UM)));
    assert_eq!(p.sites[0].tolerance, Some(40e-9));
    assert_eq!(p.sites[1].tolerance, Some(30e-9));
}

#[test]
fn a_bad_file_names_the_field_and_the_allowed_range() {
    let e = |text: &str| Pattern::parse("p.toml", text).unwrap_err().to_string();
    assert_eq!(
        e("[[site]]\nx_um = 1\ny_um = 2\ntolerance_nm = 0.5\n"),
        "p.toml: site[0].tolerance_nm = 0.5 is out of range; allowed: [1, 100000] nm"
    );
    assert_eq!(
        e("radius_nm = 1\n[[site]]\nx_um = 1\ny_um = 2\n"),
        "p.toml: radius_nm = 1 is out of range; allowed: [2, 10000] nm"
    );
    assert!(
        e("").contains("[[site]] entries = 0 is out of range; allowed: [1, 400]"),
        "{}",
        e("")
    );
    assert!(
        e("[[site]]\nx_um = 1\n").starts_with("p.toml: missing field `y_um`"),
        "{}",
        e("[[site]]\nx_um = 1\n")
    );
    assert!(e("[[site]]\nx_um = 1\ny_um = 2\nz_um = 3\n").contains("unknown field `z_um`"));
    assert!(e("[[site]]\nx_um = nan\ny_um = 2\n").contains("site[0].x_um = NaN is out of range"));
}

#[test]
fn a_line_is_centred_on_its_point_and_turned_by_its_angle() {
    let p = Pattern::generate("line:n=3,spacing_um=4,angle_deg=90", (50.0 * UM, 40.0 * UM)).unwrap();
    let xy: Vec<(f64, f64)> = p.sites.iter().map(|s| (s.x, s.y)).collect();
    assert!(close(xy[0], (50.0 * UM, 36.0 * UM)), "{xy:?}");
    assert!(close(xy[1], (50.0 * UM, 40.0 * UM)));
    assert!(close(xy[2], (50.0 * UM, 44.0 * UM)));
    assert!(close(p.centre(), (50.0 * UM, 40.0 * UM)));
}

#[test]
fn a_grid_and_a_ring_have_their_counts_and_spacings() {
    let g = Pattern::generate("grid:rows=2,cols=3,spacing_um=5", (50.0 * UM, 50.0 * UM)).unwrap();
    assert_eq!(g.sites.len(), 6);
    let d = |a: &Site, b: &Site| (a.x - b.x).hypot(a.y - b.y);
    assert!((d(&g.sites[0], &g.sites[1]) - 5.0 * UM).abs() < 1e-12);
    assert!((d(&g.sites[0], &g.sites[3]) - 5.0 * UM).abs() < 1e-12);
    assert!(close(g.centre(), (50.0 * UM, 50.0 * UM)));
    let r = Pattern::generate("ring:n=8,radius_um=6,tolerance_nm=30", (40.0 * UM, 60.0 * UM)).unwrap();
    assert_eq!(r.sites.len(), 8);
    for s in &r.sites {
        assert!(((s.x - 40.0 * UM).hypot(s.y - 60.0 * UM) - 6.0 * UM).abs() < 1e-12);
        assert_eq!(s.tolerance, Some(30e-9));
    }
}

#[test]
fn text_is_dots_of_the_5_by_7_font() {
    let i = Pattern::generate("text:I,pitch_um=2", (50.0 * UM, 50.0 * UM)).unwrap();
    // The I: three dots on top and at the bottom, five down the middle.
    assert_eq!(i.sites.len(), 3 + 5 + 3);
    let np = Pattern::generate("text:NP,pitch_um=3", (50.0 * UM, 50.0 * UM)).unwrap();
    assert!(np.sites.len() > 20);
    let xs: Vec<f64> = np.sites.iter().map(|s| s.x).collect();
    let (lo, hi) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, &x| (a.0.min(x), a.1.max(x)));
    // Two letters of five columns and a blank between: 10 pitches wide, centred.
    assert!((hi - lo - 10.0 * 3.0 * UM).abs() < 1e-12, "{lo} {hi}");
    assert!(((hi + lo) / 2.0 - 50.0 * UM).abs() < 1e-12);
}

#[test]
fn a_bad_generator_says_what_is_wrong_and_what_is_allowed() {
    let e = |spec: &str| Pattern::generate(spec, (0.0, 0.0)).unwrap_err().to_string();
    assert_eq!(
        e("star:n=5"),
        "pattern \"star:n=5\": unknown shape \"star\"; allowed: line, grid, ring, text"
    );
    assert_eq!(e("line:spacing_um=4"), "pattern \"line:spacing_um=4\": line needs n=…");
    assert!(e("line:n=2.5,spacing_um=4").contains("n = 2.5 is out of range; allowed: a whole number in [2, 400]"));
    assert!(e("line:n=3,spacing_um=0").contains("spacing_um = 0 is out of range; allowed: (0, 1000] µm"));
    assert!(e("line:n=3,spacing_um=4,colour=red").contains("line takes no \"colour\"; allowed: n, spacing_um"));
    assert!(e("ring:n=8,radius_um=x").contains("radius_um=\"x\" is not a number"));
    assert!(e("grid:rows=30,cols=30,spacing_um=2").contains("rows × cols = 900; allowed: [2, 400] sites"));
    assert!(e("text:a?,pitch_um=2").contains("'?' is not in the font"));
    assert!(
        e("line:n=3,spacing_um=4,tolerance_nm=0").contains("tolerance_nm = 0 is out of range; allowed: [1, 100000] nm")
    );
}
