//! `nanopush campaign`: random valid scenes nobody tuned, planned, pushed and judged
//! (`nanopush_study::random_scenes`), a row per scene in `OUT/random.csv`.

use std::fmt::Write as _;
use std::path::Path;

use nanopush_instrument::control::derive::short;
use nanopush_study::random_scenes::{RandomCase, Ranges, random_scene, run_random, scene_text, shard_seeds};
use rayon::prelude::*;

/// Arguments of `nanopush campaign`: random valid scenes nobody tuned, planned, pushed and
/// judged (`nanopush_study::random_scenes`).
#[derive(clap::Args, Debug)]
pub struct CampaignArgs {
    /// How many random scenes (seeds `--seed` … `--seed + N − 1`), in [1, 100000].
    #[arg(long, value_name = "N", default_value_t = 100, allow_hyphen_values = true, value_parser = crate::units::scenes_arg)]
    random: u64,
    /// The first seed.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true, value_parser = crate::units::seed_arg)]
    seed: u64,
    /// The generator's ranges: `lab` (the instruments and samples of a nanomanipulation lab) or
    /// `validator` (every parameter across the scene validator's whole range).
    #[arg(long, default_value = "lab")]
    ranges: String,
    /// Run only shard I of N (every N-th seed from the I-th), e.g. `--shard 0/4`.
    #[arg(long, value_name = "I/N")]
    shard: Option<String>,
    /// The pushes' tolerance (nm), in [1, 100000].
    #[arg(long, value_name = "NM", default_value_t = nanopush_proto::push::TOLERANCE_NM, allow_hyphen_values = true)]
    tolerance_nm: f64,
    /// Write `random.csv` (a row per scene) here.
    #[arg(long, default_value = "campaign-out")]
    out: std::path::PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
    /// Also write each scene as `OUT/scenes/seed-N.toml` (nothing hand-set: `nanopush plan`
    /// derives the campaign's plan from it), to reproduce one.
    #[arg(long)]
    scenes: bool,
}

/// Parses `I/N` with `I < N`.
pub(crate) fn parse_shard(s: &str) -> anyhow::Result<(u64, u64)> {
    let bad = || {
        anyhow::anyhow!(
            "--shard {}: expected I/N with 0 ≤ I < N ≤ 1000, e.g. 0/4",
            crate::units::echo(s)
        )
    };
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (u64, u64) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || n > 1000 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

/// Runs the random-scene campaign and reports it: the accepted share, `ok` within the
/// tolerance, the refusals by reason, the worst true error of an `ok`, and the cost.
pub fn run(a: &CampaignArgs) -> anyhow::Result<String> {
    let ranges = check(a)?;
    let shard = a.shard.as_deref().map(parse_shard).transpose()?.unwrap_or((0, 1));
    let seeds = shard_seeds(a.seed, a.random, shard.0, shard.1);
    // The output first: a bad --out is said before any work, the scenes are there to
    // reproduce while it runs, and each finished row is appended at once, so a kill keeps what
    // was done (the file is rewritten in seed order at the end).
    std::fs::create_dir_all(&a.out).map_err(|e| anyhow::anyhow!("creating {}: {e}", a.out.display()))?;
    if a.scenes {
        write_scenes(&a.out, &seeds, ranges, a.tolerance_nm)?;
    }
    let (cases, wall_time) = push_all(&a.out.join("random.csv"), &seeds, ranges, a.tolerance_nm * 1e-9)?;
    let done = Done {
        args: a,
        ranges,
        shard,
        seeds: seeds.len(),
        table: RandomTable::of(&cases),
        cases,
        wall_time,
    };
    if a.json {
        return json(&done);
    }
    let s = text(&done)?;
    if done.table.unsound > 0 {
        anyhow::bail!(
            "{s}the campaign found {} unsound scene(s) (UNSOUND above)",
            done.table.unsound
        );
    }
    Ok(s)
}

/// Checks the arguments against their ranges (before any work); returns the generator's ranges.
fn check(a: &CampaignArgs) -> anyhow::Result<Ranges> {
    let ranges = match a.ranges.as_str() {
        "lab" => Ranges::Lab,
        "validator" => Ranges::Validator,
        other => anyhow::bail!(
            "--ranges {}: unknown; allowed: lab, validator",
            crate::units::echo(other)
        ),
    };
    if !(1..=100_000).contains(&a.random) {
        anyhow::bail!("--random {} is out of range; allowed: [1, 100000] scenes", a.random);
    }
    crate::units::check_tolerance_nm(a.tolerance_nm)?;
    // The seeds run from --seed to --seed + N − 1: past the largest u64 they would wrap to 0.
    if a.seed.checked_add(a.random - 1).is_none() {
        anyhow::bail!(
            "--seed {} is out of range for --random {}; allowed: [0, {}] (the seeds run to --seed + N − 1)",
            a.seed,
            a.random,
            u64::MAX - (a.random - 1)
        );
    }
    Ok(ranges)
}

/// Writes each seed's scene as `OUT/scenes/seed-N.toml`.
fn write_scenes(out: &Path, seeds: &[u64], ranges: Ranges, tolerance_nm: f64) -> anyhow::Result<()> {
    let dir = out.join("scenes");
    std::fs::create_dir_all(&dir).map_err(|e| anyhow::anyhow!("creating {}: {e}", dir.display()))?;
    for &seed in seeds {
        let text = scene_text(&random_scene(seed, ranges), ranges, tolerance_nm)
            .map_err(|e| anyhow::anyhow!("writing the scene of seed {seed}: {e}"))?;
        crate::units::write_file(&dir.join(format!("seed-{seed}.toml")), &text)?;
    }
    Ok(())
}

/// The header of `random.csv`.
const HEADER: &str = "seed,outcome,refusal,true_error_nm,measured_error_nm,attempts,distance_um,simulated_s,wall_s,violations,advice,advice_outcome,reason,scene\n";

/// Pushes every seed's scene (in parallel), appending each row to `csv_path` as it is done,
/// then rewrites the file in seed order. Returns the cases and the wall time of the pushes (s).
fn push_all(csv_path: &Path, seeds: &[u64], ranges: Ranges, tolerance: f64) -> anyhow::Result<(Vec<RandomCase>, f64)> {
    crate::units::write_file(csv_path, HEADER)?;
    let rows = std::sync::Mutex::new(
        std::fs::OpenOptions::new()
            .append(true)
            .open(csv_path)
            .map_err(|e| anyhow::anyhow!("opening {}: {e}", csv_path.display()))?,
    );
    let start = std::time::Instant::now();
    let cases: Vec<RandomCase> = seeds
        .par_iter()
        .map(|&s| {
            let c = run_random(s, ranges, tolerance);
            if let Ok(mut f) = rows.lock() {
                use std::io::Write as _;
                // A row lost here is written with the others at the end.
                let _ = f.write_all(csv_row(&c).as_bytes());
            }
            c
        })
        .collect();
    let wall_time = start.elapsed().as_secs_f64();
    let mut csv = String::from(HEADER);
    for c in &cases {
        csv.push_str(&csv_row(c));
    }
    crate::units::write_file(csv_path, &csv)?;
    Ok((cases, wall_time))
}

/// A finished campaign, for its JSON and its text.
struct Done<'a> {
    args: &'a CampaignArgs,
    ranges: Ranges,
    /// `--shard I/N` (0/1 without it).
    shard: (u64, u64),
    /// Seeds run (this shard's).
    seeds: usize,
    table: RandomTable,
    cases: Vec<RandomCase>,
    /// Wall time of the pushes (s).
    wall_time: f64,
}

/// The `--json` object.
fn json(d: &Done) -> anyhow::Result<String> {
    let (a, t) = (d.args, &d.table);
    let v = serde_json::json!({
        "schema": "nanopush.random_campaign", "ranges": d.ranges.name(), "seeds": d.seeds, "first_seed": a.seed, "shard": [d.shard.0, d.shard.1],
        "tolerance": a.tolerance_nm * 1e-9, "accepted": t.accepted, "ok": t.ok, "refused": t.refused,
        "outcomes": t.outcomes, "refusals": t.refusals, "unsound": t.unsound,
        "worst_ok_true_error": t.worst_ok, "median_wall_time": t.median_wall, "p95_wall_time": t.p95_wall, "max_wall_time": t.max_wall,
        "advised": t.advised, "advice_ok": t.advice_ok, "advice_outcomes": t.advice_outcomes, "advice_failed": t.advice_failed,
        "wall_time": d.wall_time,
    });
    Ok(serde_json::to_string_pretty(&v)? + "\n")
}

/// The text report: the summary, the unsound scenes and the accepted ones not `ok`, and where
/// the rows went.
fn text(d: &Done) -> anyhow::Result<String> {
    let mut s = String::new();
    write_summary(&mut s, d)?;
    write_cases(&mut s, &d.cases)?;
    let a = d.args;
    writeln!(
        s,
        "Wrote {}/random.csv{}.",
        a.out.display(),
        if a.scenes {
            " and a scene file per seed under scenes/"
        } else {
            ""
        }
    )?;
    Ok(s)
}

/// The seeds, the accepted share, `ok` within the tolerance, the outcomes and refusals, the
/// worst true error of an `ok`, and the cost.
fn write_summary(s: &mut String, d: &Done) -> anyhow::Result<()> {
    let (a, t, (i, n)) = (d.args, &d.table, d.shard);
    let pct = |k: usize, of: usize| if of == 0 { 0.0 } else { 100.0 * k as f64 / of as f64 };
    writeln!(
        s,
        "Random valid scenes ({} ranges), seeds {}-{} (shard {i}/{n}: {} scenes), tolerance {} nm, {:.0} s on {} threads",
        d.ranges.name(),
        a.seed,
        a.seed + (a.random - 1),
        d.seeds,
        a.tolerance_nm,
        d.wall_time,
        rayon::current_num_threads()
    )?;
    writeln!(
        s,
        "  accepted by the plan {} ({:.0} %); of those ok within the tolerance {} ({:.1} %)",
        t.accepted,
        pct(t.accepted, d.seeds),
        t.ok,
        pct(t.ok, t.accepted)
    )?;
    writeln!(s, "  outcomes of the accepted: {}", counts_text(&t.outcomes))?;
    writeln!(s, "  refused {} by reason: {}", t.refused, counts_text(&t.refusals))?;
    writeln!(
        s,
        "  worst true error of an ok {}; unsound {}; wall time per scene median {:.2} s, p95 {:.2} s, max {:.2} s",
        if t.ok > 0 {
            format!("{:.2} nm", t.worst_ok * 1e9)
        } else {
            "- (no ok)".into()
        },
        t.unsound,
        t.median_wall,
        t.p95_wall,
        t.max_wall
    )?;
    writeln!(
        s,
        "  refusals naming a value the plan checked {}: with it applied, ok {} ({:.0} %), outcomes {}; refusals whose values all failed the check {}",
        t.advised,
        t.advice_ok,
        pct(t.advice_ok, t.advised),
        counts_text(&t.advice_outcomes),
        t.advice_failed
    )?;
    Ok(())
}

/// A line per unsound scene, then one per scene the plan accepted that did not end `ok`.
fn write_cases(s: &mut String, cases: &[RandomCase]) -> anyhow::Result<()> {
    for c in cases.iter().filter(|c| !c.judged.violations.is_empty()) {
        writeln!(
            s,
            "  UNSOUND seed {}: {} {:?}",
            c.seed, c.judged.outcome, c.judged.violations
        )?;
    }
    for (c, a) in cases
        .iter()
        .filter_map(|c| c.advice.as_ref().map(|a| (c, a)))
        .filter(|(_, a)| !a.judged.violations.is_empty())
    {
        writeln!(
            s,
            "  UNSOUND seed {} with {} = {}: {} {:?}",
            c.seed,
            a.key.field(),
            short(a.value),
            a.judged.outcome,
            a.judged.violations
        )?;
    }
    for c in cases
        .iter()
        .filter(|c| c.judged.refusal.is_none() && c.judged.outcome != "ok")
    {
        writeln!(
            s,
            "  seed {} {}: {} [{}]",
            c.seed,
            c.judged.outcome,
            c.judged.reason.chars().take(160).collect::<String>(),
            c.summary
        )?;
    }
    Ok(())
}

/// One scene's row of `random.csv`.
fn csv_row(c: &RandomCase) -> String {
    let j = &c.judged;
    format!(
        "{},{},{},{},{},{},{},{:.3},{:.3},{},{},{},{},{}\n",
        c.seed,
        j.outcome,
        j.refusal.as_deref().unwrap_or(""),
        j.true_error.map_or(String::new(), |e| format!("{:.2}", e * 1e9)),
        j.measured_error.map_or(String::new(), |e| format!("{:.2}", e * 1e9)),
        j.attempts,
        j.distance * 1e6,
        j.simulated,
        j.wall_time,
        j.violations.join("; ").replace(',', ";"),
        c.advice
            .as_ref()
            .map_or(String::new(), |a| format!("{} = {}", a.key.field(), short(a.value))),
        c.advice.as_ref().map_or(String::new(), |a| a.judged.outcome.clone()),
        j.reason.replace([',', '\n'], ";"),
        c.summary.replace(',', ";")
    )
}

fn counts_text(c: &[(String, usize)]) -> String {
    if c.is_empty() {
        return "none".into();
    }
    c.iter().map(|(k, n)| format!("{k} {n}")).collect::<Vec<_>>().join(", ")
}

/// The campaign's summary.
struct RandomTable {
    accepted: usize,
    ok: usize,
    refused: usize,
    outcomes: Vec<(String, usize)>,
    refusals: Vec<(String, usize)>,
    unsound: usize,
    worst_ok: f64,
    median_wall: f64,
    p95_wall: f64,
    max_wall: f64,
    /// Refusals that name a value the plan checked.
    advised: usize,
    /// Those whose move, with the value applied, ended `ok`.
    advice_ok: usize,
    /// Outcomes of the moves with the values applied.
    advice_outcomes: Vec<(String, usize)>,
    /// Refusals that named values none of which passed the plan's check.
    advice_failed: usize,
}

impl RandomTable {
    fn of(cases: &[RandomCase]) -> RandomTable {
        let count = |keys: Vec<String>| {
            let mut v: Vec<(String, usize)> = Vec::new();
            for k in keys {
                match v.iter_mut().find(|(o, _)| *o == k) {
                    Some((_, n)) => *n += 1,
                    None => v.push((k, 1)),
                }
            }
            v.sort_by_key(|c| std::cmp::Reverse(c.1));
            v
        };
        let accepted: Vec<_> = cases.iter().filter(|c| c.judged.refusal.is_none()).collect();
        let advised: Vec<_> = cases.iter().filter_map(|c| c.advice.as_ref()).collect();
        let mut walls: Vec<f64> = cases.iter().map(|c| c.judged.wall_time).collect();
        walls.sort_by(f64::total_cmp);
        RandomTable {
            accepted: accepted.len(),
            ok: accepted.iter().filter(|c| c.judged.outcome == "ok").count(),
            refused: cases.len() - accepted.len(),
            outcomes: count(accepted.iter().map(|c| c.judged.outcome.clone()).collect()),
            refusals: count(cases.iter().filter_map(|c| c.judged.refusal.clone()).collect()),
            unsound: cases
                .iter()
                .filter(|c| {
                    !c.judged.violations.is_empty()
                        || c.advice.as_ref().is_some_and(|a| !a.judged.violations.is_empty())
                })
                .count(),
            worst_ok: accepted
                .iter()
                .filter(|c| c.judged.outcome == "ok")
                .filter_map(|c| c.judged.true_error)
                .fold(0.0, f64::max),
            median_wall: walls.get(walls.len() / 2).copied().unwrap_or(0.0),
            p95_wall: walls.get(walls.len() * 95 / 100).copied().unwrap_or(0.0),
            advised: advised.len(),
            advice_ok: advised.iter().filter(|a| a.judged.outcome == "ok").count(),
            advice_outcomes: count(
                advised
                    .iter()
                    .map(|a| match &a.judged.refusal {
                        Some(code) => format!("refused {code}"),
                        None => a.judged.outcome.clone(),
                    })
                    .collect(),
            ),
            advice_failed: cases
                .iter()
                .filter(|c| c.advice.is_none() && c.judged.advice.iter().any(|a| a.checked == Some(false)))
                .count(),
            max_wall: walls.last().copied().unwrap_or(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    /// The seeds run from `--seed` to `--seed + N − 1`: a first seed so large that they would pass
    /// the largest u64 (and wrap to 0) is refused, with the range that fits.
    #[test]
    fn seeds_past_the_largest_are_refused_not_wrapped() {
        let crate::Command::Campaign(a) =
            crate::parse(&["campaign", "--random", "2", "--seed", "18446744073709551615"])
        else {
            panic!("a campaign")
        };
        let e = super::run(&a).unwrap_err().to_string();
        assert_eq!(
            e,
            "--seed 18446744073709551615 is out of range for --random 2; allowed: [0, 18446744073709551614] (the seeds run to --seed + N − 1)"
        );
    }
}
