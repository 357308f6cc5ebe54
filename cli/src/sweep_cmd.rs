//! `nanopush sweep`: Figs 10-13, the settled particle `y` and `ζ_z` against one parameter.

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nanopush_instrument::scene::Scene;
use nanopush_proto::sweep::{FailedPoint, SeriesSummary, SweepReport};
use nanopush_study::sweep::{Param, PointOptions, Shard, SweepPoint, compute_point, csv_header, csv_row, grid_value};
use rayon::prelude::*;

use crate::plot::{Mark, Panel, Series, stacked};
use crate::units::eng;

/// Arguments of `nanopush sweep`.
#[derive(Args, Debug)]
pub struct SweepArgs {
    /// Parameter: alpha (tilt, deg, Fig 10), beta (contact angle, deg, Fig 11), mu_as
    /// (particle-substrate static friction, Fig 12), radius (particle radius, nm, Fig 13).
    #[arg(long)]
    param: String,
    /// First value, in the parameter's unit.
    #[arg(long)]
    from: f64,
    /// Last value (included), at least --from.
    #[arg(long)]
    to: f64,
    /// Number of points, evenly spaced, in [1, 100000].
    #[arg(long)]
    steps: usize,
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Compute only shard i of n (contiguous blocks of the points, i from 0): the shards' CSVs
    /// concatenated in order are the whole sweep's CSV (only shard 0 writes the header).
    #[arg(long, default_value = "0/1")]
    shard: String,
    /// Write `sweep-<param>.csv` (and, unsharded, `sweep-<param>.svg`) into this directory; a
    /// shard writes `sweep-<param>.shard-<i>-of-<n>.csv`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Simulated push per point (s), in (0, 100]: long enough to shear and settle.
    #[arg(long, default_value_t = 0.2)]
    duration: f64,
    /// Trace sample interval (s), in [1e-6, duration/8].
    #[arg(long, default_value_t = 1e-3)]
    sample: f64,
    /// Fraction of the push, at its end, whose mean is the settled value, in (0, 1].
    #[arg(long, default_value_t = 0.25)]
    tail: f64,
    /// Turn the particle's rotation off (it can only stick or slide, as Eq 18 assumes).
    #[arg(long)]
    pure_sliding: bool,
    /// Integration method: rodas4, rodas5p, trbdf2 or implicit-euler.
    #[arg(long, default_value = "rodas4")]
    method: String,
    /// Relative tolerance, in [1e-12, 1e-1].
    #[arg(long, default_value_t = 1e-6)]
    rtol: f64,
    /// Print one JSON summary (SI lengths) instead of a table.
    #[arg(long)]
    json: bool,
}

fn check(a: &SweepArgs) -> anyhow::Result<(Param, Shard, PointOptions)> {
    let param = Param::parse(&a.param)?;
    param.check_bounds(a.from, a.to, a.steps)?;
    let shard = Shard::parse(&a.shard)?;
    let method = crate::units::parse_method(&a.method)?;
    if !(a.duration.is_finite() && a.duration > 0.0 && a.duration <= 100.0) {
        bail!("--duration {} s is out of range; allowed: (0, 100] s", a.duration);
    }
    if !(a.sample.is_finite() && a.sample >= 1e-6 && a.sample <= a.duration / 8.0) {
        bail!(
            "--sample {} s is out of range; allowed: [1e-6, duration/8 = {}] s",
            a.sample,
            a.duration / 8.0
        );
    }
    if !(a.tail.is_finite() && a.tail > 0.0 && a.tail <= 1.0) {
        bail!("--tail {} is out of range; allowed: (0, 1]", a.tail);
    }
    if !(a.rtol.is_finite() && (1e-12..=1e-1).contains(&a.rtol)) {
        bail!("--rtol {} is out of range; allowed: [1e-12, 1e-1]", a.rtol);
    }
    let opts = PointOptions {
        duration: a.duration,
        sample: a.sample,
        tail: a.tail,
        method,
        rtol: a.rtol,
        pure_sliding: a.pure_sliding,
    };
    Ok((param, shard, opts))
}

/// Progress on stderr: a bar on a terminal, a plain line per tenth when piped (no escape codes).
struct Progress {
    bar: Option<ProgressBar>,
    done: AtomicUsize,
    total: usize,
    label: String,
}

impl Progress {
    fn new(total: usize, label: String) -> Progress {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::with_draw_target(Some(total as u64), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} points, {elapsed} (eta {eta})")
                    .expect("a valid template")
                    .progress_chars("=> "),
            );
            bar.set_prefix(label.clone());
            bar
        });
        Progress {
            bar,
            done: AtomicUsize::new(0),
            total,
            label,
        }
    }

    fn tick(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        match &self.bar {
            Some(bar) => bar.inc(1),
            None => {
                let tenth = |k: usize| k * 10 / self.total.max(1);
                if tenth(done) != tenth(done - 1) {
                    eprintln!("{}: {done}/{} points", self.label, self.total);
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

fn summary(points: &[&SweepPoint], pick: impl Fn(&SweepPoint) -> Option<(f64, f64)>) -> SeriesSummary {
    let vals: Vec<(f64, f64, f64)> = points
        .iter()
        .filter_map(|p| pick(p).map(|(y, z)| (p.value, y, z)))
        .collect();
    let fold = |f: fn(f64, f64) -> f64, k: fn(&(f64, f64, f64)) -> f64| vals.iter().map(k).reduce(f);
    SeriesSummary {
        points: vals.len(),
        y_min: fold(f64::min, |v| v.1),
        y_max: fold(f64::max, |v| v.1),
        y_argmin: vals.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|v| v.0),
        zeta_z_min: fold(f64::min, |v| v.2),
        zeta_z_max: fold(f64::max, |v| v.2),
    }
}

fn plot(path: &Path, param: Param, scene: &str, pure_sliding: bool, points: &[SweepPoint]) -> anyhow::Result<()> {
    let nm = 1e9;
    let unit = match param.unit() {
        "" => String::new(),
        u => format!(" ({u})"),
    };
    let eq18: Vec<(f64, f64, f64)> = points
        .iter()
        .filter_map(|p| p.eq18_ok().map(|s| (p.value, s.y * nm, s.zeta_z * nm)))
        .collect();
    let dynamic: Vec<(&SweepPoint, &nanopush_study::sweep::Settled)> = points
        .iter()
        .filter_map(|p| p.dynamic.as_ref().ok().filter(|d| !d.stuck).map(|d| (p, d)))
        .collect();
    let model = if pure_sliding {
        "Eq 17, no rotation"
    } else {
        "Eq 17, free rotation"
    };
    let panel = |name: &str,
                 mark: Mark,
                 eq: fn(&(f64, f64, f64)) -> f64,
                 get: fn(&nanopush_study::sweep::Settled) -> nanopush_study::sweep::TailStats| Panel {
        y_desc: format!("{name} (nm)"),
        series: vec![
            Series {
                label: format!("{name}, Eq 18 (pure sliding)"),
                points: eq18.iter().map(|v| (v.0, eq(v))).collect(),
                mark: Mark::Line,
                color: 0,
                bars: Vec::new(),
            },
            Series {
                label: format!("{name}, {model}, settled mean"),
                points: dynamic.iter().map(|(p, d)| (p.value, get(d).mean * nm)).collect(),
                mark,
                color: 1,
                bars: Vec::new(),
            },
            Series {
                label: "unstable: tail min-max".into(),
                points: dynamic
                    .iter()
                    .filter(|(_, d)| d.unstable)
                    .map(|(p, d)| (p.value, get(d).mean * nm))
                    .collect(),
                mark,
                color: 3,
                bars: dynamic
                    .iter()
                    .filter(|(_, d)| d.unstable)
                    .map(|(p, d)| (p.value, get(d).min * nm, get(d).max * nm))
                    .collect(),
            },
        ],
    };
    let panels = [
        panel("y", Mark::Circle, |v| v.1, |d| d.y),
        panel("ζ_z", Mark::Cross, |v| v.2, |d| d.zeta_z),
    ];
    stacked(
        path,
        &format!(
            "Fig {}: settled y ('o') and ζ_z ('x') against {} — {scene}",
            param.figure(),
            param.symbol()
        ),
        &format!("{}{unit}", param.symbol()),
        &panels,
    )
}

/// The points of one shard of a sweep, with what they are of.
struct Computed {
    param: Param,
    shard: Shard,
    first_index: usize,
    points: Vec<SweepPoint>,
}

/// Runs `nanopush sweep`; returns what to print on stdout.
pub fn run(a: &SweepArgs) -> anyhow::Result<String> {
    let started = Instant::now();
    let (param, shard, opts) = check(a)?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let c = compute(a, &scene, param, shard, &opts)?;
    let csv = csv_text(&c);
    let files = write_files(a, &scene, &c, &csv)?;
    let report = build_report(a, &scene, &c, files, started);
    let mut out = String::new();
    if a.json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
        return Ok(out);
    }
    if a.out.is_none() {
        // No directory: the CSV is the output, so it can be piped or redirected.
        return Ok(csv);
    }
    summary_text(param, &report)
}

/// Checks the ends against the scene, creates `--out`, then computes the shard's points in
/// parallel with progress on stderr.
fn compute(a: &SweepArgs, scene: &Scene, param: Param, shard: Shard, opts: &PointOptions) -> anyhow::Result<Computed> {
    // Fail on a value the scene does not allow before spending time on the others.
    param
        .apply(scene, a.from)
        .and_then(|_| param.apply(scene, a.to))
        .with_context(|| format!("--param {} from {} to {}", param.name(), a.from, a.to))?;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let range = shard.range(a.steps);
    let label = format!("sweep {} (shard {}/{})", param.name(), shard.index, shard.count);
    let progress = Progress::new(range.len(), label);
    let points: Vec<SweepPoint> = range
        .clone()
        .into_par_iter()
        .map(|i| {
            let p = compute_point(scene, param, i, grid_value(a.from, a.to, a.steps, i), opts);
            progress.tick();
            p
        })
        .collect();
    progress.finish();
    Ok(Computed {
        param,
        shard,
        first_index: range.start,
        points,
    })
}

/// The shard's CSV: the header on shard 0 only, then a row per point.
fn csv_text(c: &Computed) -> String {
    let mut csv = if c.shard.index == 0 {
        csv_header(c.param)
    } else {
        String::new()
    };
    for p in &c.points {
        csv.push_str(&csv_row(p));
    }
    csv
}

/// With `--out`, writes the CSV and, unsharded, the SVG; returns their paths.
fn write_files(
    a: &SweepArgs,
    scene: &Scene,
    c: &Computed,
    csv: &str,
) -> anyhow::Result<(Option<String>, Option<String>)> {
    let (param, shard) = (c.param, c.shard);
    let (mut csv_path, mut svg_path) = (None, None);
    if let Some(dir) = &a.out {
        let path = if shard.count == 1 {
            dir.join(format!("sweep-{}.csv", param.name()))
        } else {
            dir.join(format!(
                "sweep-{}.shard-{}-of-{}.csv",
                param.name(),
                shard.index,
                shard.count
            ))
        };
        crate::units::write_file(&path, csv)?;
        csv_path = Some(path.display().to_string());
        if shard.count == 1 {
            let svg = dir.join(format!("sweep-{}.svg", param.name()));
            plot(&svg, param, &scene.file.name, a.pure_sliding, &c.points)
                .with_context(|| format!("drawing {}", svg.display()))?;
            svg_path = Some(svg.display().to_string());
        }
    }
    Ok((csv_path, svg_path))
}

/// The summary of the shard (`--json` prints it whole), its wall time measured from `started`.
fn build_report(
    a: &SweepArgs,
    scene: &Scene,
    c: &Computed,
    (csv_path, svg_path): (Option<String>, Option<String>),
    started: Instant,
) -> SweepReport {
    let (param, shard, points) = (c.param, c.shard, &c.points);
    let all: Vec<&SweepPoint> = points.iter().collect();
    let values =
        |f: &dyn Fn(&SweepPoint) -> bool| -> Vec<f64> { points.iter().filter(|p| f(p)).map(|p| p.value).collect() };
    SweepReport {
        schema: "nanopush.sweep".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        param: param.name().into(),
        unit: param.unit().into(),
        figure: param.figure(),
        from: a.from,
        to: a.to,
        steps: a.steps,
        shard: shard.index,
        shards: shard.count,
        first_index: c.first_index,
        points: points.len(),
        pure_sliding: a.pure_sliding,
        eq18: summary(&all, |p| p.eq18_ok().map(|s| (s.y, s.zeta_z))),
        dynamic: summary(&all, |p| {
            p.dynamic
                .as_ref()
                .ok()
                .filter(|d| !d.stuck)
                .map(|d| (d.y.mean, d.zeta_z.mean))
        }),
        unstable: values(&|p| p.dynamic.as_ref().is_ok_and(|d| d.unstable)),
        stuck: values(&|p| p.dynamic.as_ref().is_ok_and(|d| d.stuck)),
        eq18_missing: values(&|p| p.eq18_note().is_some()),
        failed: points
            .iter()
            .filter_map(|p| {
                p.dynamic.as_ref().err().map(|e| FailedPoint {
                    index: p.index,
                    value: p.value,
                    error: e.clone(),
                })
            })
            .collect(),
        wall_time: started.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
        csv: csv_path,
        svg: svg_path,
    }
}

/// The table printed with `--out` and without `--json`.
fn summary_text(param: Param, r: &SweepReport) -> anyhow::Result<String> {
    let mut out = String::new();
    let u = if r.unit.is_empty() { "" } else { r.unit.as_str() };
    writeln!(
        out,
        "Fig {}: sweep of {} from {} to {} {u} in {} points (shard {}/{}: {} points from index {}) on scene \"{}\"",
        r.figure,
        param.symbol(),
        r.from,
        r.to,
        r.steps,
        r.shard,
        r.shards,
        r.points,
        r.first_index,
        r.scene
    )?;
    for (name, s) in [
        ("Eq 18 (pure sliding)", &r.eq18),
        ("dynamic model, settled", &r.dynamic),
    ] {
        let opt = |v: Option<f64>| v.map_or("-".into(), |v| eng(v, "m"));
        writeln!(
            out,
            "  {name:<24} {} points: y in [{}, {}] (min at {} = {}), ζ_z in [{}, {}]",
            s.points,
            opt(s.y_min),
            opt(s.y_max),
            param.symbol(),
            s.y_argmin.map_or("-".into(), |v| format!("{v} {u}")),
            opt(s.zeta_z_min),
            opt(s.zeta_z_max)
        )?;
    }
    let list = |v: &[f64]| {
        if v.is_empty() {
            "none".to_string()
        } else {
            v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ")
        }
    };
    writeln!(out, "  unstable (stick-slip or wide tail): {}", list(&r.unstable))?;
    writeln!(out, "  stuck (never sheared): {}", list(&r.stuck))?;
    writeln!(out, "  no Eq 18 steady state: {}", list(&r.eq18_missing))?;
    for f in &r.failed {
        writeln!(out, "  failed at {} = {}: {}", param.name(), f.value, f.error)?;
    }
    writeln!(out, "  wall time {} on {} threads", eng(r.wall_time, "s"), r.threads)?;
    for path in [&r.csv, &r.svg].into_iter().flatten() {
        writeln!(out, "  wrote {path}")?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Command;

    fn parse(args: &[&str]) -> SweepArgs {
        let Command::Sweep(a) = crate::parse(args) else {
            unreachable!("`sweep` parses as Sweep")
        };
        a
    }

    /// docs/model.md, "The paper's figures": `nanopush sweep` integrates each point for
    /// `--duration` 0.2 s at 1 ms samples and averages over the last quarter, Rodas4 at rtol 1e-6,
    /// the whole sweep as one shard: the [`PointOptions::default`] that the Figs 10-13 tests pin
    /// their figures on, with the rotation on unless `--pure-sliding`.
    #[test]
    fn sweep_defaults_are_the_point_options_the_figures_pin() {
        let args = ["sweep", "--param", "beta", "--from", "5", "--to", "65", "--steps", "31"];
        let a = parse(&args);
        let (param, shard, opts) = check(&a).unwrap();
        assert_eq!(param, Param::Beta);
        assert_eq!(shard, Shard::parse("0/1").unwrap());
        assert_eq!(opts, PointOptions::default());
        assert_eq!(
            (
                opts.duration,
                opts.sample,
                opts.tail,
                opts.method,
                opts.rtol,
                opts.pure_sliding
            ),
            (
                0.2,
                1e-3,
                0.25,
                nanopush_instrument::numerics::integrate::Method::Rodas4,
                1e-6,
                false
            )
        );
        let with: Vec<&str> = args.into_iter().chain(["--pure-sliding"]).collect();
        let a = parse(&with);
        let (_, _, opts) = check(&a).unwrap();
        assert_eq!(
            opts,
            PointOptions {
                pure_sliding: true,
                ..PointOptions::default()
            }
        );
    }
}
