//! `nanopush simulate`.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::PushModel;
use nanopush_instrument::physics::pushing::trace::{PushRun, run_push};
use nanopush_proto::simulate::SimulateReport;

use crate::units::eng;

/// Arguments of `nanopush simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulated time (s), in (0, 100].
    #[arg(long, default_value_t = 0.05)]
    duration: f64,
    /// Integration method: rodas4, rodas5p, trbdf2 or implicit-euler.
    #[arg(long, default_value = "rodas4")]
    method: String,
    /// Relative tolerance, in [1e-12, 1e-1].
    #[arg(long, default_value_t = 1e-6)]
    rtol: f64,
    /// Trace sample interval (s), in [1e-7, duration].
    #[arg(long, default_value_t = 1e-4)]
    sample: f64,
    /// Write the trace (CSV) here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Draw Fig 7 here (SVG): stage travel and particle y against time, and the particle's
    /// offset behind the stage settling.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print one JSON object (SI units) instead of a table.
    #[arg(long)]
    json: bool,
}

fn check(a: &SimulateArgs) -> anyhow::Result<Method> {
    let method = crate::units::parse_method(&a.method)?;
    if !(a.duration.is_finite() && a.duration > 0.0 && a.duration <= 100.0) {
        bail!("--duration {} s is out of range; allowed: (0, 100] s", a.duration);
    }
    if !(a.rtol.is_finite() && (1e-12..=1e-1).contains(&a.rtol)) {
        bail!("--rtol {} is out of range; allowed: [1e-12, 1e-1]", a.rtol);
    }
    if !(a.sample.is_finite() && a.sample >= 1e-7 && a.sample <= a.duration) {
        bail!(
            "--sample {} s is out of range; allowed: [1e-7, duration = {}] s",
            a.sample,
            a.duration
        );
    }
    if a.duration / a.sample > 2e6 {
        bail!(
            "--duration/--sample = {:.0} trace rows; allowed: at most 2000000",
            a.duration / a.sample
        );
    }
    Ok(method)
}

/// Writes the trace CSV (atomically: see [`crate::units::write_file`]).
fn write_trace(path: &std::path::Path, run: &PushRun) -> anyhow::Result<()> {
    let mut w = String::from(
        "t_s,stage_y_m,particle_y_m,particle_z_m,theta_rad,zeta_y_m,zeta_z_m,normal_ta_n,friction_ta_n,load_as_n,friction_as_n,phase\n",
    );
    for r in &run.trace {
        writeln!(
            w,
            "{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{}",
            r.t,
            r.stage_y,
            r.particle_y,
            r.particle_z,
            r.theta,
            r.zeta_y,
            r.zeta_z,
            r.normal_ta,
            r.friction_ta,
            r.load_as,
            r.friction_as,
            r.phase
        )?;
    }
    crate::units::write_file(path, w)
}

/// Fig 7: the settling of the particle's y during pushing.
fn plot_settling(path: &std::path::Path, scene: &str, run: &PushRun) -> anyhow::Result<()> {
    use crate::plot::{Mark, Panel, Series, stacked};
    let series = |label: &str, color, f: fn(&nanopush_instrument::physics::pushing::trace::TraceRow) -> f64| Series {
        label: label.into(),
        points: run.trace.iter().map(|r| (r.t * 1e3, f(r) * 1e9)).collect(),
        mark: Mark::Line,
        color,
        bars: Vec::new(),
    };
    let panels = [
        Panel {
            y_desc: "travel (nm)".into(),
            series: vec![
                series("stage s", 0, |r| r.stage_y),
                series("particle y", 1, |r| r.particle_y),
            ],
        },
        Panel {
            y_desc: "s − particle y (nm)".into(),
            series: vec![series("particle offset behind the stage", 2, |r| {
                r.stage_y - r.particle_y
            })],
        },
    ];
    stacked(
        path,
        &format!("Fig 7: settling of the particle's y during pushing — {scene}"),
        "t (ms)",
        &panels,
    )
}

/// Runs `nanopush simulate`; returns what to print on stdout.
pub fn run(a: &SimulateArgs) -> anyhow::Result<String> {
    let method = check(a)?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let model = PushModel::new(scene.push_params());
    let speed = model.p.speed;
    let run = run_push(model.clone(), method, Options::with_rtol(a.rtol), a.duration, a.sample)
        .context("simulating the push")?;
    // The estimated global error: a rerun at a hundredth of the tolerance (not below 1e-12,
    // where double precision runs out), with the same sampling.
    let fine = run_push(
        model,
        method,
        Options::with_rtol((a.rtol * 1e-2).max(1e-12)),
        a.duration,
        a.sample,
    )
    .ok();
    if let Some(path) = &a.out {
        write_trace(path, &run)?;
    }
    if let Some(path) = &a.plot {
        plot_settling(path, &scene.file.name, &run).with_context(|| format!("drawing {}", path.display()))?;
    }
    let st = &run.stats;
    let report = SimulateReport {
        schema: "nanopush.simulate".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        method: method.name().into(),
        rtol: a.rtol,
        duration: a.duration,
        speed,
        final_particle_y: run.final_particle_y(),
        final_stage: run.trace.last().map_or(0.0, |r| r.stage_y),
        steady_zeta_z: run.steady_zeta_z(),
        shearing_time: run.shearing_time,
        final_phase: run.final_phase.into(),
        steps: st.steps,
        rejected: st.rejected,
        jacobians: st.jac_evals,
        factorizations: st.factorizations,
        events: st.events,
        estimated_error_y: fine
            .as_ref()
            .map(|f| (run.final_particle_y() - f.final_particle_y()).abs()),
        estimated_error_zeta_z: fine.as_ref().map(|f| (run.final_zeta_z() - f.final_zeta_z()).abs()),
        wall_time: st.wall_time,
        real_time_factor: a.duration / st.wall_time.max(1e-12),
        trace_rows: if a.out.is_some() { run.trace.len() } else { 0 },
    };
    let mut out = String::new();
    if a.json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
        return Ok(out);
    }
    let r = &report;
    writeln!(
        out,
        "Push in scene \"{}\": {} at V = {}, {} with rtol {:e}",
        r.scene,
        eng(r.duration, "s"),
        eng(r.speed, "m/s"),
        r.method,
        r.rtol
    )?;
    let rows: Vec<(&str, String)> = vec![
        ("final particle y", eng(r.final_particle_y, "m")),
        ("final stage travel", eng(r.final_stage, "m")),
        ("steady ζ_z (last 20 %)", eng(r.steady_zeta_z, "m")),
        (
            "shearing time t*",
            r.shearing_time.map_or("never sheared".into(), |t| eng(t, "s")),
        ),
        ("final phase", r.final_phase.clone()),
        ("steps / rejected", format!("{} / {}", r.steps, r.rejected)),
        ("Jacobians / LUs", format!("{} / {}", r.jacobians, r.factorizations)),
        ("mode switches", r.events.to_string()),
        (
            "est. global error y",
            r.estimated_error_y.map_or("unavailable".into(), |e| eng(e, "m")),
        ),
        (
            "est. global error ζ_z",
            r.estimated_error_zeta_z.map_or("unavailable".into(), |e| eng(e, "m")),
        ),
        ("wall time", eng(r.wall_time, "s")),
        ("real-time factor", format!("{:.1}", r.real_time_factor)),
    ];
    for (k, v) in rows {
        writeln!(out, "  {k:<24} {v:>20}")?;
    }
    if let Some(path) = &a.out {
        writeln!(out, "  trace: {} rows in {}", r.trace_rows, path.display())?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Command;

    /// docs/model.md, "`nanopush simulate`": the defaults its figures are of: the default scene, a
    /// 50 ms push, Rodas4 at rtol 1e-6, 0.1 ms samples (the 1 µm/s is the scene's).
    #[test]
    fn simulate_defaults_are_the_documented_ones() {
        let Command::Simulate(a) = crate::parse(&["simulate"]) else {
            unreachable!()
        };
        assert_eq!(a.scene, None);
        assert_eq!((a.duration, a.rtol, a.sample), (0.05, 1e-6, 1e-4));
        assert_eq!(check(&a).unwrap(), Method::Rodas4);
    }
}
