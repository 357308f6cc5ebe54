//! `nanopush assemble --random N`: random assemblies nobody tuned
//! (`nanopush_study::random_assemblies`), in parallel, each row appended to
//! `OUT/random-assemblies.csv` as it finishes and each case's scene written to
//! `OUT/scenes/seed-N.toml` first; the table says what share of the sites of the
//! accepted assemblies ended truly filled, whether any site was reported filled falsely, and
//! why the rest stayed open.

use std::fmt::Write as _;
use std::io::Write as _;

use anyhow::Context as _;
use nanopush_study::random_assemblies::{JudgedAssembly, random_assembly, run_case};
use rayon::prelude::*;

const HEADER: &str = "seed,outcome,particles,sites,inside,reported_filled,truly_filled,open,moves,wall_s,push_s,scan_s,violations,refusal,pattern\n";

/// Runs the cases `seeds` and reports them; an unsound case (a site reported filled falsely,
/// a particle through another, a refusal with no reason) makes it an error after the report.
pub fn run(seeds: &[u64], out: &std::path::Path, json: bool) -> anyhow::Result<String> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let scenes = out.join("scenes");
    std::fs::create_dir_all(&scenes).with_context(|| format!("creating {}", scenes.display()))?;
    let csv_path = out.join("random-assemblies.csv");
    crate::units::write_file(&csv_path, HEADER)?;
    let rows = std::sync::Mutex::new(
        std::fs::OpenOptions::new()
            .append(true)
            .open(&csv_path)
            .with_context(|| format!("opening {}", csv_path.display()))?,
    );
    let started = std::time::Instant::now();
    let cases: Vec<JudgedAssembly> = seeds
        .par_iter()
        .map(|&seed| {
            // The case's scene first, to reproduce it while the campaign runs.
            let case = random_assembly(seed);
            if let Ok(text) = case.scene_text() {
                let _ = crate::units::write_file(&scenes.join(format!("seed-{seed}.toml")), text);
            }
            let c = run_case(&case);
            if let Ok(mut f) = rows.lock() {
                // A row lost here is written with the others at the end.
                let _ = f.write_all(row(&c).as_bytes());
            }
            c
        })
        .collect();
    let total = started.elapsed().as_secs_f64();
    let mut csv = String::from(HEADER);
    for c in &cases {
        csv.push_str(&row(c));
    }
    crate::units::write_file(&csv_path, &csv)?;
    let t = Table::of(&cases);
    let text = if json {
        serde_json::to_string_pretty(&serde_json::json!({
            "schema": "nanopush.random_assemblies",
            "version": nanopush_proto::VERSION,
            "cases": cases.len(),
            "accepted": t.accepted,
            "sites_of_accepted": t.sites,
            "truly_filled": t.truly,
            "filled_share": t.share(),
            "falsely_filled": t.false_fills,
            "unsound": t.unsound,
            "open_by_status": t.open,
            "refusals": t.refusals,
            "wall_time": total,
            "wall_per_simulated_push_time": t.wall / t.push.max(1e-9),
        }))? + "\n"
    } else {
        let mut s = String::new();
        writeln!(
            s,
            "Random assemblies, {} cases in {total:.0} s on {} threads: {} accepted, {} refused before anything moved",
            cases.len(),
            rayon::current_num_threads(),
            t.accepted,
            cases.len() - t.accepted
        )?;
        writeln!(
            s,
            "  of the {} sites of the accepted, {} truly filled within their tolerance ({:.1} %); {} reported filled falsely",
            t.sites,
            t.truly,
            100.0 * t.share(),
            t.false_fills
        )?;
        writeln!(s, "  sites left open, by status: {}", counts(&t.open))?;
        writeln!(s, "  refusals: {}", counts(&t.refusals))?;
        writeln!(
            s,
            "  wall time {:.0} s for {:.0} s of simulated pushes ({:.2} of it) and {:.0} s of scans",
            t.wall,
            t.push,
            t.wall / t.push.max(1e-9),
            t.scan
        )?;
        for c in cases.iter().filter(|c| !c.violations.is_empty()) {
            writeln!(s, "  UNSOUND seed {}: {:?}", c.seed, c.violations)?;
        }
        writeln!(
            s,
            "Wrote {} and each case's scene, with the command that assembles it, under {}.",
            csv_path.display(),
            scenes.display()
        )?;
        s
    };
    if t.unsound > 0 {
        anyhow::bail!("{text}{} unsound case(s) (UNSOUND above)", t.unsound);
    }
    Ok(text)
}

fn row(c: &JudgedAssembly) -> String {
    let open: Vec<String> = c.open.iter().map(|(k, n)| format!("{k} {n}")).collect();
    format!(
        "{},{},{},{},{},{},{},{},{},{:.1},{:.1},{:.1},{},{},{}\n",
        c.seed,
        c.outcome,
        c.particles,
        c.sites,
        c.inside,
        c.reported_filled,
        c.truly_filled,
        open.join("; "),
        c.moves,
        c.wall_time,
        c.push_time,
        c.scan_time,
        c.violations.join("; ").replace(',', ";"),
        c.refusal.as_deref().unwrap_or("").replace([',', '\n'], ";"),
        c.spec.replace(',', " ")
    )
}

fn counts(c: &[(String, usize)]) -> String {
    if c.is_empty() {
        return "none".into();
    }
    c.iter().map(|(k, n)| format!("{k} {n}")).collect::<Vec<_>>().join(", ")
}

/// The campaign's figures.
struct Table {
    accepted: usize,
    sites: usize,
    truly: usize,
    false_fills: usize,
    unsound: usize,
    open: Vec<(String, usize)>,
    refusals: Vec<(String, usize)>,
    wall: f64,
    push: f64,
    scan: f64,
}

impl Table {
    fn of(cases: &[JudgedAssembly]) -> Table {
        let accepted: Vec<&JudgedAssembly> = cases.iter().filter(|c| c.outcome != "refused").collect();
        let mut open: Vec<(String, usize)> = Vec::new();
        for (k, n) in accepted.iter().flat_map(|c| c.open.iter()) {
            match open.iter_mut().find(|(o, _)| o == k) {
                Some((_, m)) => *m += n,
                None => open.push((k.clone(), *n)),
            }
        }
        let mut refusals: Vec<(String, usize)> = Vec::new();
        for c in cases.iter().filter(|c| c.outcome == "refused") {
            // The refusal's kind: its words up to the first colon.
            let kind = c
                .refusal
                .as_deref()
                .unwrap_or("")
                .split(':')
                .next()
                .unwrap_or("")
                .chars()
                .take(60)
                .collect::<String>();
            match refusals.iter_mut().find(|(o, _)| *o == kind) {
                Some((_, m)) => *m += 1,
                None => refusals.push((kind, 1)),
            }
        }
        Table {
            accepted: accepted.len(),
            sites: accepted.iter().map(|c| c.sites).sum(),
            truly: accepted.iter().map(|c| c.truly_filled).sum(),
            false_fills: cases
                .iter()
                .flat_map(|c| c.violations.iter())
                .filter(|v| v.contains("reported filled"))
                .count(),
            unsound: cases.iter().filter(|c| !c.violations.is_empty()).count(),
            open,
            refusals,
            wall: cases.iter().map(|c| c.wall_time).sum(),
            push: cases.iter().map(|c| c.push_time).sum(),
            scan: cases.iter().map(|c| c.scan_time).sum(),
        }
    }

    fn share(&self) -> f64 {
        if self.sites == 0 {
            0.0
        } else {
            self.truly as f64 / self.sites as f64
        }
    }
}
