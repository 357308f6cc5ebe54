//! An assembly on a server's state without a loop: the plan from the first full frame, `plan_only`
//! of the largest pattern, and a stop before the first move.

use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use nanopush_instrument::assembly::{AssemblyOptions, Pattern};

use super::*;
use crate::app_state::test_state;

fn job(st: &AppState, pattern: Pattern, plan_only: bool) -> AssemblyJob {
    st.activity.assembling.store(true, Relaxed);
    AssemblyJob {
        number: 7,
        pattern,
        options: AssemblyOptions::default(),
        plan_only,
        by: 1,
        person: "operator".into(),
        generation: st.activity.generation.load(Relaxed),
    }
}

fn done(rx: &mut tokio::sync::broadcast::Receiver<axum::extract::ws::Utf8Bytes>) -> (Vec<String>, serde_json::Value) {
    let mut types = Vec::new();
    while let Ok(m) = rx.try_recv() {
        let v: serde_json::Value = serde_json::from_str(m.as_str()).unwrap();
        types.push(v["type"].as_str().unwrap().to_string());
        if v["type"] == "assembly_done" {
            return (types, v);
        }
    }
    panic!("no assembly_done: {types:?}")
}

/// The largest pattern a command may give, 400 sites, planned on the thread in well under a
/// second's order and ended `planned`, nothing moved, the instrument free.
#[test]
fn a_plan_only_assembly_of_400_sites_is_planned_and_ends() {
    let st = test_state();
    let mut rx = st.channels.events.subscribe();
    let grid = Pattern::generate("grid:rows=20,cols=20,spacing_um=4", (50e-6, 50e-6)).unwrap();
    let t0 = Instant::now();
    run_assembly(&st, job(&st, grid, true));
    let took = t0.elapsed().as_secs_f64();
    let (types, end) = done(&mut rx);
    assert_eq!(end["outcome"], "planned", "{end}");
    assert_eq!(types, ["assembly_planned", "assembly_done"]);
    assert!(took < 30.0, "{took} s");
    assert!(!st.activity.assembling.load(Relaxed));
    assert!(st.activity.assembly_now.lock().unwrap().is_none());
    assert!(!st.shared.busy.load(Relaxed));
}

/// A `stop` (or the holder leaving) while the first plan is made ends the assembly `stopped`
/// before any move, with its last frame and its record.
#[test]
fn a_stop_during_the_first_plan_ends_it_before_any_move() {
    let st = test_state();
    let mut rx = st.channels.events.subscribe();
    let p = st.scene.pushed_particle().clone();
    let sites = Pattern::generate("line:n=2,spacing_um=4", (p.x_um * 1e-6 + 3e-6, p.y_um * 1e-6)).unwrap();
    let j = job(&st, sites, false);
    st.activity.generation.fetch_add(1, Relaxed);
    run_assembly(&st, j);
    let (types, end) = done(&mut rx);
    assert_eq!(types, ["assembly_planned", "assembly_done"], "no move");
    assert_eq!(end["outcome"], "stopped", "{end}");
    assert_eq!(
        end["reason"], "stopped: the lease holder disconnected",
        "nobody holds the lease here"
    );
    let name = end["record"].as_str().expect("a record");
    let path = st.cfg.data_dir.join(name);
    let rec: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(rec["summary"]["outcome"], "stopped");
    for frame in ["first_frame", "final_frame"] {
        let gsf = rec[frame]["record"].as_str().expect("a frame's record");
        let _ = std::fs::remove_file(st.cfg.data_dir.join(gsf));
        let _ = std::fs::remove_file(st.cfg.data_dir.join(gsf.replace(".gsf", ".json")));
    }
    std::fs::remove_file(path).unwrap();
}

/// Particles the simulation has overlapping after a move are reported, each pair once.
#[test]
fn overlapping_particles_after_a_move_are_violations_once() {
    let st = test_state();
    let grid = Pattern::generate("grid:rows=1,cols=2,spacing_um=4", (50e-6, 50e-6)).unwrap();
    let j = job(&st, grid, true);
    let mut a = Assembly::new(&st, &j);
    {
        let mut s = st.shared.snapshot.lock().unwrap();
        s.particles = vec![
            (1, 10e-6, 10e-6, 0.5e-6),
            (2, 10.8e-6, 10e-6, 0.5e-6),
            (3, 20e-6, 10e-6, 0.5e-6),
        ];
    }
    a.check_overlaps(1);
    a.check_overlaps(2);
    assert_eq!(
        a.violations,
        ["after move 1, particles 1 and 2 overlap (200 nm deep) at (10.000, 10.000) µm"]
    );
    st.shared.snapshot.lock().unwrap().particles[1].1 = 11.2e-6;
    a.check_overlaps(3);
    assert_eq!(a.violations.len(), 1, "apart again: nothing new");
}
