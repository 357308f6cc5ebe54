//! Issue 25's grid, in one process and tick by tick (the bridge's device cycle with the
//! simulated handle and hand, the server's law, the simulated instrument, one tick of delay each
//! way, as `haptic_loop.rs` joins them): every position scale × pull-off scale × operator the
//! issue names, at the scales a `scale` request accepts. Each cell must end its closed cycle
//! (free space → contact → free space) with the raw port's energy `−Σ F·Δx ≥ −1 µJ`, never
//! render more than the device's force, chatter in at most 50 cycles (the hand force's second
//! difference above 0.05 N), and keep the tip force, while the hand holds it in contact, within
//! 10 % of its mean over every 20 ms window. The same cells run with the real processes in
//! `tests/e2e/haptic_grid.rs` (a subset) and in the `nanopush-haptic-grid` benchmark (all).

use nanopush::control::bilateral::{Bilateral, Input, Phase};
use nanopush::instrument::Afm;
use nanopush::scene::Scene;
use nanopush_haptic::bridge::{Bridge, BridgeConfig, CycleRow, Link};
use nanopush_haptic::grid::{CellVerdict, GRID_NM_PER_MM, GRID_OPERATORS, GRID_PULL_OFF_N, judge};
use nanopush_haptic::operator::Script;
use nanopush_haptic::sim::SimDevice;
use nanopush_proto::haptic::{ForceFeedback, HapticState};

/// The link: the newest sample each way.
#[derive(Default)]
struct Wire {
    state: Option<HapticState>,
    force: Option<ForceFeedback>,
}

impl Link for Wire {
    fn publish(&mut self, s: &HapticState) {
        self.state = Some(*s);
    }
    fn newest(&mut self) -> Option<ForceFeedback> {
        self.force.take()
    }
}

/// One cell: the operator `script` at `nm_per_mm` and `pull_off_n` (set as a `scale` request
/// sets them), until the script ends or 30 s; the rows from the engagement on.
fn run(nm_per_mm: f64, pull_off_n: f64, script: &str) -> Vec<CycleRow> {
    let dt = 1e-3;
    let scene = Scene::default_scene();
    let mut afm = Afm::from_scene(&scene, 20e-6, 20e-6, dt);
    let mut law = Bilateral::new(scene.bilateral_params(dt));
    law.rescale(
        Some(nm_per_mm * 1e-6),
        Some(pull_off_n / scene.tip_sample().adhesion()),
        None,
    );
    let device = SimDevice::new(Script::parse(script).expect("a grid script"), dt);
    let mut bridge = Bridge::new(device, BridgeConfig::default(), 0);
    let mut wire = Wire::default();
    let mut reading = afm.read();
    law.engage(reading.stage);
    let mut rows = Vec::new();
    let mut engaged = false;
    for n in 0..30_000u64 {
        let now = (n + 1) * 1_000_000;
        let o = law.tick(&Input {
            handle: wire.state,
            stage: reading.stage,
            volts: reading.volts,
            pushing: false,
        });
        reading = afm.step(o.target.unwrap_or(reading.stage)).expect("the free tip steps");
        wire.force = Some(ForceFeedback {
            seq: n,
            time_ns: now,
            ..o.feedback
        });
        engaged |= law.phase() == Phase::Engaged;
        let row = bridge.cycle(now + 30_000, &mut wire);
        if engaged {
            rows.push(row);
        }
        if bridge.device.operator.finished() {
            break;
        }
    }
    assert!(engaged, "{script} at {nm_per_mm} nm/mm, {pull_off_n} N never engaged");
    rows
}

/// Issue 25's failure, first: the press at 10 nm/mm and 10 N handed the hand energy nothing
/// stored (−4.1 mJ) and buzzed for a second (1308-1820 cycles of chatter). Limited to the
/// device's region it ends positive and calm.
#[test]
fn issue_25_a_press_at_10_nm_per_mm_and_10_n_is_passive_and_calm() {
    let v = judge(&run(10.0, 10.0, "press"), 2.5);
    assert!(v.passes(), "{v:?}");
}

/// Every cell of the grid (80, ~1 s in all).
#[test]
fn every_cell_of_the_grid_is_passive_calm_and_keeps_the_tip_steady() {
    let mut failed = Vec::new();
    for op in GRID_OPERATORS {
        for g in GRID_NM_PER_MM {
            for f in GRID_PULL_OFF_N {
                let v: CellVerdict = judge(&run(g, f, op), 2.5);
                println!("{op:>10} {g:>6} nm/mm {f:>4} N: {v}");
                // A press that reaches the surface (10 nm/mm and finer: at 1 nm/mm the
                // surface is 100 mm of handle away, past the travel) is held in contact.
                let held = op != "tap" && g >= 10.0;
                if !v.passes() || (held && v.tip_windows < 10) {
                    failed.push(format!("{op} {g} nm/mm {f} N: {v}"));
                }
            }
        }
    }
    assert!(failed.is_empty(), "cells that fail:\n{}", failed.join("\n"));
}
