//! `nanopush model`.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use nanopush_proto::model::{ForceCurveReport, ModelReport};
use nanopush_study::report::{force_curve_report, model_report};

use crate::units::eng;

/// Arguments of `nanopush model`.
#[derive(Args, Debug)]
pub struct ModelArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Print one JSON object (SI units) instead of a table.
    #[arg(long)]
    json: bool,
    /// Print the tip-sample force curve (approach and retraction, Fig 3) instead.
    #[arg(long)]
    force_curve: bool,
    /// Points per branch of the force curve.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(10..=100_000))]
    steps: u32,
}

/// Runs `nanopush model`; returns what to print on stdout.
pub fn run(a: &ModelArgs) -> anyhow::Result<String> {
    let mut out = String::new();
    let scene = crate::load_scene(a.scene.as_ref())?;
    if a.force_curve {
        let r = force_curve_report(&scene, a.steps as usize);
        if a.json {
            writeln!(out, "{}", serde_json::to_string(&r)?)?;
            return Ok(out);
        }
        return force_curve_table(&r);
    }
    let r = model_report(&scene);
    if a.json {
        writeln!(out, "{}", serde_json::to_string(&r)?)?;
        return Ok(out);
    }
    model_table(&r)
}

/// `--force-curve`: the snap-in and pull-off, then the curve's points, about 40 a branch.
fn force_curve_table(r: &ForceCurveReport) -> anyhow::Result<String> {
    let mut out = String::new();
    writeln!(
        out,
        "Force curve of scene \"{}\" (tip Rₜ = {}, k_c = {}) against the bare substrate (Fig 3)",
        r.scene,
        eng(r.tip_radius, "m"),
        eng(r.k_c, "N/m")
    )?;
    writeln!(
        out,
        "  snap-in at piezo distance   {}",
        r.snap_in_distance.map_or("none".into(), |d| eng(d, "m"))
    )?;
    writeln!(out, "  pull-off force              {}", eng(r.pull_off_force, "N"))?;
    writeln!(
        out,
        "  pull-off at piezo distance  {}",
        r.pull_off_distance.map_or("none".into(), |d| eng(d, "m"))
    )?;
    writeln!(out)?;
    writeln!(
        out,
        "{:>12} {:>12} {:>12} {:>12} {:>12}   branch",
        "distance/nm", "gap/nm", "deflect/nm", "force/nN", "meniscus"
    )?;
    let every = (r.approach.len() / 40).max(1);
    for (branch, pts) in [("approach", &r.approach), ("retract", &r.retraction)] {
        for p in pts.iter().step_by(every) {
            writeln!(
                out,
                "{:>12.3} {:>12.3} {:>12.3} {:>12.3} {:>12}   {branch}",
                p.distance * 1e9,
                p.gap * 1e9,
                p.deflection * 1e9,
                p.force * 1e9,
                if p.meniscus { "yes" } else { "no" }
            )?;
        }
    }
    Ok(out)
}

/// The derived quantities, a line each, then the Eq 18 steady state and the warnings.
fn model_table(r: &ModelReport) -> anyhow::Result<String> {
    let mut out = String::new();
    writeln!(out, "Scene \"{}\": derived quantities", r.scene)?;
    for (name, value, eq) in model_rows(r) {
        writeln!(out, "  {name:<24} {value:>22}   {eq}")?;
    }
    match (&r.steady_state, &r.steady_state_error) {
        (Some(s), _) => {
            writeln!(
                out,
                "  Eq 18 steady state: F_ta = {}, f_ta = {}, y = {}, ζ_y = {}, ζ_z = {}, z = {}",
                eng(s.normal_ta, "N"),
                eng(s.friction_ta, "N"),
                eng(s.y, "m"),
                eng(s.zeta_y, "m"),
                eng(s.zeta_z, "m"),
                eng(s.z, "m")
            )?;
        }
        (None, Some(e)) => writeln!(out, "  Eq 18 steady state: {e}")?,
        (None, None) => {}
    }
    for w in &r.warnings {
        writeln!(out, "  warning: {w}")?;
    }
    Ok(out)
}

/// The table's rows: name, value and where it comes from in the paper.
fn model_rows(r: &ModelReport) -> Vec<(&'static str, String, &'static str)> {
    vec![
        ("c1", format!("{:.6}", r.c1), "Eq 10"),
        ("c2", format!("{:.6}", r.c2), "Eq 10"),
        ("c3", format!("{:.6}", r.c3), "Eq 10"),
        ("k_y = k_c/c2", eng(r.k_y, "N/m"), "Sec 2.5"),
        ("k_z = k_c", eng(r.k_z, "N/m"), "Sec 2.5"),
        ("k_yz = k_c/c3", eng(r.k_yz, "N/m"), "Sec 2.5"),
        ("m_c* = k_z/(4π²f_r²)", eng(r.m_c * 1e3, "g"), "Sec 2.5 (corrected)"),
        ("b_y = b_z", eng(r.b_y, "N·s/m"), "Sec 2.5"),
        ("k_as* = 8RₐG*", eng(r.k_as, "N/m"), "Sec 2.5"),
        ("A_as = 4πRₐγ_L", eng(r.a_as, "N"), "Eq 6"),
        ("A_ta = 2πR̃γ_L", eng(r.a_ta, "N"), "Eq 7"),
        ("A_as (included terms)", eng(r.a_as_model, "N"), "Eq 2-6"),
        ("A_ta (included terms)", eng(r.a_ta_model, "N"), "Eq 1-5, 7"),
        ("R̃", eng(r.r_eff, "m"), "Eq 3"),
        ("r1 (Kelvin)", eng(r.r1, "m"), "Eq 3 (natural log)"),
        ("L_t = 2 r1", eng(r.meniscus_formation_gap, "m"), "Eq 3"),
        ("δ (meniscus breaking)", eng(r.meniscus_breaking_length, "m"), "Eq 3"),
        (
            "y* (paper's A_as)",
            r.y_star.map_or("none: cannot be pushed".into(), |y| eng(y, "m")),
            "Eq 15",
        ),
        (
            "y* (included terms)",
            r.y_star_model.map_or("none: cannot be pushed".into(), |y| eng(y, "m")),
            "Eq 15",
        ),
        ("μ_as^s lower bound", format!("{:.4}", r.mu_lower_bound), "Eq 9"),
        (
            "μ_as^s upper bound",
            r.mu_upper_bound.map_or("unbounded".into(), |u| format!("{u:.4}")),
            "Eq 16",
        ),
        (
            "μ_as^s (scene)",
            format!(
                "{:.4} ({})",
                r.mu_as_static,
                if r.mu_feasible {
                    "feasible"
                } else {
                    "OUTSIDE the Eq 16 window"
                }
            ),
            "Eq 16",
        ),
        ("no sticking to tip", r.no_sticking_to_tip.to_string(), "Eq 8"),
        ("particle mass", eng(r.particle_mass * 1e3, "g"), ""),
        ("contact period", eng(r.contact_period, "s"), "2π sqrt(mₐ/k_as*)"),
        ("cantilever period", eng(r.cantilever_period, "s"), "1/f_r"),
        ("stage period", eng(r.stage_period, "s"), "1/f_y"),
        (
            "state dimension",
            format!("{} ({})", r.state_dimension, r.states.join(", ")),
            "Eq 17",
        ),
    ]
}
