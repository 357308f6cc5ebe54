//! The plan's dry run: the whole strategy on the scene's model, as a real push would run it,
//! before the plan is given out.

use super::DerivedStrategy;
use crate::afm::Afm;
use crate::control::moves::locate::MoveTarget;
use crate::control::moves::run::{DEFAULT_ATTEMPTS, MoveOptions, Verdict, move_particle};
use crate::control::strategy::Failure;
use crate::scene::Scene;

/// Runs `plan` on a copy of `scene` with other seeds for the readout's noise and the
/// substrate's roughness (the plan knows their statistics, not their realization): one push of
/// the longest leg the plan allows (within [0.3, 1] µm) up the substrate's slope, and one down it
/// (the contact angle falls on the way up, rises on the way down), each from where a local scan
/// finds the particle and judged with the plan's tolerance; a leg that would leave the stage is
/// not run; with `push_cap` (the plan's shorter pushes) each is a move of three such pushes. The
/// legs run, or how one failed.
pub fn dry_run(scene: &Scene, plan: &DerivedStrategy, push_cap: Option<f64>) -> Result<usize, DryRunFailure> {
    dry_run_with(scene, plan, push_cap, 1)
}

/// [`dry_run`] with realization `k` (1, 2, ...) of the noise and the roughness: a marginal plan
/// is dry-run again with a second.
pub fn dry_run_with(
    scene: &Scene,
    plan: &DerivedStrategy,
    push_cap: Option<f64>,
    k: u64,
) -> Result<usize, DryRunFailure> {
    dry_run_along(scene, plan, push_cap, k, false)
}

/// [`dry_run_with`] across the substrate's slope (its legs at right angles to the slope's
/// direction, one way and back) instead of up and down it: a plan that pushes without a
/// lost-particle test is dry-run in a third realization this way, since nothing tells it, while
/// it pushes, that a leg lost the particle.
pub fn dry_run_across(
    scene: &Scene,
    plan: &DerivedStrategy,
    push_cap: Option<f64>,
    k: u64,
) -> Result<usize, DryRunFailure> {
    dry_run_along(scene, plan, push_cap, k, true)
}

fn dry_run_along(
    scene: &Scene,
    plan: &DerivedStrategy,
    push_cap: Option<f64>,
    k: u64,
    across: bool,
) -> Result<usize, DryRunFailure> {
    let mut s = scene.clone();
    plan.apply(&mut s);
    s.file.sensor.noise_seed = s
        .file
        .sensor
        .noise_seed
        .wrapping_add(k.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    s.file.substrate.roughness_seed = s
        .file
        .substrate
        .roughness_seed
        .wrapping_add(k.wrapping_mul(0x2545_f491_4f6c_dd1d));
    s.pushable(plan.particle)
        .map_err(|e| DryRunFailure::said(e.to_string()))?;
    let part = s
        .file
        .particles
        .iter()
        .find(|p| p.id == plan.particle)
        .ok_or_else(|| DryRunFailure::said(format!("no particle {}", plan.particle)))?;
    let (x, y, r) = (part.x_um * 1e-6, part.y_um * 1e-6, part.radius_nm * 1e-9);
    let range = s.file.stage.range_um * 1e-6;
    // Shorter pushes are dry-run as a move of three of them (at most 1 µm), each re-parked as a
    // real move's legs are: their errors add up, and one leg alone does not show it.
    let distance = push_cap.map_or((s.file.strategy.max_push_um * 1e-6).clamp(0.3e-6, 1e-6), |cap| {
        (3.0 * cap).min(1e-6)
    });
    let (tx, ty) = (s.file.substrate.tilt_x_mrad, s.file.substrate.tilt_y_mrad);
    let tilt = tx.hypot(ty);
    let up = if tilt > 0.0 { (tx / tilt, ty / tilt) } else { (1.0, 0.0) };
    let up = if across { (-up.1, up.0) } else { up };
    // Up the slope, then down it, each from where the scan after the last found the particle.
    let back = s.file.strategy.approach_distance_um * 1e-6 + r + 2e-6;
    let start = ((x - up.0 * back).clamp(0.0, range), (y - up.1 * back).clamp(0.0, range));
    let mut afm = Afm::from_scene(&s, start.0, start.1, 1e-3);
    let mut at = (x, y);
    let mut legs = 0;
    for direction in [up, (-up.0, -up.1)] {
        let end = (at.0 + direction.0 * distance, at.1 + direction.1 * distance);
        if !(r..=range - r).contains(&end.0) || !(r..=range - r).contains(&end.1) {
            continue;
        }
        legs += 1;
        let options = MoveOptions {
            tolerance: plan.tolerance,
            attempts: DEFAULT_ATTEMPTS,
            pause: None,
        };
        let target = MoveTarget::Distance { distance, direction };
        let moved = move_particle(&s, &mut afm, plan.particle, at, r, target, options)
            .map_err(|e| DryRunFailure::said(e.to_string()))?;
        judge(&moved, plan).map_err(|text| {
            let lost = moved.legs.iter().find_map(|l| match l.run.summary.failure {
                Some(Failure::ParticleLost { travel_um }) => Some((l, travel_um * 1e-6)),
                _ => None,
            });
            DryRunFailure {
                how: lost.and_then(|(l, _)| how_lost(&l.run, direction)),
                text,
                lost_after: lost.map(|(_, travel)| travel),
            }
        })?;
        if let Some(found) = moved.after.1 {
            at = (found.x, found.y);
        }
    }
    Ok(legs)
}

/// What the particle did while the push lost it, from the run's hidden truth (the dry run is a
/// simulation, so it may look): how far it moved along the push while the tip pushed, against the
/// tip's own travel. Under 0.8 of the tip's travel the tip climbed over it (it rolled or slid
/// under the tip); over 1.2 it ran ahead; in between it went with the tip and the reading drifted
/// off the contact.
fn how_lost(run: &crate::control::strategy::StrategyRun, d: (f64, f64)) -> Option<String> {
    let pushing: Vec<_> = run.trace.iter().filter(|r| r.phase == "push").collect();
    let (first, last) = (pushing.first()?, pushing.last()?);
    let along = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0) * d.0 + (b.1 - a.1) * d.1;
    let tip = along((first.stage[0], first.stage[1]), (last.stage[0], last.stage[1]));
    let particle = along(first.particle, last.particle);
    if tip <= 1e-9 {
        return None;
    }
    let what = if particle < 0.8 * tip {
        "the tip climbed over it"
    } else if particle > 1.2 * tip {
        "it ran ahead of the tip"
    } else {
        "it went with the tip, and the reading drifted off the contact"
    };
    Some(format!(
        "the particle moved {:.0} nm while the tip pushed {:.0} nm: {what}",
        particle * 1e9,
        tip * 1e9
    ))
}

/// How a dry run failed: in words (`code: text`), and the push's travel when a leg lost the
/// particle.
#[derive(Debug, Clone, PartialEq)]
pub struct DryRunFailure {
    /// `code: what happened`.
    pub text: String,
    /// What the particle did, when a leg lost it ([`how_lost`]).
    pub how: Option<String>,
    /// The push travel (m) at which a leg lost the particle.
    pub lost_after: Option<f64>,
}

impl DryRunFailure {
    fn said(text: String) -> DryRunFailure {
        DryRunFailure {
            text,
            how: None,
            lost_after: None,
        }
    }
}

impl std::fmt::Display for DryRunFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.how {
            Some(how) => write!(f, "{} ({how})", self.text),
            None => f.write_str(&self.text),
        }
    }
}

fn judge(moved: &crate::control::moves::run::MoveRun, plan: &DerivedStrategy) -> Result<(), String> {
    // A push that read the particle as lost fails the dry run even when the move's scan after
    // found it and a correction brought it home: a plan is to keep its particle, and a shorter
    // push may (the move's correction is the real push's fallback, not the plan).
    if let Some(l) = moved.legs.iter().find(|l| l.run.summary.failure.is_some()) {
        let code = l.run.summary.failure.map_or("failed", |f| f.code());
        return Err(format!("{code}: {}", l.run.failure_text().unwrap_or_default()));
    }
    match moved.verdict {
        Verdict::Ok { .. } => Ok(()),
        Verdict::Missed { error } => Err(format!(
            "missed: {:.1} nm from the target after {} push(es) (tolerance {} nm)",
            error * 1e9,
            moved.attempts,
            crate::words::nm_text(plan.tolerance)
        )),
        Verdict::NotFound => Err("not_found: the scan after the push did not find the particle".into()),
        Verdict::Failed { code } => Err(format!(
            "{code}: {}",
            moved.legs.last().and_then(|l| l.run.failure_text()).unwrap_or_default()
        )),
    }
}

/// The scene field a dry run's failure points to (`still_held`: the fields of the terms that
/// hold the tip on the substrate, [`super::adhesion_field`]). A stiffer lever is named only
/// while the scene's is below the stiffest a scene allows.
pub fn field_for(why: &str, scene: &Scene) -> String {
    let code = why.split(':').next().unwrap_or("");
    let can_stiffen = scene.file.cantilever.stiffness_n_per_m < super::MAX_STIFFNESS;
    let stiffer = |other: &str| {
        if can_stiffen {
            format!("cantilever.stiffness_n_per_m (stiffer) or {other}")
        } else {
            format!(
                "{other} (the lever is already the stiffest a scene allows, {} N/m)",
                super::short(super::MAX_STIFFNESS)
            )
        }
    };
    match code {
        "still_held" => stiffer(&super::adhesion_field::field(
            super::adhesion_field::Pair::TipSubstrate,
            &scene.tip_sample().adhesion_sources(),
        )),
        "deflection_limit" => stiffer("sensor.gain_v_per_nm (smaller |gain|)"),
        // Both raised to their limits, the dry run loses the particle at the same travel: the
        // instrument and the model's push disagree, and no field is known to settle it.
        "particle_lost" => {
            "friction.tip_particle_static (higher), though no field is known to help: the dry run lost the particle that the model's push kept".into()
        }
        "no_contact" => "sensor.gain_v_per_nm (larger |gain|) or friction.particle_substrate_static".into(),
        "no_separation" => stiffer("friction.particle_substrate_static (lower)"),
        "snapped_back" => {
            if can_stiffen {
                "push.contact_angle_deg (a higher parking height) or cantilever.stiffness_n_per_m (stiffer)".into()
            } else {
                "push.contact_angle_deg (a higher parking height)".into()
            }
        }
        "missed" => "stage.resonance_hz (a stiffer stage) or a looser --tolerance-nm".into(),
        "not_found" => "scan.noise_rms_nm or substrate.roughness_rms_nm (lower)".into(),
        "timeout" => "push.speed_um_per_s (faster) or strategy.phase_timeout_s".into(),
        _ => "the scene's physics (see the reason)".into(),
    }
}

#[cfg(test)]
mod tests {
    use crate::scene::Scene;

    #[test]
    fn a_lever_at_the_stiffest_a_scene_allows_is_not_asked_to_be_stiffer() {
        let mut scene = Scene::default_scene();
        let why = "deflection_limit: deflection -10.000 V at or beyond the limit";
        assert_eq!(
            super::field_for(why, &scene),
            "cantilever.stiffness_n_per_m (stiffer) or sensor.gain_v_per_nm (smaller |gain|)"
        );
        scene.file.cantilever.stiffness_n_per_m = super::super::MAX_STIFFNESS;
        assert_eq!(
            super::field_for(why, &scene),
            "sensor.gain_v_per_nm (smaller |gain|) (the lever is already the stiffest a scene allows, 500 N/m)"
        );
        assert_eq!(
            super::field_for("snapped_back: x", &scene),
            "push.contact_angle_deg (a higher parking height)"
        );
    }
}
