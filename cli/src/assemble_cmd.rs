//! `nanopush assemble`: particles pushed into a pattern (`nanopush_instrument::assembly`), with
//! progress on stderr, the report on stdout, and in `--out DIR`: `summary.json`, `plan.png`
//! (the assignment and the routes over the first full frame), `final.gsf` and `final.png`.

mod campaign;
mod picture;

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use nanopush_instrument::afm::Afm;
use nanopush_instrument::assembly::summary::Totals;
use nanopush_instrument::assembly::{
    AssemblyOptions, AssemblyRun, Event, MoveRecord, Outcome, Pattern, Purpose, assemble,
};
use nanopush_instrument::scan::{write_gsf, write_png};
use nanopush_proto::assembly::AssemblySummary;

/// Exit status of an assembly that ran and left a site open (or was stopped).
pub const EXIT_INCOMPLETE: u8 = 1;
/// Exit status of an assembly refused before anything moved.
pub const EXIT_REFUSED: u8 = 2;

/// Arguments of `nanopush assemble`.
#[derive(clap::Args, Debug)]
pub struct AssembleArgs {
    /// Scene file (TOML); default: the embedded paper scene. `scenes/assembly-latex.toml` has
    /// twenty particles to assemble with.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// The pattern: a TOML file of `[[site]]` entries, or a generator: `line:n=5,spacing_um=4`,
    /// `grid:rows=3,cols=3,spacing_um=4`, `ring:n=8,radius_um=6`, `text:NP,pitch_um=3` (each
    /// takes `angle_deg`, `tolerance_nm`, `radius_nm` too).
    #[arg(long, required_unless_present = "random")]
    pattern: Option<String>,
    /// Where the pattern's centre goes (µm): a generator's centre, or a file's sites moved so that
    /// their mean lands there. Default: a generator at the stage's centre, a file where it is.
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
    at_um: Option<String>,
    /// A site's tolerance when the pattern gives none (nm), in [1, 100000].
    #[arg(long, value_name = "NM", default_value_t = nanopush_proto::push::TOLERANCE_NM, allow_hyphen_values = true)]
    tolerance_nm: f64,
    /// Pushes a move may make (the first and its corrections), in [1, 10].
    #[arg(long, default_value_t = 3, allow_hyphen_values = true, value_parser = crate::units::attempts_arg)]
    attempts: i64,
    /// Where the summary, the plan's picture and the last frame go.
    #[arg(long, default_value = "assembly-out")]
    out: PathBuf,
    /// Print the summary as JSON instead of the text.
    #[arg(long)]
    json: bool,
    /// Instead of one assembly: N random layouts and patterns nobody tuned (seeds `--seed` …
    /// `--seed + N − 1`), in [1, 100000], each checked against the truth; `OUT/random-assemblies.csv`.
    #[arg(long, value_name = "N", conflicts_with_all = ["pattern", "scene", "at_um"], value_parser = crate::units::scenes_arg)]
    random: Option<u64>,
    /// The first seed of `--random`.
    #[arg(long, default_value_t = 0, requires = "random", value_parser = crate::units::seed_arg)]
    seed: u64,
    /// Run only shard I of N of `--random`'s seeds (every N-th from the I-th), e.g. `--shard 0/4`.
    #[arg(long, value_name = "I/N", requires = "random")]
    shard: Option<String>,
}

/// The pattern `--pattern` names, placed by `--at-um`.
fn pattern(a: &AssembleArgs, spec: &str, range: f64) -> anyhow::Result<Pattern> {
    let at = a
        .at_um
        .as_deref()
        .map(|s| crate::units::parse_point_um("--at-um", s, "--at-um 50,50"))
        .transpose()?
        .map(|(x, y)| (x * 1e-6, y * 1e-6));
    let path = std::path::Path::new(spec);
    // A generator always has a `:`; without one, a path (`dir/sites`, `/tmp`) is a file to
    // read, so a missing one is named as missing rather than as an unknown shape.
    let names_a_file = !spec.contains(':') && (spec.contains('/') || spec.contains(std::path::MAIN_SEPARATOR));
    if spec.ends_with(".toml") || path.is_file() || names_a_file {
        let p = Pattern::from_path(path)?;
        Ok(match at {
            Some(to) => {
                let c = p.centre();
                p.shifted((to.0 - c.0, to.1 - c.1))
            }
            None => p,
        })
    } else {
        Ok(Pattern::generate(spec, at.unwrap_or((range / 2.0, range / 2.0)))?)
    }
}

/// Runs `nanopush assemble`: the report, and the exit status (0 filled, 1 a site open or
/// stopped, 2 refused before anything moved).
pub fn run(a: &AssembleArgs) -> anyhow::Result<(String, u8)> {
    if let Some(n) = a.random {
        if !(1..=100_000).contains(&n) {
            anyhow::bail!("--random {n} is out of range; allowed: [1, 100000] cases");
        }
        if a.seed.checked_add(n - 1).is_none() {
            anyhow::bail!(
                "--seed {} is out of range for --random {n}; allowed: [0, {}] (the seeds run to --seed + N − 1)",
                a.seed,
                u64::MAX - (n - 1)
            );
        }
        let (i, of) = a
            .shard
            .as_deref()
            .map(crate::campaign_cmd::parse_shard)
            .transpose()?
            .unwrap_or((0, 1));
        let seeds: Vec<u64> = (0..n).filter(|k| k % of == i).map(|k| a.seed + k).collect();
        return Ok((campaign::run(&seeds, &a.out, a.json)?, 0));
    }
    let spec = a
        .pattern
        .as_deref()
        .context("--pattern FILE|SPEC is needed (or --random N)")?;
    crate::units::check_tolerance_nm(a.tolerance_nm)?;
    let attempts = u32::try_from(a.attempts)
        .ok()
        .filter(|n| (1..=10).contains(n))
        .with_context(|| format!("--attempts {} is out of range; allowed: [1, 10]", a.attempts))?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let range = scene.file.stage.range_um * 1e-6;
    let pattern = pattern(a, spec, range)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let options = AssemblyOptions {
        tolerance: a.tolerance_nm * 1e-9,
        attempts,
        ..AssemblyOptions::default()
    };
    // The tip starts at a corner of the stage, at the start height.
    let mut afm = Afm::from_scene(&scene, 0.0, 0.0, 1e-3);
    let run = assemble(&scene, &mut afm, &pattern, &options, &mut progress, &|| false);
    write_outputs(a, &pattern, &run)?;
    let summary = summary(&pattern, &run);
    let code = match run.outcome {
        Outcome::Filled => 0,
        Outcome::Refused => EXIT_REFUSED,
        Outcome::Incomplete | Outcome::Stopped => EXIT_INCOMPLETE,
    };
    let text = if a.json {
        serde_json::to_string_pretty(&summary)? + "\n"
    } else {
        text(&summary, &a.out)?
    };
    Ok((text, code))
}

/// A line on stderr for each step, as the assembly goes.
fn progress(e: Event) {
    match e {
        Event::Planned { plan, map } => eprintln!(
            "planned: {} particles found, {} of {} sites fillable, {} moves",
            map.len(),
            plan.fillable(),
            plan.sites.len(),
            plan.moves.len()
        ),
        Event::MoveStarted { number, of, planned } => eprintln!(
            "move {number} of {of}: {} from ({:.2}, {:.2}) to ({:.2}, {:.2}) µm, {} leg{}",
            purpose_words(planned.purpose),
            planned.from.0 * 1e6,
            planned.from.1 * 1e6,
            planned.to.0 * 1e6,
            planned.to.1 * 1e6,
            planned.legs.len(),
            if planned.legs.len() == 1 { "" } else { "s" }
        ),
        Event::MoveEnded { record, .. } => eprintln!("  {}", record_words(record)),
        Event::SiteFilled { site } => eprintln!("  site {site} filled"),
        Event::Replanned { plan, .. } => eprintln!("  planned again: {} moves left", plan.moves.len()),
    }
}

fn purpose_words(p: Purpose) -> String {
    match p {
        Purpose::Fill { site } => format!("fill site {site}"),
        Purpose::Clear => "clear a particle out of the way".into(),
        Purpose::Park => "park a particle for later".into(),
    }
}

fn record_words(r: &MoveRecord) -> String {
    format!(
        "{}{} ({} push{}, {:.1} s)",
        r.outcome,
        r.error
            .map_or(String::new(), |e| format!(": {:.1} nm from the target", e * 1e9)),
        r.pushes,
        if r.pushes == 1 { "" } else { "es" },
        r.push_time
    )
}

/// The report as the proto document.
fn summary(pattern: &Pattern, run: &AssemblyRun) -> AssemblySummary {
    nanopush_instrument::assembly::summary::summary(
        pattern,
        run.outcome.code(),
        run.refusal.clone(),
        &run.sites,
        &run.moves,
        Totals {
            wall_time: run.wall_time,
            push_time: run.push_time,
            scan_time: run.scan_time,
            violations: run.violations.clone(),
        },
    )
}

/// `summary.json`, `plan.png`, `final.gsf` and `final.png` in `--out`.
fn write_outputs(a: &AssembleArgs, pattern: &Pattern, run: &AssemblyRun) -> anyhow::Result<()> {
    let summary = summary(pattern, run);
    crate::units::write_file(
        &a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)? + "\n",
    )?;
    let (first, map, plan) = &run.first;
    crate::units::write_file(&a.out.join("plan.png"), picture::plan_png(first, map, pattern, plan)?)?;
    if let Some(last) = &run.last {
        let mut gsf = Vec::new();
        write_gsf(
            &mut gsf,
            last,
            &format!("assembly of {}: the last full frame", pattern.name),
        )?;
        crate::units::write_file(&a.out.join("final.gsf"), &gsf)?;
        let mut png = Vec::new();
        write_png(&mut png, last)?;
        crate::units::write_file(&a.out.join("final.png"), &png)?;
    }
    Ok(())
}

/// The report in words.
fn text(s: &AssemblySummary, out: &std::path::Path) -> anyhow::Result<String> {
    let mut t = String::new();
    let filled = s.sites.iter().filter(|x| x.status == "filled").count();
    writeln!(
        t,
        "{}: {filled} of {} sites filled ({})",
        s.outcome,
        s.sites.len(),
        s.pattern
    )?;
    if let Some(r) = &s.refusal {
        writeln!(t, "  refused: {r}")?;
    }
    for (i, site) in s.sites.iter().enumerate() {
        let particle = site.particle.map_or("-".to_string(), |p| format!("particle {p}"));
        let error = site
            .error
            .map_or(String::new(), |e| format!(", {:.1} nm from it (true)", e * 1e9));
        writeln!(
            t,
            "  site {i} ({:.2}, {:.2}) µm: {} {particle}{error}{}",
            site.target[0] * 1e6,
            site.target[1] * 1e6,
            site.status,
            site.reason.as_ref().map_or(String::new(), |r| format!(": {r}"))
        )?;
    }
    let simulated = s.push_time + s.scan_time;
    writeln!(
        t,
        "  {} moves; wall time {:.1} s for {:.1} s simulated ({:.1} s of pushes, {:.1} s of scans at the scene's line rate)",
        s.moves.len(),
        s.wall_time,
        simulated,
        s.push_time,
        s.scan_time
    )?;
    for v in &s.violations {
        writeln!(t, "  VIOLATION: {v}")?;
    }
    writeln!(
        t,
        "Wrote {0}/summary.json, {0}/plan.png, {0}/final.gsf and {0}/final.png.",
        out.display()
    )?;
    Ok(t)
}
