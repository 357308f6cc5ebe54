//! `nanopush-haptic-grid`: the full haptic grid with the real processes (a benchmark that
//! prints, not a test: 80 cells of 5-25 s each, ~15 min). Each cell starts `nanopush serve
//! --haptic external` and a simulated `nanopush-haptic` playing one operator, sets the scales
//! over the WebSocket as the lease holder, engages, plays the script to its end and judges the
//! bridge's trace (`nanopush_haptic::grid`): the raw port's energy over the closed cycle, the
//! largest hand force, the chatter cycles and the tip force's swing held in contact.
//!
//! ```text
//! cargo run --release -p nanopush-e2e --bin nanopush-haptic-grid [-- CELL...]
//! ```
//!
//! A `CELL` is an operator (all its settings) or `OPERATOR@NM_PER_MM:PULL_OFF_N` (one). Prints
//! one Markdown row per cell, then the cells that failed (their directories kept: the trace and
//! the logs); exits 1 if any did.

use nanopush_e2e::haptic_grid::{CellBench, run_cell};
use nanopush_haptic::grid::{GRID_NM_PER_MM, GRID_OPERATORS, GRID_PULL_OFF_N};

fn main() {
    let asked: Vec<String> = std::env::args().skip(1).collect();
    let mut cells: Vec<(String, f64, f64)> = Vec::new();
    let every = |op: &str, cells: &mut Vec<(String, f64, f64)>| {
        for g in GRID_NM_PER_MM {
            for f in GRID_PULL_OFF_N {
                cells.push((op.to_string(), g, f));
            }
        }
    };
    if asked.is_empty() {
        GRID_OPERATORS.iter().for_each(|op| every(op, &mut cells));
    }
    for a in &asked {
        match a.split_once('@') {
            None => every(a, &mut cells),
            Some((op, setting)) => {
                let parsed = setting
                    .split_once(':')
                    .and_then(|(g, f)| Some((g.parse().ok()?, f.parse().ok()?)));
                let Some((g, f)) = parsed else {
                    eprintln!("{a:?}: expected OPERATOR or OPERATOR@NM_PER_MM:PULL_OFF_N");
                    std::process::exit(2);
                };
                cells.push((op.to_string(), g, f));
            }
        }
    }
    println!(
        "| operator | nm/mm | pull-off asked (N) | in force (N) | limit | raw port energy (J) | max |F| (N) | chatter | tip swing (windows) | |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut failed = Vec::new();
    for (i, (op, g, f)) in cells.iter().enumerate() {
        let mut b = CellBench::new(&format!("b{i}"));
        match run_cell(&b, op, *g, *f) {
            Ok(r) => {
                let v = r.verdict;
                println!(
                    "| {op} | {g} | {f} | {:.3} | {} | {:+.2e} | {:.2} | {} | {:.3} ({}) | {} |",
                    r.scales["pull_off_at_hand_n"].as_f64().unwrap_or(f64::NAN),
                    r.scales["limit"].as_str().unwrap_or("?"),
                    v.energy,
                    v.max_force,
                    v.chatter,
                    v.tip_swing,
                    v.tip_windows,
                    if v.passes() { "pass" } else { "**FAIL**" }
                );
                if !v.passes() {
                    b.keep = true;
                    failed.push(format!("{op} {g} nm/mm {f} N: {v} (in {})", b.dir.display()));
                }
            }
            Err(e) => {
                println!("| {op} | {g} | {f} | | | | | | | **did not run**: {e} |");
                b.keep = true;
                failed.push(format!("{op} {g} nm/mm {f} N: {e} (in {})", b.dir.display()));
            }
        }
    }
    if failed.is_empty() {
        println!("\nevery cell passed");
    } else {
        println!("\n{} cells failed:\n{}", failed.len(), failed.join("\n"));
        std::process::exit(1);
    }
}
