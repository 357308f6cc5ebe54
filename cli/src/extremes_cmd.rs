//! `nanopush accuracy --extremes`: the stability grid over extreme parameters
//! (`nanopush_study::extremes`, `DIR/extremes.csv`), then the whole pushes
//! ([`crate::whole_pushes`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use nanopush_study::extremes::{CaseResult, grid, run_case};

/// Runs `nanopush accuracy --extremes` on `scene` (the embedded paper scene when absent), the
/// reduced grid and whole pushes when `reduced`, writing into `dir`; the text report, or the JSON
/// object when `json`.
pub fn run(scene: Option<&PathBuf>, reduced: bool, dir: &Path, json: bool) -> anyhow::Result<String> {
    let scene = crate::load_scene(scene)?;
    let cases = grid(&scene, reduced);
    let start = std::time::Instant::now();
    let results: Vec<_> = cases.iter().map(|c| run_case(&scene, c, 1e-5)).collect();
    let total = start.elapsed().as_secs_f64();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    crate::units::write_file(&dir.join("extremes.csv"), extremes_csv(&results)?)?;
    let bad = results.iter().filter(|r| !r.finite_and_bounded && !r.refused).count();
    let refused = results.iter().filter(|r| r.refused).count();
    // Then the whole pushes (A → E) over the validated ranges.
    let (whole_text, whole_json) = crate::whole_pushes::run(&scene, reduced, dir)?;
    let mut out = String::new();
    if json {
        let rows: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                let c = &r.case;
                serde_json::json!({
                    "radius_nm": c.radius_nm, "stiffness_n_per_m": c.stiffness_n_per_m, "humidity": c.humidity, "mu_as": c.mu_as,
                    "tilt_deg": c.tilt_deg, "contact_angle_deg": c.contact_angle_deg, "speed_um_per_s": c.speed_um_per_s,
                    "finite_and_bounded": r.finite_and_bounded, "outcome": r.outcome, "diagnoses": r.diagnoses,
                    "steps": r.steps, "rejected": r.rejected, "error": if r.error.is_finite() { Some(r.error) } else { None }, "wall_time": r.wall_time,
                })
            })
            .collect();
        writeln!(
            out,
            "{}",
            serde_json::json!({"schema": "nanopush.extremes", "version": nanopush_proto::VERSION, "scene": scene.file.name, "cases": rows.len(), "not_finite_or_unbounded": bad, "refused": refused, "wall_time": total, "results": rows, "campaign": whole_json})
        )?;
        return Ok(out);
    }
    writeln!(
        out,
        "Stability grid around scene \"{}\": {} cases, {} refused by the scene's rules, {} not finite or unbounded, {:.2} s",
        scene.file.name,
        results.len(),
        refused,
        bad,
        total
    )?;
    write_worst_cases(&mut out, &results)?;
    if bad > 0 {
        writeln!(out, "Not finite or unbounded:")?;
        for r in results.iter().filter(|r| !r.finite_and_bounded && !r.refused) {
            writeln!(out, "{}", case_row(r))?;
        }
    }
    writeln!(out, "Wrote {}/extremes.csv.", dir.display())?;
    out.push_str(&whole_text);
    Ok(out)
}

/// extremes.csv: a row per case of the stability grid.
fn extremes_csv(results: &[CaseResult]) -> anyhow::Result<String> {
    let mut csv = String::from(
        "radius_nm,stiffness_n_per_m,humidity,mu_as,tilt_deg,contact_angle_deg,speed_um_per_s,finite_and_bounded,steps,rejected,error_m,wall_time_s,outcome,diagnoses\n",
    );
    for r in results {
        let c = &r.case;
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{:e},{:e},{},{}",
            c.radius_nm,
            c.stiffness_n_per_m,
            c.humidity,
            c.mu_as,
            c.tilt_deg,
            c.contact_angle_deg,
            c.speed_um_per_s,
            r.finite_and_bounded,
            r.steps,
            r.rejected,
            r.error,
            r.wall_time,
            r.outcome.replace(',', ";"),
            r.diagnoses.join("; ").replace(',', ";")
        )?;
    }
    Ok(csv)
}

/// The five worst cases of the grid by steps, by rejections and by error.
fn write_worst_cases(out: &mut String, results: &[CaseResult]) -> anyhow::Result<()> {
    let header = format!(
        "  {:>8} {:>6} {:>5} {:>5} {:>5} {:>5} {:>8} {:>7} {:>5} {:>10}  outcome",
        "Ra/nm", "kc", "RH", "mu", "alpha", "beta", "V/um/s", "steps", "rej", "error/m"
    );
    for (title, key) in [("most steps", 0), ("most rejections", 1), ("largest error", 2)] {
        let mut sorted: Vec<_> = results.iter().collect();
        sorted.sort_by(|x, y| match key {
            0 => y.steps.cmp(&x.steps),
            1 => y.rejected.cmp(&x.rejected),
            _ => y.error.total_cmp(&x.error),
        });
        writeln!(out, "Worst cases, {title}:")?;
        writeln!(out, "{header}")?;
        for r in sorted.iter().take(5) {
            writeln!(out, "{}", case_row(r))?;
        }
    }
    Ok(())
}

/// One case of the stability grid, a line of the text report.
fn case_row(r: &CaseResult) -> String {
    let c = &r.case;
    format!(
        "  {:>8} {:>6} {:>5} {:>5} {:>5} {:>5} {:>8} {:>7} {:>5} {:>10.2e}  {}{}",
        c.radius_nm,
        c.stiffness_n_per_m,
        c.humidity,
        c.mu_as,
        c.tilt_deg,
        c.contact_angle_deg,
        c.speed_um_per_s,
        r.steps,
        r.rejected,
        r.error,
        r.outcome,
        if r.diagnoses.is_empty() {
            String::new()
        } else {
            format!(" [{}]", r.diagnoses.join("; "))
        }
    )
}
