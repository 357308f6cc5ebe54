//! The whole pushes of `nanopush accuracy --extremes` (`nanopush_study::whole_pushes`): a
//! table, `DIR/campaign.csv`, and a JSON value.

use std::fmt::Write as _;
use std::path::Path;

use nanopush_instrument::scene::Scene;
use nanopush_study::whole_pushes::{PushCase, cases, peak_rss_bytes, run_case};
use rayon::prelude::*;

/// Runs the whole pushes around `scene` (in parallel, one case per thread) and reports them.
pub fn run(scene: &Scene, reduced: bool, out: &Path) -> anyhow::Result<(String, serde_json::Value)> {
    let cases = cases(reduced);
    let start = std::time::Instant::now();
    let results: Vec<PushCase> = cases.par_iter().map(|c| run_case(scene, c)).collect();
    let total = start.elapsed().as_secs_f64();
    let rss = peak_rss_bytes();
    let mut csv =
        String::from("case,outcome,distance_um,moved_um,max_volts,ticks,trace_bytes,wall_time_s,violations,reason\n");
    for r in &results {
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{:e},{},{}",
            r.case,
            r.outcome,
            r.distance * 1e6,
            r.moved * 1e6,
            r.max_volts,
            r.ticks,
            r.trace_bytes,
            r.wall_time,
            r.violations.join("; ").replace(',', ";"),
            r.reason.replace(',', ";")
        )?;
    }
    crate::units::write_file(&out.join("campaign.csv"), &csv)?;
    let mut counts: Vec<(String, usize)> = Vec::new();
    for r in &results {
        match counts.iter_mut().find(|(o, _)| *o == r.outcome) {
            Some((_, n)) => *n += 1,
            None => counts.push((r.outcome.clone(), 1)),
        }
    }
    counts.sort_by_key(|c| std::cmp::Reverse(c.1));
    let unsound: Vec<&PushCase> = results.iter().filter(|r| !r.violations.is_empty()).collect();
    let slowest = results.iter().max_by(|a, b| a.wall_time.total_cmp(&b.wall_time));
    let biggest = results.iter().max_by_key(|r| r.trace_bytes);
    let mut text = String::new();
    writeln!(
        text,
        "Whole pushes (A → E, ≥ 1 µm) around scene \"{}\": {} cases in {:.1} s, {} unsound; outcomes: {}",
        scene.file.name,
        results.len(),
        total,
        unsound.len(),
        counts
            .iter()
            .map(|(o, n)| format!("{o} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    if let (Some(s), Some(b)) = (slowest, biggest) {
        writeln!(
            text,
            "  slowest case {:.2} s ({}: {}); largest trace {:.1} MB ({}); peak RSS {}",
            s.wall_time,
            s.case,
            s.outcome,
            b.trace_bytes as f64 / 1e6,
            b.case,
            rss.map_or("unknown".into(), |v| format!("{:.0} MB", v as f64 / 1e6))
        )?;
    }
    writeln!(
        text,
        "  {:<44} {:<17} {:>9} {:>9} {:>8}  reason",
        "case", "outcome", "moved/µm", "|U|max/V", "wall/s"
    )?;
    for r in &results {
        writeln!(
            text,
            "  {:<44} {:<17} {:>9.3} {:>9.3} {:>8.2}  {}{}",
            r.case,
            r.outcome,
            r.moved * 1e6,
            r.max_volts,
            r.wall_time,
            r.reason.chars().take(110).collect::<String>(),
            if r.violations.is_empty() {
                String::new()
            } else {
                format!(" UNSOUND: {}", r.violations.join("; "))
            }
        )?;
    }
    writeln!(text, "Wrote {}/campaign.csv.", out.display())?;
    let json = serde_json::json!({
        "cases": results.len(),
        "unsound": unsound.len(),
        "wall_time": total,
        "peak_rss_bytes": rss,
        "results": results.iter().map(|r| serde_json::json!({
            "case": r.case, "outcome": r.outcome, "reason": r.reason, "distance": r.distance, "moved": r.moved,
            "max_volts": r.max_volts, "violations": r.violations, "ticks": r.ticks, "trace_bytes": r.trace_bytes,
            "wall_time": r.wall_time,
        })).collect::<Vec<_>>(),
    });
    Ok((text, json))
}
