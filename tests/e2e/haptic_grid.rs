//! The haptic grid with the real processes, a subset sized for `make test` (the full grid is the
//! `nanopush-haptic-grid` benchmark; every cell in one process is `instrument/tests/haptic_grid.rs`):
//! the worst cells (10 N of pull-off at 10 and 1000 nm/mm, which unlimited chatter for a second
//! and hand the hand millijoules), a tap there, and a hand that lets go. Each passes the grid's
//! bounds (`nanopush_e2e::haptic_grid`), and a scale past the
//! device's region is answered with the scales in force and the reason, which `/api/status`
//! shows too.

use nanopush_e2e::haptic_grid::{CellBench, run_cell};

use crate::haptic_link::one_at_a_time;

/// One cell; the runs' figures are printed (`--nocapture`).
fn cell(tag: &str, operator: &str, nm_per_mm: f64, pull_off_n: f64) -> nanopush_e2e::haptic_grid::CellRun {
    let _one = one_at_a_time();
    let b = CellBench::new(tag);
    let run = run_cell(&b, operator, nm_per_mm, pull_off_n).unwrap_or_else(|e| {
        for log in ["server.log", "bridge.log"] {
            eprintln!(
                "--- {log} ---\n{}",
                std::fs::read_to_string(b.dir.join(log)).unwrap_or_default()
            );
        }
        panic!("{operator} at {nm_per_mm} nm/mm, {pull_off_n} N: {e}")
    });
    println!(
        "{operator} {nm_per_mm} nm/mm {pull_off_n} N: {} ({} rows)",
        run.verdict, run.rows
    );
    assert!(run.rows > 3000, "{} rows", run.rows);
    // Every cell reaches the surface (a cell that never touched would pass its bounds vacuously:
    // a lease holder that had left ended z-control, and these cells passed with no force).
    assert!(
        run.verdict.max_force > 0.05,
        "{operator}: no force at the hand: {}",
        run.verdict
    );
    assert!(
        run.verdict.passes(),
        "{operator} at {nm_per_mm} nm/mm, {pull_off_n} N: {}",
        run.verdict
    );
    run
}

/// The hardest press: 10 nm/mm and 10 N. It is answered with the region's
/// edge (the pull-off lowered from 10 N to what 2 kN/m allows, 1.38 N), shown in the status,
/// and the press is passive, calm, and holds the tip steady.
#[test]
fn a_press_at_the_strongest_scales_is_limited_passive_and_calm() {
    let run = cell("p10x10", "press", 10.0, 10.0);
    let s = &run.scales;
    assert_eq!(s["limit"], "renderable_region", "{s}");
    assert!(s["reason"].as_str().unwrap().contains("Z-width"), "{s}");
    let k_max = s["max_stiffness_n_per_m"].as_f64().unwrap();
    assert!((1500.0..=2100.0).contains(&k_max), "{s}");
    let felt = s["felt_stiffness_n_per_m"].as_f64().unwrap();
    assert!((felt - k_max).abs() < 1e-6 * k_max, "{s}");
    let pull_off = s["pull_off_at_hand_n"].as_f64().unwrap();
    assert!(pull_off < 1.6 && s["asked_pull_off_at_hand_n"] == 10.0, "{s}");
    let st = &run.status;
    assert_eq!(st["scales"]["limit"], "renderable_region", "{st}");
    assert!(
        st["raw_port_energy_j"].is_number() && st["stored_energy_bound_j"].as_f64().unwrap() > 0.0,
        "{st}"
    );
    assert!(run.verdict.tip_windows >= 10, "held in contact: {}", run.verdict);
}

/// The worst corner: 1000 nm/mm and 10 N (a contact asked 1000 times stiffer than the device
/// renders), and a tap there.
#[test]
fn the_stiffest_corner_is_passive_and_calm_pressed_and_tapped() {
    let run = cell("p1000x10", "press", 1000.0, 10.0);
    assert_eq!(run.scales["limit"], "renderable_region");
    cell("t1000x10", "tap", 1000.0, 10.0);
}

/// At the default scale the scales are as asked (a loose grip there, which the old loop made
/// active, is a cell of the in-process grid: 24 s of press with the real processes); a hand that
/// lets go of the handle in contact at 100 nm/mm and 2.5 N stays passive.
#[test]
fn a_hand_that_lets_go_in_contact_stays_passive() {
    let run = cell("g100x2", "let-go", 100.0, 2.5);
    assert_eq!(run.scales["limit"], "renderable_region", "{}", run.scales);
}
