//! The contact angle β: the hand-set one, or the first of [`BETAS_DEG`] whose parking height
//! is above the snap-in and whose predicted push passes the model's checks, read on the push
//! side; failing that, the first whose push the push side cannot read but the pull side can
//! ([`ContactSide`]).

use super::adhesion_field;
use super::{
    BACK_OFF, BETAS_DEG, Candidate, Derivation, Fails, MAX_START, OVER_TOP_MARGIN, Refusal, SET_FRACTION, TICK,
};
use crate::control::estimator::{ContactSide, RetractPlan, predict_with_set_fraction};
use crate::control::strategy::HOLD;
use crate::physics::pushing::SimulationError;

impl Derivation<'_> {
    /// The contact angle: the hand-set one, or the first of [`BETAS_DEG`] whose predicted push
    /// passes [`Derivation::check`].
    pub(super) fn contact_angle(
        &mut self,
        r_a: f64,
        r_t: f64,
        v: f64,
        approach_speed: f64,
        skip: &[f64],
    ) -> Result<Candidate, Refusal> {
        let hand = self.hand("push.contact_angle_deg");
        let betas: Vec<f64> = if hand {
            vec![self.scene.file.push.contact_angle_deg]
        } else {
            BETAS_DEG.iter().copied().filter(|b| !skip.contains(b)).collect()
        };
        if betas.is_empty() {
            return Err(self.refuse(Fails {
                code: "dry_run",
                advice: Vec::new(),
                reason: "no contact angle left to try".into(),
                field: "push.contact_angle_deg".into(),
            }));
        }
        let mut first_failure: Option<Fails> = None;
        let mut tried = Vec::new();
        // Angles whose push the push side cannot read: tried on the pull side once no angle
        // works on the push side (the paper's reading; a scene it reads keeps its plan).
        let mut unread: Vec<(f64, f64, Fails)> = Vec::new();
        // Auto-parking detects the substrate where the tip snaps in (the meniscus, the
        // attraction), this high above it; the tip rises from there to the parking height, and
        // a parking height below it would drive the tip down into the meniscus while the
        // substrate still holds it.
        let snap_in = crate::control::strategy::runner::detection_offset(self.scene, &self.scene.strategy_params(TICK));
        // How far off the parking height may be: the roughness under the tip, and a nanometre of
        // the detection's own error.
        let height_error = OVER_TOP_MARGIN + 4.0 * self.scene.file.substrate.roughness_rms_nm * 1e-9;
        for &beta_deg in &betas {
            let beta = beta_deg.to_radians();
            let parking = r_a - r_t + (r_a + r_t) * beta.sin();
            // The apex passes the particle's top by (Rₐ + Rₜ)(1 − sin β): a parking height off
            // by more sends the tip over the particle without touching it.
            let over_top = (r_a + r_t) * (1.0 - beta.sin());
            let result = if parking <= 0.05 * r_a {
                Err(Fails {
                    code: "geometry",
                    advice: Vec::new(),
                    reason: format!(
                        "at β = {beta_deg}° the parking height Rₐ − Rₜ + (Rₐ + Rₜ) sin β = {:.2} nm leaves the apex within 5 % of Rₐ of the substrate",
                        parking * 1e9
                    ),
                    field: "tip.radius_nm (a sharper tip) or push.contact_angle_deg (steeper)".into(),
                })
            } else if over_top < height_error && !hand {
                Err(Fails {
                    code: "geometry",
                    advice: Vec::new(),
                    reason: format!(
                        "at β = {beta_deg}° the tip's apex parks {:.2} nm below the particle's top, within the {:.2} nm the parking height may be off (1 nm and 4 × the substrate's roughness): the tip may pass over the particle",
                        over_top * 1e9,
                        height_error * 1e9
                    ),
                    field: "push.contact_angle_deg (lower) or substrate.roughness_rms_nm (smoother)".into(),
                })
            } else if parking <= snap_in {
                let (cause, field) = adhesion_field::snap_in_cause(
                    &self.scene.tip_sample(),
                    || {
                        let mut dry = self.scene.clone();
                        dry.file.physics.capillary = false;
                        crate::control::strategy::runner::detection_offset(&dry, &dry.strategy_params(TICK))
                    },
                    parking,
                );
                // Even β = 90° parks the apex only 2Rₐ up: a steeper angle may not help.
                let steeper = if 2.0 * r_a > snap_in {
                    " or push.contact_angle_deg (steeper)".to_string()
                } else {
                    format!(
                        " (no contact angle helps: even β = 90° parks at 2Rₐ = {:.2} nm)",
                        2.0 * r_a * 1e9
                    )
                };
                Err(Fails {
                    code: "geometry",
                    advice: Vec::new(),
                    reason: format!(
                        "at β = {beta_deg}° the parking height {:.2} nm is not above the {:.2} nm where the tip snaps in to the substrate: the tip would park where {cause} holds it",
                        parking * 1e9,
                        snap_in * 1e9
                    ),
                    field: format!("{field}{steeper}"),
                })
            } else {
                self.predict_at(beta, parking, v, approach_speed, ContactSide::Push)
                    .and_then(|c| self.check(&c).map(|()| c))
            };
            tried.push(beta_deg);
            match result {
                Ok(c) => return Ok(c),
                Err(f) if hand => {
                    // A hand-set angle the push side cannot read is read on the pull side when
                    // that side can, as a derived one is.
                    if matches!(f.code, "unreadable" | "no_resistance")
                        && let Ok(c) = self
                            .predict_at(beta, parking, v, approach_speed, ContactSide::Pull)
                            .and_then(|c| self.check(&c).map(|()| c))
                    {
                        return Ok(c);
                    }
                    // The hand-set angle wins; its failure is a warning, when the model could
                    // say anything at all.
                    let warning = format!(
                        "push.contact_angle_deg = {beta_deg} (hand-set): {}; change {}",
                        f.reason, f.field
                    );
                    if let Ok(c) = self.predict_at(beta, parking, v, approach_speed, ContactSide::Push)
                        && c.prediction.peak_deflection > 0.0
                    {
                        self.warnings.push(warning);
                        return Ok(c);
                    }
                    return Err(self.refuse(f));
                }
                Err(f) => {
                    self.note_failure(beta_deg, ContactSide::Push, &f);
                    if matches!(f.code, "unreadable" | "no_resistance") {
                        unread.push((beta, parking, f.clone()));
                    }
                    if f.code == "deflection_limit" && self.limit_advice.is_empty() {
                        self.limit_advice = f.advice.clone();
                    }
                    if first_failure.is_none() {
                        first_failure = Some(f);
                    }
                }
            }
        }
        let mut pull_failure: Option<Fails> = None;
        for (beta, parking, push_failure) in unread {
            let pull = self
                .predict_at(beta, parking, v, approach_speed, ContactSide::Pull)
                .and_then(|c| self.check(&c).map(|()| c));
            if let Err(g) = &pull {
                self.note_failure(beta.to_degrees().round(), ContactSide::Pull, g);
            }
            match pull {
                Ok(c) => return Ok(c),
                Err(g) if pull_failure.is_none() => {
                    // A push bent only to the pull side is told by its pull-side failure.
                    pull_failure = Some(if push_failure.reason.contains("bends the lever away") {
                        g
                    } else {
                        Fails {
                            reason: format!("{}; read on the pull side: {}", push_failure.reason, g.reason),
                            ..push_failure
                        }
                    });
                }
                Err(_) => {}
            }
        }
        let first = first_failure.expect("at least one angle tried");
        // The first angle's failure, or its pull side's when that is where it was unreadable.
        let f = match pull_failure {
            Some(g) if matches!(first.code, "unreadable" | "no_resistance") => g,
            _ => first,
        };
        Err(self.refuse(Fails {
            reason: format!("{} (and at every other contact angle tried: {tried:?}°)", f.reason),
            ..f
        }))
    }

    /// Notes an angle that failed the model's checks on `side` among what was tried.
    fn note_failure(&mut self, beta_deg: f64, side: ContactSide, f: &Fails) {
        let reason = f.reason.trim_start_matches(&format!("at β = {beta_deg}° ")).to_string();
        self.note_tried(format!(
            "β = {beta_deg}°, {} side: {}: {}",
            side.name(),
            f.code,
            super::derivation::brief(&reason)
        ));
    }

    fn predict_at(
        &self,
        beta: f64,
        parking: f64,
        v: f64,
        approach_speed: f64,
        side: ContactSide,
    ) -> Result<Candidate, Fails> {
        let mut params = self.scene.push_params_for(self.part);
        params.beta = beta;
        params.speed = v;
        let retract = RetractPlan {
            hold: HOLD,
            back_off: BACK_OFF,
            speed: approach_speed,
            lift: MAX_START - parking,
        };
        // The set point at SET_FRACTION of the push's own peak, and the travel to it, from one
        // model push.
        // A push that loses its particle is a physical outcome, not a failure of the solver.
        let prediction = predict_with_set_fraction(params, side, SET_FRACTION, retract).map_err(|e| match e {
            SimulationError::ContactLost { .. } => Fails {
                code: "escapes",
                advice: Vec::new(),
                reason: format!(
                    "at β = {:.0}° the model's push loses the particle: {e}",
                    beta.to_degrees()
                ),
                field: crate::physics::pushing::ESCAPE_FIELD.into(),
            },
            _ => Fails {
                code: "model",
                advice: Vec::new(),
                reason: format!("the model's push at β = {:.0}° failed: {e}", beta.to_degrees()),
                field: crate::physics::pushing::MODEL_REFUSAL_FIELD.into(),
            },
        })?;
        Ok(Candidate {
            beta_deg: beta.to_degrees().round(),
            parking,
            prediction,
        })
    }
}
