//! One derivation of the strategy: the checks of the scene, then each contact angle that passes
//! the model's checks gets its settings and a dry run, until one ends `ok`.

use super::readout::Readout;
use super::{BETAS_DEG, Choice, DerivedStrategy, Fails, MAX_DRY_RUN, MIN_PUSH, PAPER_SPEED, Refusal, dry_run, short};
use crate::control::estimator::ContactSide;
use crate::scene::Scene;
use crate::scene::file::{ParticleFile, StrategyFile};

/// One derivation: the scene and particle it is for, and the choices and warnings so far.
pub(super) struct Derivation<'a> {
    pub(super) scene: &'a Scene,
    pub(super) part: &'a ParticleFile,
    pub(super) tolerance: f64,
    pub(super) readout: Readout,
    pub(super) file: StrategyFile,
    pub(super) choices: Vec<Choice>,
    pub(super) warnings: Vec<String>,
    /// The longest push a dry run showed the particle is kept for (m), with the travel at which
    /// a longer one lost it: the settings' longest push is held under it.
    pub(super) push_cap: Option<(f64, f64)>,
    /// What was tried before the strategy the plan gives, a line each ([`DerivedStrategy::tried`]).
    pub(super) tried: Vec<String>,
    /// The values the first angle the lever's deflection limit ruled out named (a stiffer lever,
    /// a smaller gain): a refusal whose dry runs then trip the same limit names them too.
    pub(super) limit_advice: Vec<super::Advice>,
    /// The tip is held at one height: a dry run of this angle's plan following the slope the
    /// scans measure failed (a scan whose height drifts reads a slope the substrate does not
    /// have, along its slow axis).
    pub(super) held: bool,
}

impl<'a> Derivation<'a> {
    pub(super) fn new(scene: &'a Scene, id: u32, tolerance: f64) -> Result<Derivation<'a>, Refusal> {
        let part = scene
            .file
            .particles
            .iter()
            .find(|p| p.id == id)
            .ok_or_else(|| Refusal {
                particle: id,
                code: "geometry",
                advice: Vec::new(),
                reason: format!("the scene has no particle with id {id}"),
                field: "push.particle_id".into(),
            })?;
        Ok(Derivation {
            scene,
            part,
            tolerance,
            readout: Readout::of(scene),
            file: scene.file.strategy.clone(),
            choices: Vec::new(),
            warnings: Vec::new(),
            push_cap: None,
            tried: Vec::new(),
            limit_advice: Vec::new(),
            held: false,
        })
    }

    pub(super) fn hand(&self, key: &str) -> bool {
        self.scene.hand_set.contains(key)
    }

    pub(super) fn refuse(&self, fails: Fails) -> Refusal {
        Refusal {
            particle: self.part.id,
            code: fails.code,
            advice: fails.advice,
            reason: fails.reason,
            field: fails.field,
        }
    }

    /// Records a choice: the hand-set value when there is one (warned about if `check` says it
    /// cannot work), else the derived one. Returns the value in force.
    pub(super) fn choose(
        &mut self,
        key: &'static str,
        hand_value: f64,
        derived: f64,
        why: String,
        check: Option<String>,
    ) -> f64 {
        let hand_set = self.hand(key);
        let value = if hand_set { hand_value } else { derived };
        if hand_set && let Some(problem) = check {
            self.warnings.push(format!(
                "{key} = {} (hand-set): {problem}; the model suggests {}",
                short(hand_value),
                short(derived)
            ));
        }
        let why = if hand_set && (hand_value - derived).abs() > 1e-12 * derived.abs().max(1e-30) {
            format!(
                "given by the scene; derived would be {}: {why}",
                super::choice::value_text(key, derived)
            )
        } else {
            why
        };
        self.choices.push(Choice {
            key,
            value,
            hand_set,
            why,
        });
        value
    }

    pub(super) fn run(mut self) -> Result<DerivedStrategy, Refusal> {
        self.check_model()?;
        let f = &self.scene.file;
        let (r_a, r_t) = (self.part.radius_nm * 1e-9, f.tip.radius_nm * 1e-9);
        self.substrate_threshold()?;
        self.check_pull_off()?;
        self.check_stage()?;
        let approach_speed = f.strategy.approach_speed_um_per_s * 1e-6;
        let v0 = if self.hand("push.speed_um_per_s") {
            f.push.speed_um_per_s * 1e-6
        } else {
            PAPER_SPEED
        };
        // Each angle that passes the checks is tried in a dry run of the whole strategy on the
        // model; the first that ends `ok` is the plan.
        let (base_choices, base_warnings) = (self.choices.clone(), self.warnings.clone());
        let mut rejected: Vec<(f64, String, Vec<String>)> = Vec::new();
        let mut retry: Option<f64> = None;
        loop {
            // A retry with shorter pushes keeps its angle: the others come first otherwise.
            let skip: Vec<f64> = rejected
                .iter()
                .map(|r| r.0)
                .chain(BETAS_DEG.iter().copied().filter(|b| retry.is_some_and(|r| r != *b)))
                .collect();
            retry = None;
            let cand = match self.contact_angle(r_a, r_t, v0, approach_speed, &skip) {
                Ok(c) => c,
                Err(refusal) if rejected.is_empty() => return Err(refusal),
                Err(_) => return Err(self.every_dry_run_failed(&rejected)),
            };
            let mut plan = self.settings(cand, r_a, r_t, approach_speed)?;
            // The geometry a push checks before it moves (hand-set values may break it): what
            // the plan accepts, a push must not refuse.
            let mut applied = self.scene.clone();
            plan.apply(&mut applied);
            if let Err(e) = applied.pushable(self.part.id) {
                let text = e.to_string();
                let field = text
                    .split(" = ")
                    .next()
                    .filter(|k| k.contains('.'))
                    .unwrap_or("strategy");
                return Err(self.refuse(Fails {
                    code: "geometry",
                    advice: Vec::new(),
                    reason: text.clone(),
                    field: field.to_string(),
                }));
            }
            // A dry run that would take longer than a real push may is not run: said instead.
            let dry_run_time = 2.0 * (1e-6 + plan.strategy.search_range_um * 1e-6) / (plan.speed_um_per_s * 1e-6);
            if dry_run_time > MAX_DRY_RUN {
                plan.warnings.push(format!(
                    "no dry run: at {} µm/s it would take {dry_run_time:.0} s of simulated time (at most {MAX_DRY_RUN:.0} s)",
                    short(plan.speed_um_per_s)
                ));
                return Ok(plan);
            }
            let cap = self.push_cap.map(|c| c.0);
            // A marginal plan (read on the pull side, or found only after a dry run failed) must
            // also pass a move of three of its longest pushes in a row with other noise and
            // roughness: one push can pass by luck (a pull-side plan for validator seed 110
            // passed once and lost the particle in the push).
            // A plan without a lost-particle test is marginal too, and dry-run a third time,
            // across the slope.
            let blind = self.rolls_unread(&cand.prediction);
            let marginal =
                cand.prediction.side == ContactSide::Pull || blind || !rejected.is_empty() || self.push_cap.is_some();
            let longest = cap.unwrap_or(plan.strategy.max_push_um * 1e-6);
            let result = dry_run::dry_run(self.scene, &plan, cap).and_then(|legs| {
                if marginal && legs > 0 {
                    dry_run::dry_run_with(self.scene, &plan, Some(longest), 2)
                } else {
                    Ok(legs)
                }
            });
            let result = result.and_then(|legs| {
                if marginal && legs > 0 {
                    dry_run::dry_run_across(self.scene, &plan, Some(longest), 3).map(|_| legs)
                } else {
                    Ok(legs)
                }
            });
            match result {
                Ok(0) => {
                    plan.warnings.push(
                        "no dry run: neither leg of it (up and down the slope, 0.3-1 µm) stays on the stage from this particle"
                            .into(),
                    );
                    return Ok(plan);
                }
                Ok(_) => {
                    plan.dry_run_passed = true;
                    return Ok(plan);
                }
                // A reading that drifts off the contact over a long push (the substrate's slope
                // or the particle's turn changing the contact) trips the lost-particle test
                // well after t*: shorter pushes, each re-parked at a fresh set point, keep it.
                // Tried at half the travel it was lost at, while that is at least MIN_PUSH.
                Err(why) if let Some(cap) = self.shorter_push(why.lost_after, plan.strategy.max_push_um * 1e-6) => {
                    self.note_tried(dry_run_line(&plan, &why));
                    self.push_cap = Some((cap, why.lost_after.unwrap_or(cap)));
                    self.choices = base_choices.clone();
                    self.warnings = base_warnings.clone();
                    rejected.retain(|r| r.0 != cand.beta_deg);
                    retry = Some(cand.beta_deg);
                }
                // Held at one height instead, a slope the scan misreads is not followed.
                Err(why) if plan.strategy.follow_slope && !self.hand("strategy.follow_slope") => {
                    self.note_tried(dry_run_line(&plan, &why));
                    self.held = true;
                    self.push_cap = None;
                    self.choices = base_choices.clone();
                    self.warnings = base_warnings.clone();
                    rejected.retain(|r| r.0 != cand.beta_deg);
                    retry = Some(cand.beta_deg);
                }
                Err(why) if self.hand("push.contact_angle_deg") => {
                    plan.warnings
                        .push(format!("the plan's dry run on the model fails: {why}"));
                    return Ok(plan);
                }
                Err(why) => {
                    self.note_tried(dry_run_line(&plan, &why));
                    rejected.push((cand.beta_deg, why.to_string(), plan.warnings.clone()));
                    self.push_cap = None;
                    self.held = false;
                    self.choices = base_choices.clone();
                    self.warnings = base_warnings.clone();
                }
            }
        }
    }

    /// Adds a line to what was tried, once (each retry of the angles meets the same failures).
    pub(super) fn note_tried(&mut self, line: String) {
        if !self.tried.contains(&line) {
            self.tried.push(line);
        }
    }

    /// The longest push to try after a dry run lost the particle `lost_after` into a push of a
    /// plan whose longest push is `max_push` (m): half that travel, when the longest push is not
    /// hand-set, the loss came after t* had passed (past [`MIN_PUSH`]) and the halved push is
    /// still at least [`MIN_PUSH`] and shorter than the one tried.
    fn shorter_push(&self, lost_after: Option<f64>, max_push: f64) -> Option<f64> {
        let lost = lost_after?;
        let tried = self.push_cap.map_or(max_push.clamp(0.3e-6, 1e-6), |c| c.0);
        // Whole hundredths of a µm, as the plan writes it.
        let cap = (0.5 * lost.min(tried) * 1e8).floor() / 1e8;
        (!self.hand("strategy.max_push_um") && cap >= MIN_PUSH && cap < 0.9 * tried).then_some(cap)
    }

    /// A model no push can run (dynamic degrees of freedom) is refused before anything is
    /// derived or dry-run.
    fn check_model(&self) -> Result<(), Refusal> {
        if let Err(e) = self.scene.model_pushable() {
            let text = e.to_string();
            let field = text
                .split("physics.")
                .nth(1)
                .and_then(|r| r.split(" = ").next())
                .map_or("physics".to_string(), |k| format!("physics.{k} = \"quasi_static\""));
            return Err(self.refuse(Fails {
                code: "model",
                advice: Vec::new(),
                reason: text,
                field,
            }));
        }
        Ok(())
    }

    /// The refusal when every angle that passes the model's checks fails its dry run:
    /// `rejected` holds each angle, why its dry run failed, and the plan's warnings then.
    /// When the dry run tripped the deflection limit, the values the model's check of another
    /// angle named for it are named (and checked) here too.
    fn every_dry_run_failed(&self, rejected: &[(f64, String, Vec<String>)]) -> Refusal {
        let (beta, why, warned) = &rejected[0];
        let advice = if why.starts_with("deflection_limit:") {
            self.limit_advice.clone()
        } else {
            Vec::new()
        };
        let angles: Vec<f64> = rejected.iter().map(|r| r.0).collect();
        // A hand-set value the plan warned about is the likelier cause.
        let (hand, field) = match warned.iter().find(|w| w.contains("(hand-set)")) {
            Some(w) => (
                format!("; the plan warned: {w}"),
                w.split(" = ").next().unwrap_or("the hand-set value").to_string(),
            ),
            None => (String::new(), dry_run::field_for(why, self.scene)),
        };
        self.refuse(Fails {
            code: "dry_run",
            advice,
            reason: format!(
                "the strategy passes the model's checks but its dry run on the model fails at every such angle ({angles:?}°); at β = {beta}°: {why}{hand}"
            ),
            field,
        })
    }
}

/// The line of what was tried for a plan whose dry run failed.
fn dry_run_line(plan: &DerivedStrategy, why: &dry_run::DryRunFailure) -> String {
    format!(
        "β = {}°, {} side, {}, pushes of at most {} µm: the dry run failed: {}",
        plan.contact_angle_deg,
        plan.prediction.side.name(),
        plan.height(),
        short(plan.strategy.max_push_um),
        brief_with(why)
    )
}

/// [`brief`] of a dry run's failure, with what the particle did when a leg lost it.
fn brief_with(why: &dry_run::DryRunFailure) -> String {
    match &why.how {
        Some(how) => format!("{} ({how})", brief(&why.text)),
        None => brief(&why.text),
    }
}

/// The first clause or two of a reason (`code: what happened`), at most 160 characters: enough
/// for a line of what was tried.
pub(super) fn brief(reason: &str) -> String {
    let mut parts = reason.splitn(3, ": ");
    let mut s = parts.next().unwrap_or("").to_string();
    if let Some(next) = parts.next() {
        s.push_str(": ");
        s.push_str(next.split(';').next().unwrap_or(next));
    }
    if s.chars().count() > 160 {
        s = s.chars().take(157).collect::<String>() + "...";
    }
    s
}
