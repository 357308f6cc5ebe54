//! `nanopush plan`: the push strategy derived from the scene's model, each setting with its
//! reason, or why no strategy can push the particle (`control::derive`).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use nanopush_instrument::control::derive;

/// Arguments of `nanopush plan`.
#[derive(Args, Debug)]
pub struct PlanArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Particle to plan for (its id); the scene's `push.particle_id` when absent.
    #[arg(long, allow_hyphen_values = true)]
    particle: Option<u32>,
    /// The push's tolerance (nm), in [1, 100000].
    #[arg(long, value_name = "NM", default_value_t = nanopush_proto::push::TOLERANCE_NM, allow_hyphen_values = true)]
    tolerance_nm: f64,
    /// Ignore the scene's hand-set values: derive every setting.
    #[arg(long)]
    derive_all: bool,
    /// Print one JSON object instead of the lines.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command: the plan, or the refusal as an error (exit 2).
pub fn run(a: &PlanArgs) -> anyhow::Result<String> {
    let mut scene = crate::load_scene(a.scene.as_ref())?;
    crate::units::check_tolerance_nm(a.tolerance_nm)?;
    let id = a.particle.unwrap_or(scene.file.push.particle_id);
    if a.derive_all {
        scene.hand_set = nanopush_instrument::scene::hand_set::HandSet::none();
    }
    let plan = derive::derive(&scene, id, a.tolerance_nm * 1e-9)?;
    if a.json {
        let choices: Vec<serde_json::Value> = plan
            .choices
            .iter()
            .map(|c| {
                // A switch as the scene file writes it: `true` or `false`.
                let value = if derive::SWITCHES.contains(&c.key) {
                    serde_json::json!(c.value != 0.0)
                } else {
                    serde_json::json!(c.value)
                };
                serde_json::json!({"key": c.key, "value": value, "hand_set": c.hand_set, "why": c.why})
            })
            .collect();
        let v = serde_json::json!({
            "schema": "plan",
            "scene": scene.file.name,
            "particle": id,
            "tolerance": plan.tolerance,
            "summary": plan.summary(),
            "tried": plan.tried,
            "choices": choices,
            "warnings": plan.warnings,
        });
        return Ok(serde_json::to_string_pretty(&v)? + "\n");
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Strategy for particle {id} of scene {:?} (tolerance {} nm):",
        scene.file.name, a.tolerance_nm
    );
    let _ = writeln!(s, "  chosen: {}", plan.summary());
    for t in &plan.tried {
        let _ = writeln!(s, "  tried first: {t}");
    }
    s.push_str(&plan.explain());
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(clap::Parser)]
    struct P {
        #[command(flatten)]
        a: PlanArgs,
    }

    fn scene_path(name: &str) -> String {
        format!("{}/../scenes/{name}", env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn every_setting_has_a_line_and_the_refusal_names_the_field() {
        let p = P::parse_from(["plan", "--scene", &scene_path("gold-14nm.toml")]);
        let text = run(&p.a).unwrap();
        for key in nanopush_instrument::scene::hand_set::DERIVABLE {
            if key != "strategy.control" {
                assert!(text.contains(&format!("{key} = ")), "{key} in\n{text}");
            }
        }
        assert!(text.contains("strategy.set_point_v = ") && text.contains("% of the stick-phase peak deflection"));
        let soft = std::env::temp_dir().join(format!("nanopush-plan-soft-{}.toml", std::process::id()));
        let text = std::fs::read_to_string(scene_path("paper-default.toml"))
            .unwrap()
            .replace("stiffness_n_per_m = 8.0", "stiffness_n_per_m = 0.01");
        std::fs::write(&soft, text).unwrap();
        let p = P::parse_from(["plan", "--scene", soft.to_str().unwrap(), "--derive-all"]);
        let e = run(&p.a).unwrap_err().to_string();
        let _ = std::fs::remove_file(&soft);
        assert!(e.contains("cantilever.stiffness_n_per_m"), "{e}");
        let p = P::parse_from(["plan", "--tolerance-nm", "0"]);
        assert!(run(&p.a).unwrap_err().to_string().contains("allowed: [1, 100000] nm"));
    }
}
