//! The strategy of Sec 2.1 derived from the scene's model, instead of tuned by hand for each
//! scene (`nanopush plan`; `push` and the server use it for every setting the scene does not
//! give by hand).
//!
//! The model's push at constant speed ([`predict`]) gives what the strategy needs: the
//! stick-phase peak deflection `ζ_peak` before the particle-substrate separation `t*`, the tip
//! travel to it, the settled deflection `ζ°` after it, and, lifting the tip until it lets go,
//! the lift that takes and the drag it causes. From these, with the readout (gain `g`, noise
//! `σ`, periodic perturbation `p`, full scale) and the stage (`f_y`):
//!
//! - **β**: the first of 30°, 45°, 20°, 60°, 15°, 70°, 10°, 80° whose parking height
//!   `h = Rₐ − Rₜ + (Rₐ + Rₜ) sin β` keeps the apex above the substrate, lies above the height
//!   where the tip snaps in to it (auto-parking detects the substrate there, and the tip rises
//!   from it to `h`: a 50 nm particle at 99 % humidity has none), and whose predicted push
//!   passes every check below (the paper's 30° first).
//! - **set point** `ζ_set = 0.6 ζ_peak`: reached before the particle moves; its reading must be
//!   at least `10 (σ + p)` from the baseline.
//! - **safety limit**: `max(2.5 ζ_peak g, ζ_peak g + 10σ)` from the baseline, within 90 % of
//!   the readout's room on the push side, which must hold twice the peak.
//! - **`t*` is seen**: the drop `(ζ_peak − ζ°) g` at least `12σ + 2p` (the detector's margin
//!   is a third of it, at least 4σ); **particle lost** at half the settled reading, which
//!   must be at least `8σ + 2p`.
//! - **V**: at most the paper's 1 µm/s; at most the travel between the set point and the peak
//!   in 1.5 ticks of 1 ms (the search stops before the particle shears); at most
//!   `tolerance · 2π f_y / 4`, so the stage's ringing at the stop (`≈ V/(2π f_y)`) stays
//!   within a quarter of the tolerance.
//! - **Δ** `= (Rₐ + Rₜ)/4` within [5, 100] nm; **approach distance**: the clearance the tip
//!   needs to touch down beside the particle, `2√(Rₐ Rₜ) − (Rₐ + Rₜ) cos β` when positive,
//!   plus four local-scan pixels (where the scan may have put it) and two steps; **search
//!   range**: twice that plus the model's travel to the set point and four steps.
//! - **start height** (the retraction's): above the tallest particle by a quarter of its height
//!   (at least 0.5 µm) plus the substrate's rise over the stage's diagonal (the tip travels at
//!   a fixed height: `|tilt| · √2 · range`) and four RMS of roughness, and above the parking
//!   height plus 1.25 × the lift the model needs to let go, plus 0.2 µm; at most 50 µm.
//! - **adhesion**: the pull-off from the substrate after auto-parking bends the lever the
//!   other way by up to the tip's adhesion over `k_c`, and may saturate the readout on that
//!   side: the strategy rides that out while it rises, until the tip lets go, within
//!   `1.5 (F_ad/k_c + L_t + δ_b + a₀) + 10 nm` of the detected substrate
//!   ([`crate::control::strategy::pull_off`]); that rise must be at most the 50 µm the
//!   strategy may lift.
//! - **stage**: settled within 0.1 s of a step, `Q/(π f_y) ≤ 0.1 s` (the paper's stage:
//!   25 ms). A stage softer than `20 max(k_y, k_z)` (the paper's is 86 times stiffer than its
//!   lever) is warned about, not refused: it yields under the push, but the pushing model
//!   (Eq 13, the load through the stage's stiffness) predicts that yield, and the dry run judges
//!   the result.
//! - **longest push**: the substrate's slope moves the contact angle by at most 5° a push,
//!   `|slope| · L ≤ 0.087 (Rₐ + Rₜ) cos β`, within [0.2, 20] µm; longer moves are split and
//!   each leg re-parks.
//! - **time-out**: three times the longest phase (the longest push at V, the approach from
//!   twice the start height), within [120, 600] s.
//!
//! Each angle whose predicted push passes these checks gets its settings and a **dry run**: the
//! whole strategy (local scan, park, search, push, retract, scan after, corrections) on the
//! scene's model with another noise and roughness realization, a push of the longest leg the
//! plan allows (within [0.3, 1] µm) up the substrate's slope and one down it, each judged like a
//! real one. The first angle whose dry run
//! ends `ok` is the plan; the checks say why a scene fails in the model's terms, the dry run
//! catches what they do not (a true peak above twice the model's, a particle lost in the noise).
//!
//! A value the scene gives by hand ([`crate::scene::hand_set`]) wins; when it fails a check, the
//! plan warns. When no derived strategy can pass, the plan is refused, naming the field to
//! change and the value it would need ([`Refusal`]).

mod adhesion_field;
mod choice;
mod dry_run;
#[cfg(test)]
mod tests;

pub use choice::{Choice, DerivedStrategy, Refusal, short};

use crate::control::estimator::{PushPrediction, RetractPlan, predict_with_set_fraction};
use crate::control::moves::locate::{LOCAL_PIXELS, local_scan_size};
use crate::control::strategy::pull_off::{PULL_OFF_MARGIN, PULL_OFF_SLACK, pull_off_rise};
use crate::control::strategy::{BACK_OFF, HOLD};
use crate::scene::Scene;
use crate::scene::file::{ParticleFile, StrategyFile};
use adhesion_field::{Pair, field as adhesion_field};

/// The default tolerance of a push (m): `ok` within [`nanopush_proto::push::TOLERANCE_NM`] of
/// the target.
pub const DEFAULT_TOLERANCE: f64 = nanopush_proto::push::TOLERANCE_NM * 1e-9;

/// The set point as a fraction of the stick-phase peak deflection.
pub const SET_FRACTION: f64 = 0.6;

/// Contact angles tried, in order (degrees): the paper's 30° first.
pub const BETAS_DEG: [f64; 8] = [30.0, 45.0, 20.0, 60.0, 15.0, 70.0, 10.0, 80.0];

/// Below this many times the lever's stiffness the stage's yield under the push is warned about.
pub const STAGE_STIFFNESS_RATIO: f64 = 20.0;

/// The stage's ringing must die within this (s): the paper's stage (250 Hz, Q = 20) takes 25 ms.
pub const STAGE_SETTLE: f64 = 0.1;

/// The longest a derived phase time-out may be (s): a slower push fails with a time-out.
pub const MAX_TIMEOUT: f64 = 600.0;

/// The longest simulated time a dry run may take (s): a slower plan is not dry-run (and says so).
pub const MAX_DRY_RUN: f64 = 60.0;

/// Highest start height the scene allows (m), `strategy.start_height_um`'s upper bound.
const MAX_START: f64 = crate::scene::START_HEIGHT_UM.hi() * 1e-6;

/// The paper's stage speed (m/s), the plan's upper bound.
const PAPER_SPEED: f64 = 1e-6;
/// The most the tip may press into the substrate before the reading shows the touch (m).
const TOUCH_PRESS: f64 = 10e-9;
/// The stiffest lever a scene allows (N/m).
const MAX_STIFFNESS: f64 = crate::scene::STIFFNESS_N_PER_M.hi();

/// Control tick (s).
const TICK: f64 = 1e-3;

/// The readout must hold this many times the model's stick-phase peak: the instrument's peak
/// exceeds the model's where its contact angle or its substrate differ a little.
const PEAK_SPARE: f64 = 2.0;

/// The readout as the plan sees it (V).
#[derive(Debug, Clone, Copy)]
struct Readout {
    /// |gain| (V/m).
    gain: f64,
    /// Sign of the gain: which way a push moves the reading.
    sign: f64,
    baseline: f64,
    /// Noise RMS (V).
    sigma: f64,
    /// Periodic perturbation amplitude (V).
    pert: f64,
    /// From the baseline to the rail on the push side (V).
    room: f64,
}

impl Readout {
    fn of(scene: &Scene) -> Readout {
        let s = &scene.file.sensor;
        let sign = s.gain_v_per_nm.signum();
        Readout {
            gain: s.gain_v_per_nm.abs() * 1e9,
            sign,
            baseline: s.baseline_v,
            sigma: s.noise_rms_mv * 1e-3,
            pert: s.perturbation_mv * 1e-3,
            room: s.full_scale_v - sign * s.baseline_v,
        }
    }

    /// The reading of a deflection (V).
    fn volts(&self, deflection: f64) -> f64 {
        self.baseline + self.sign * self.gain * deflection
    }
}

/// What a predicted push at one β says of the strategy: the numbers the settings derive from.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    beta_deg: f64,
    parking: f64,
    prediction: PushPrediction,
}

/// Why a candidate fails, before it is a [`Refusal`].
struct Fails {
    code: &'static str,
    reason: String,
    field: String,
}

/// Derives the strategy for pushing particle `id` of `scene` to within `tolerance` (m).
pub fn derive(scene: &Scene, id: u32, tolerance: f64) -> Result<DerivedStrategy, Refusal> {
    Derivation::new(scene, id, tolerance)?.run()
}

struct Derivation<'a> {
    scene: &'a Scene,
    part: &'a ParticleFile,
    tolerance: f64,
    readout: Readout,
    file: StrategyFile,
    choices: Vec<Choice>,
    warnings: Vec<String>,
}

impl<'a> Derivation<'a> {
    fn new(scene: &'a Scene, id: u32, tolerance: f64) -> Result<Derivation<'a>, Refusal> {
        let part = scene
            .file
            .particles
            .iter()
            .find(|p| p.id == id)
            .ok_or_else(|| Refusal {
                particle: id,
                code: "geometry",
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
        })
    }

    fn hand(&self, key: &str) -> bool {
        self.scene.hand_set.contains(key)
    }

    fn refuse(&self, fails: Fails) -> Refusal {
        Refusal {
            particle: self.part.id,
            code: fails.code,
            reason: fails.reason,
            field: fails.field,
        }
    }

    /// Records a choice: the hand-set value when there is one (warned about if `check` says it
    /// cannot work), else the derived one. Returns the value in force.
    fn choose(&mut self, key: &'static str, hand_value: f64, derived: f64, why: String, check: Option<String>) -> f64 {
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
            format!("given by the scene; derived would be {}: {why}", short(derived))
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

    fn run(mut self) -> Result<DerivedStrategy, Refusal> {
        // A model no push can run (dynamic degrees of freedom) is refused before anything is
        // derived or dry-run.
        if let Err(e) = self.scene.model_pushable() {
            let text = e.to_string();
            let field = text
                .split("physics.")
                .nth(1)
                .and_then(|r| r.split(" = ").next())
                .map_or("physics".to_string(), |k| format!("physics.{k} = \"quasi_static\""));
            return Err(self.refuse(Fails {
                code: "model",
                reason: text,
                field,
            }));
        }
        let f = &self.scene.file;
        let (r_a, r_t) = (self.part.radius_nm * 1e-9, f.tip.radius_nm * 1e-9);
        let ro = self.readout;

        // Substrate detection during auto-parking.
        let noise = 10.0 * ro.sigma + 2.0 * ro.pert;
        let thr = noise.max(0.03);
        let thr_check = (f.strategy.substrate_threshold_mv * 1e-3 < noise).then(|| {
            format!(
                "within 10σ + 2p = {:.1} mV of the readout's noise: the noise can trip it",
                noise * 1e3
            )
        });
        let thr = self.choose(
            "strategy.substrate_threshold_mv",
            f.strategy.substrate_threshold_mv,
            (thr * 1e3).round(),
            format!(
                "10σ of the readout noise plus twice the perturbation, at least 30 mV: the touch is told from noise (the tip presses {:.2} nm before it is seen)",
                thr / ro.gain * 1e9
            ),
            thr_check,
        ) * 1e-3;
        if thr >= 0.5 * ro.room {
            return Err(self.refuse(Fails {
                code: "unreadable",
                reason: format!(
                    "the substrate threshold {:.0} mV (10σ of the noise) is over half the readout's room {:.2} V on the push side",
                    thr * 1e3,
                    ro.room
                ),
                field: "sensor.noise_rms_mv (lower) or sensor.full_scale_v (higher)".into(),
            }));
        }
        let press = thr / ro.gain;
        if press > TOUCH_PRESS {
            return Err(self.refuse(Fails {
                code: "unreadable",
                reason: format!(
                    "the tip would press {:.1} nm into the substrate before the reading shows it ({:.0} mV at {} V/nm)",
                    press * 1e9,
                    thr * 1e3,
                    short(ro.gain * 1e-9)
                ),
                field: format!(
                    "sensor.gain_v_per_nm: |gain| ≥ {} V/nm",
                    short(thr / TOUCH_PRESS * 1e-9)
                ),
            }));
        }

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
        loop {
            let skip: Vec<f64> = rejected.iter().map(|r| r.0).collect();
            let cand = match self.contact_angle(r_a, r_t, v0, approach_speed, &skip) {
                Ok(c) => c,
                Err(refusal) if rejected.is_empty() => return Err(refusal),
                Err(_) => {
                    let (beta, why, warned) = &rejected[0];
                    let angles: Vec<f64> = rejected.iter().map(|r| r.0).collect();
                    // A hand-set value the plan warned about is the likelier cause.
                    let (hand, field) = match warned.iter().find(|w| w.contains("(hand-set)")) {
                        Some(w) => (
                            format!("; the plan warned: {w}"),
                            w.split(" = ").next().unwrap_or("the hand-set value").to_string(),
                        ),
                        None => (String::new(), dry_run::field_for(why, self.scene)),
                    };
                    return Err(self.refuse(Fails {
                        code: "dry_run",
                        reason: format!(
                            "the strategy passes the model's checks but its dry run on the model fails at every such angle ({angles:?}°); at β = {beta}°: {why}{hand}"
                        ),
                        field,
                    }));
                }
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
            match dry_run::dry_run(self.scene, &plan) {
                Ok(0) => {
                    plan.warnings.push(
                        "no dry run: neither leg of it (up and down the slope, 0.3-1 µm) stays on the stage from this particle"
                            .into(),
                    );
                    return Ok(plan);
                }
                Ok(_) => return Ok(plan),
                Err(why) if self.hand("push.contact_angle_deg") => {
                    plan.warnings
                        .push(format!("the plan's dry run on the model fails: {why}"));
                    return Ok(plan);
                }
                Err(why) => {
                    rejected.push((cand.beta_deg, why, plan.warnings.clone()));
                    self.choices = base_choices.clone();
                    self.warnings = base_warnings.clone();
                }
            }
        }
    }

    /// Every setting that follows from the contact angle's predicted push.
    fn settings(
        &mut self,
        cand: Candidate,
        r_a: f64,
        r_t: f64,
        approach_speed: f64,
    ) -> Result<DerivedStrategy, Refusal> {
        let f = &self.scene.file;
        let ro = self.readout;
        let beta_hand = self.hand("push.contact_angle_deg");
        let why_beta = format!(
            "{}: the parking height {:.1} nm keeps the apex above the substrate, the push bends the lever up to a stick-phase peak of {:.3} nm before t*, and every check below passes",
            if beta_hand {
                "given by the scene".to_string()
            } else {
                format!("the first of {BETAS_DEG:?}° that works")
            },
            cand.parking * 1e9,
            cand.prediction.peak_deflection * 1e9
        );
        self.choices.push(Choice {
            key: "push.contact_angle_deg",
            value: cand.beta_deg,
            hand_set: beta_hand,
            why: why_beta,
        });
        let beta = cand.beta_deg.to_radians();
        let pred = cand.prediction;
        let peak_v = pred.peak_deflection * ro.gain;
        let settled_v = pred.settled_deflection * ro.gain;

        // The set point, the safety limit and "particle lost".
        let set_defl = SET_FRACTION * pred.peak_deflection;
        let set_v = ro.volts(set_defl);
        let hand_set_signal = (f.strategy.set_point_v - ro.baseline) * ro.sign;
        let set_check = if hand_set_signal >= 0.95 * peak_v {
            Some(format!(
                "{:.3} V from the baseline, at or beyond the predicted peak {:.3} V: the search pushes the particle without reaching it",
                hand_set_signal, peak_v
            ))
        } else if hand_set_signal < 5.0 * (ro.sigma + ro.pert) {
            Some(format!(
                "{hand_set_signal:.3} V from the baseline: within 5 × the noise, a false contact"
            ))
        } else {
            None
        };
        self.choose(
            "strategy.set_point_v",
            f.strategy.set_point_v,
            set_v,
            format!(
                "{:.0} % of the stick-phase peak deflection {:.3} nm ({:.3} V from the baseline): reached before the particle moves, {:.0} × the noise",
                SET_FRACTION * 100.0,
                pred.peak_deflection * 1e9,
                peak_v,
                SET_FRACTION * peak_v / (ro.sigma + ro.pert).max(1e-6)
            ),
            set_check,
        );
        let safety = (2.5 * peak_v)
            .max(peak_v + 10.0 * ro.sigma)
            .min(0.9 * ro.room)
            .max(PEAK_SPARE * peak_v);
        let hand_safety = (f.strategy.safety_limit_v - ro.baseline) * ro.sign;
        let safety_check = (hand_safety < 1.1 * peak_v).then(|| {
            format!("{hand_safety:.3} V from the baseline, within 10 % of the predicted peak {peak_v:.3} V: an ordinary push trips it")
        });
        self.choose(
            "strategy.safety_limit_v",
            f.strategy.safety_limit_v,
            ro.baseline + ro.sign * safety,
            format!(
                "2.5 × the peak reading {peak_v:.3} V (or the peak plus 10σ; the instrument's peak exceeds the model's where the snap-in lifts the detected substrate), within 90 % of the readout's {:.2} V on the push side",
                ro.room
            ),
            safety_check,
        );
        let lost = settled_v / 2.0;
        let lost_check = (f.strategy.lost_threshold_mv * 1e-3 >= 0.9 * settled_v).then(|| {
            format!(
                "at or above the settled reading {:.1} mV: an ordinary push looks lost",
                settled_v * 1e3
            )
        });
        self.choose(
            "strategy.lost_threshold_mv",
            f.strategy.lost_threshold_mv,
            (lost * 1e3 * 10.0).round() / 10.0,
            format!(
                "half the settled reading {:.1} mV the model predicts after t*",
                settled_v * 1e3
            ),
            lost_check,
        );

        // The speed: the search must stop between the set point and the peak.
        let window = pred.travel_to_peak - pred.travel_to_deflection.unwrap_or(0.0);
        let v_detect = window.max(1e-12) / (1.5 * TICK);
        let omega = 2.0 * std::f64::consts::PI * f.stage.resonance_hz;
        let v_ring = self.tolerance * omega / 4.0;
        let v = PAPER_SPEED.min(v_detect).min(v_ring);
        let hand_v = f.push.speed_um_per_s * 1e-6;
        let v_check = (hand_v > 1.05 * v_detect.min(v_ring)).then(|| {
            format!(
                "faster than {:.3} µm/s: {}",
                v_detect.min(v_ring) * 1e6,
                if v_detect < v_ring {
                    format!(
                        "the search crosses the {:.2} nm between the set point and the peak in under 1.5 ticks",
                        window * 1e9
                    )
                } else {
                    format!(
                        "the stage rings about V/(2π f_y) at the stop, over a quarter of the {} nm tolerance",
                        crate::nm_text(self.tolerance)
                    )
                }
            )
        });
        let speed_um = self.choose(
            "push.speed_um_per_s",
            hand_v * 1e6,
            round_down(v * 1e6),
            format!(
                "the least of the paper's 1 µm/s, the {:.2} nm from the set point to the peak in 1.5 ticks of 1 ms ({:.3} µm/s), and the tolerance × 2π f_y / 4 ({:.3} µm/s: the stage's ringing at the stop)",
                window * 1e9,
                v_detect * 1e6,
                v_ring * 1e6
            ),
            v_check,
        );
        let v = speed_um * 1e-6;

        // The contact search's geometry, from the local scan that finds the particle.
        let range = f.stage.range_um * 1e-6;
        let scan = local_scan_size(r_a, r_t, range);
        let pitch = scan / LOCAL_PIXELS as f64;
        self.choices.push(Choice {
            key: "local_scan.size_um",
            value: scan * 1e6,
            hand_set: false,
            why: "12 particle radii of substrate to level on, at least 4 µm, at most 32 (Rₐ + Rₜ) (four pixels across the particle's image) and the stage".into(),
        });
        self.choices.push(Choice {
            key: "local_scan.pixels",
            value: LOCAL_PIXELS as f64,
            hand_set: false,
            why: format!(
                "a {:.1} nm pitch: the sphere fit locates the particle to a small fraction of it",
                pitch * 1e9
            ),
        });
        let step = ((r_a + r_t) / 4.0).clamp(5e-9, 100e-9);
        let step = self.choose(
            "strategy.step_um",
            f.strategy.step_um,
            round_nm(step) * 1e6,
            "a quarter of Rₐ + Rₜ within [5, 100] nm (the paper's 0.1 µm for its 1 µm particles)".into(),
            None,
        ) * 1e-6;
        let clearance = (2.0 * (r_a * r_t).sqrt() - (r_a + r_t) * beta.cos()).max(0.0);
        let approach = clearance + 4.0 * pitch + 2.0 * step;
        let approach = self.choose(
            "strategy.approach_distance_um",
            f.strategy.approach_distance_um,
            round_nm(approach) * 1e6,
            format!(
                "{:.0} nm for the tip to touch down beside the particle, 2√(RₐRₜ) − (Rₐ + Rₜ) cos β, plus four local-scan pixels ({:.0} nm) and two steps",
                clearance * 1e9,
                4.0 * pitch * 1e9
            ),
            (f.strategy.approach_distance_um * 1e-6 < clearance).then(|| {
                format!(
                    "the tip touches down on the particle, not beside it: it needs {:.3} µm",
                    clearance * 1e6
                )
            }),
        ) * 1e-6;
        let to_set = pred.travel_to_deflection.unwrap_or(pred.travel_to_peak);
        let search = 2.0 * approach + to_set + 4.0 * step;
        self.choose(
            "strategy.search_range_um",
            f.strategy.search_range_um,
            round_nm(search) * 1e6,
            format!(
                "twice the approach distance, plus the model's {:.1} nm from the touch to the set point, plus four steps",
                to_set * 1e9
            ),
            (f.strategy.search_range_um * 1e-6 < approach + to_set).then(|| "shorter than the approach distance and the travel to the set point".into()),
        );

        // The retraction: high enough to let go, and to clear every particle wherever the tip
        // travels at it: the tip moves at a fixed height, and a tilted substrate rises (or falls,
        // and auto-parking descends at most twice the start height) by the tilt times the
        // distance, at most the stage's diagonal; plus four RMS of roughness.
        let tallest = f.particles.iter().map(|p| 2.0 * p.radius_nm * 1e-9).fold(0.0, f64::max);
        let sub = &f.substrate;
        let slope = sub.tilt_x_mrad.hypot(sub.tilt_y_mrad) * 1e-3;
        let rise = slope * f.stage.range_um * 1e-6 * std::f64::consts::SQRT_2 + 4.0 * sub.roughness_rms_nm * 1e-9;
        let clear = tallest + (0.25 * tallest).max(0.5e-6) + rise;
        let release = pred.release_lift.unwrap_or(0.0);
        let lift_need = cand.parking + BACK_OFF * beta.sin() + 1.25 * release + 0.2e-6;
        let start = clear.max(lift_need);
        if start > MAX_START {
            return Err(self.refuse(Fails {
                code: "too_tall",
                reason: format!(
                    "the retraction needs a start height of {:.1} µm (the tallest particle {:.1} µm, the lift to let go {:.2} µm), above the {} µm allowed",
                    start * 1e6,
                    tallest * 1e6,
                    release * 1e6,
                    MAX_START * 1e6
                ),
                field: format!(
                    "particles[].radius_nm (smaller) or {}",
                    adhesion_field(Pair::TipParticle, &self.scene.push_params_for(self.part).adhesion_ta_sources())
                ),
            }));
        }
        let start_check = (f.strategy.start_height_um * 1e-6 < lift_need).then(|| {
            format!(
                "below the {:.3} µm the tip needs to let go of the particle: it drags the particle back as it lifts",
                lift_need * 1e6
            )
        });
        let start = self.choose(
            "strategy.start_height_um",
            f.strategy.start_height_um,
            (start * 1e7).ceil() / 10.0,
            format!(
                "above the tallest particle ({:.2} µm) by a quarter of it, at least 0.5 µm, plus the substrate's rise over the stage's diagonal and its roughness ({:.3} µm), and above the parking height plus 1.25 × the {:.3} µm the model lifts before the tip lets go",
                tallest * 1e6,
                rise * 1e6,
                release * 1e6
            ),
            start_check,
        ) * 1e-6;

        // Settings the model does not change, said with their reasons.
        let fixed = |s: &mut Self, key: &'static str, value: f64, why: &str| {
            s.choose(key, value, value, why.into(), None);
        };
        fixed(
            self,
            "strategy.approach_speed_um_per_s",
            f.strategy.approach_speed_um_per_s,
            "the z approach and the lift: 1 nm a tick, gentle on the substrate",
        );
        fixed(
            self,
            "strategy.travel_speed_um_per_s",
            f.strategy.travel_speed_um_per_s,
            "moves at the start height, clear of every particle",
        );
        fixed(
            self,
            "strategy.dwell_ms",
            f.strategy.dwell_ms,
            "readings averaged after each search step (the contact is checked every tick regardless)",
        );
        // The substrate's slope changes the contact angle along a push held at one height: at
        // most 5° a leg, `Δz = 0.087 (Rₐ + Rₜ) cos β`; a longer move re-parks for each leg.
        let slope = (f.substrate.tilt_x_mrad.hypot(f.substrate.tilt_y_mrad)) * 1e-3;
        let dz = 5f64.to_radians() * (r_a + r_t) * beta.cos();
        let range = f.stage.range_um * 1e-6;
        let max_push = if slope > 0.0 {
            (dz / slope).clamp(0.2e-6, 20e-6)
        } else {
            20e-6
        }
        .min(range);
        let max_push = self.choose(
            "strategy.max_push_um",
            f.strategy.max_push_um,
            (max_push * 1e8).floor() / 100.0,
            format!(
                "a longer move is planned as several pushes, each re-parked: the substrate's slope {:.1} mrad may change the contact angle by at most 5° a push ({:.1} nm of height), at most 20 µm and the stage's range",
                slope * 1e3,
                dz * 1e9
            ),
            None,
        ) * 1e-6;
        fixed(
            self,
            "strategy.clearance_um",
            f.strategy.clearance_um,
            "kept between the pushed particle and the others when planning",
        );
        fixed(
            self,
            "strategy.z_gain_nm_per_v",
            f.strategy.z_gain_nm_per_v,
            "the z force loop's gain (z and xyz control only)",
        );
        let longest = (max_push / v)
            .max(2.0 * start / approach_speed)
            .max(pull_off_rise(&self.scene.tip_sample()) / approach_speed)
            .max(search / v + search / step * f.strategy.dwell_ms * 1e-3);
        let timeout = (3.0 * longest).clamp(120.0, MAX_TIMEOUT).ceil();
        if longest > MAX_TIMEOUT {
            self.warnings.push(format!(
                "the longest phase would take {longest:.0} s at {} µm/s, more than the {MAX_TIMEOUT:.0} s a phase may: such a push fails with a time-out",
                short(v * 1e6)
            ));
        }
        self.choose(
            "strategy.phase_timeout_s",
            f.strategy.phase_timeout_s,
            timeout,
            format!("three times the longest phase ({longest:.0} s), within [120, {MAX_TIMEOUT:.0}] s"),
            (f.strategy.phase_timeout_s < longest).then(|| format!("shorter than the longest phase, {longest:.0} s")),
        );
        self.tolerance_warnings(&pred, pitch);
        self.file = resolved(self.scene, &self.choices);
        Ok(DerivedStrategy {
            particle: self.part.id,
            tolerance: self.tolerance,
            choices: self.choices.clone(),
            warnings: self.warnings.clone(),
            strategy: self.file.clone(),
            contact_angle_deg: cand.beta_deg,
            speed_um_per_s: speed_um,
            local_scan: (scan, LOCAL_PIXELS),
            prediction: pred,
        })
    }

    /// The tip's pull-off from the substrate after auto-parking: the lever bends the other way
    /// by up to the adhesion over `k_c` as the stage rises, and the strategy rides out a reading
    /// saturated on that side up to [`pull_off_rise`] above the detected substrate. That rise
    /// must be at most what the strategy may lift, [`MAX_START`].
    fn check_pull_off(&mut self) -> Result<(), Refusal> {
        let ts = self.scene.tip_sample();
        let f = &self.scene.file;
        let ro = self.readout;
        let adhesion = ts.adhesion();
        let k_c = ts.k_c;
        let bend = adhesion.max(0.0) / k_c;
        let rise = pull_off_rise(&ts);
        let other_room = f.sensor.full_scale_v + ro.sign * ro.baseline;
        let pull_v = bend * ro.gain;
        if !(rise.is_finite() && rise <= MAX_START) {
            // 1.5 (F/k + r) + slack ≤ MAX: F/k ≤ (MAX − slack)/1.5 − r.
            let rest = ts.release_distance() - bend;
            let room = (MAX_START - PULL_OFF_SLACK) / PULL_OFF_MARGIN - rest;
            return Err(self.refuse(Fails {
                code: "adhesion",
                reason: format!(
                    "the tip's adhesion to the substrate, {:.2} nN, holds it until the {} N/m lever has bent {:.2} µm: letting go after auto-parking needs a rise of up to {:.1} µm (1.5 (F_ad/k_c + L_t + δ_b + a₀) + 10 nm), more than the {} µm the strategy may lift",
                    adhesion * 1e9,
                    short(k_c),
                    bend * 1e6,
                    rise * 1e6,
                    MAX_START * 1e6
                ),
                field: format!(
                    "cantilever.stiffness_n_per_m: k_c ≥ {} N/m, or {}",
                    short(adhesion / room.max(1e-12)),
                    adhesion_field(Pair::TipSubstrate, &ts.adhesion_sources())
                ),
            }));
        }
        let saturates = if pull_v >= other_room {
            format!(
                "the pull-off reads up to {:.1} V, past the {:.2} V of room on that side: the saturated reading is ridden out meanwhile",
                pull_v, other_room
            )
        } else {
            format!(
                "the pull-off reads up to {:.2} V, within the {:.2} V of room on that side",
                pull_v, other_room
            )
        };
        self.choices.push(Choice {
            key: "pull_off.rise_um",
            value: rise * 1e6,
            hand_set: false,
            why: format!(
                "the rise above the detected substrate by which the tip must have let go of it after auto-parking: 1.5 × (the adhesion {:.2} nN over k_c, {:.1} nm, plus the meniscus's rupture gap and a₀) + 10 nm; {saturates}",
                adhesion * 1e9,
                bend * 1e9
            ),
        });
        Ok(())
    }

    /// The stage must settle between the steps: its ringing `Q/(π f_y)` dying within
    /// [`STAGE_SETTLE`]. A stiffness `m (2π f_y)²` under [`STAGE_STIFFNESS_RATIO`] times the
    /// lever's is a warning: the model's Eq 13 carries the push's load through the stage's
    /// stiffness, so the prediction and the dry run see the yield.
    fn check_stage(&mut self) -> Result<(), Refusal> {
        let f = &self.scene.file;
        let st = &f.stage;
        if f.physics.stage == crate::scene::file::DofFile::Off {
            return Ok(());
        }
        let m = st.moving_mass_g * 1e-3;
        let omega = 2.0 * std::f64::consts::PI * st.resonance_hz;
        let k_stage = m * omega * omega;
        let c = self.scene.cantilever();
        let k_lever = c.k_y().max(c.k_z());
        if k_stage < STAGE_STIFFNESS_RATIO * k_lever {
            let need = (STAGE_STIFFNESS_RATIO * k_lever / m).sqrt() / (2.0 * std::f64::consts::PI);
            self.warnings.push(format!(
                "the stage's stiffness m (2π f_y)² = {} N/m is less than {} times the lever's stiffer direction (max(k_y, k_z) = {} N/m, the lateral k_y from the lever's shape): it yields under the push, which the model predicts and the dry run checks; stage.resonance_hz ≥ {} Hz would make it negligible",
                short(k_stage),
                STAGE_STIFFNESS_RATIO,
                short(k_lever),
                short(need)
            ));
        }
        let settle = st.quality_factor / (std::f64::consts::PI * st.resonance_hz);
        if settle > STAGE_SETTLE {
            return Err(self.refuse(Fails {
                code: "stage",
                reason: format!(
                    "the stage rings for Q/(π f_y) = {} s after every step and stop, more than {} s",
                    short(settle),
                    STAGE_SETTLE
                ),
                field: format!(
                    "stage.quality_factor: Q ≤ {} at this resonance, or a higher stage.resonance_hz",
                    short(STAGE_SETTLE * std::f64::consts::PI * st.resonance_hz)
                ),
            }));
        }
        Ok(())
    }

    /// The contact angle: the hand-set one, or the first of [`BETAS_DEG`] whose predicted push
    /// passes [`Derivation::check`].
    fn contact_angle(
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
                reason: "no contact angle left to try".into(),
                field: "push.contact_angle_deg".into(),
            }));
        }
        let mut first_failure: Option<Fails> = None;
        let mut tried = Vec::new();
        // Auto-parking detects the substrate where the tip snaps in (the meniscus, the
        // attraction), this high above it; the tip rises from there to the parking height, and
        // a parking height below it would drive the tip down into the meniscus while the
        // substrate still holds it (the review of issue 24).
        let snap_in = crate::control::strategy::runner::detection_offset(self.scene, &self.scene.strategy_params(TICK));
        for &beta_deg in &betas {
            let beta = beta_deg.to_radians();
            let parking = r_a - r_t + (r_a + r_t) * beta.sin();
            let result = if parking <= 0.05 * r_a {
                Err(Fails {
                    code: "geometry",
                    reason: format!(
                        "at β = {beta_deg}° the parking height Rₐ − Rₜ + (Rₐ + Rₜ) sin β = {:.2} nm leaves the apex within 5 % of Rₐ of the substrate",
                        parking * 1e9
                    ),
                    field: "tip.radius_nm (a sharper tip) or push.contact_angle_deg (steeper)".into(),
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
                    reason: format!(
                        "at β = {beta_deg}° the parking height {:.2} nm is not above the {:.2} nm where the tip snaps in to the substrate: the tip would park where {cause} holds it",
                        parking * 1e9,
                        snap_in * 1e9
                    ),
                    field: format!("{field}{steeper}"),
                })
            } else {
                self.predict_at(beta, parking, v, approach_speed)
                    .and_then(|c| self.check(&c).map(|()| c))
            };
            tried.push(beta_deg);
            match result {
                Ok(c) => return Ok(c),
                Err(f) if hand => {
                    // The hand-set angle wins; its failure is a warning, when the model could
                    // say anything at all.
                    let warning = format!(
                        "push.contact_angle_deg = {beta_deg} (hand-set): {}; change {}",
                        f.reason, f.field
                    );
                    if let Ok(c) = self.predict_at(beta, parking, v, approach_speed)
                        && c.prediction.peak_deflection > 0.0
                    {
                        self.warnings.push(warning);
                        return Ok(c);
                    }
                    return Err(self.refuse(f));
                }
                Err(f) => {
                    if first_failure.is_none() {
                        first_failure = Some(f);
                    }
                }
            }
        }
        let f = first_failure.expect("at least one angle tried");
        Err(self.refuse(Fails {
            reason: format!("{} (and at every other contact angle tried: {tried:?}°)", f.reason),
            ..f
        }))
    }

    fn predict_at(&self, beta: f64, parking: f64, v: f64, approach_speed: f64) -> Result<Candidate, Fails> {
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
        let prediction = predict_with_set_fraction(params, SET_FRACTION, retract).map_err(|e| Fails {
            code: "model",
            reason: format!("the model's push at β = {:.0}° failed: {e}", beta.to_degrees()),
            field: crate::physics::pushing::MODEL_REFUSAL_FIELD.into(),
        })?;
        Ok(Candidate {
            beta_deg: beta.to_degrees().round(),
            parking,
            prediction,
        })
    }

    /// Whether the strategy can work on the predicted push: the reading shows the contact, the
    /// peak fits the readout, `t*` is seen and the tip lets go.
    fn check(&self, c: &Candidate) -> Result<(), Fails> {
        let ro = self.readout;
        let p = &c.prediction;
        let k = self.scene.file.cantilever.stiffness_n_per_m;
        let gain_nm = ro.gain * 1e-9;
        if p.peak_deflection.abs() < 1e-13 && p.settled_deflection.abs() < 1e-13 {
            return Err(Fails {
                code: "no_resistance",
                reason: format!(
                    "at β = {}° the particle offers the tip no resistance: it moves without bending the lever (ζ_z stays below 0.1 pm), so no reading can find or follow it",
                    c.beta_deg
                ),
                field: "friction.particle_substrate_static and friction.tip_particle_static (above 0)".into(),
            });
        }
        if p.peak_deflection <= 0.0 {
            return Err(Fails {
                code: "unreadable",
                reason: format!(
                    "at β = {}° the push bends the lever away from the set point's side (peak ζ_z = {:.3} nm)",
                    c.beta_deg,
                    p.peak_deflection * 1e9
                ),
                field: "push.contact_angle_deg (steeper) or cantilever.tilt_deg".into(),
            });
        }
        // The deflection limit first: a lever that reaches it before the model's push ends
        // cannot push, whether or not the particle would shear loose later.
        let separates = p.travel_to_peak <= 0.75 * p.travel;
        let peak_v = p.peak_deflection * ro.gain;
        if PEAK_SPARE * peak_v > 0.9 * ro.room {
            let need_k = k * PEAK_SPARE * peak_v / (0.9 * ro.room);
            return Err(Fails {
                code: "deflection_limit",
                reason: format!(
                    "at β = {}° the lever's deflection limit is reached before the particle shears: the stick-phase peak {}{:.2} nm reads {:.2} V, and twice that is beyond 90 % of the readout's {:.2} V",
                    c.beta_deg,
                    if separates {
                        ""
                    } else {
                        "(still rising at the end of the model's push) "
                    },
                    p.peak_deflection * 1e9,
                    peak_v,
                    ro.room
                ),
                // Still rising: the figures scale a peak the model has not reached, so they
                // are needed but not known to be enough (the review of issue 24 applied 1.1 × the
                // figure and was asked for 20 times more). A figure outside what a scene allows,
                // or a gain too small for the readout to see the touch or the set point, is
                // said to be no way out rather than offered.
                field: self.deflection_limit_field(p, separates, need_k, peak_v),
            });
        }
        if !separates {
            return Err(Fails {
                code: "no_separation",
                reason: format!(
                    "at β = {}° the particle does not shear loose within {:.0} nm of push (ζ_z still rising at {:.2} nm, {:.2} nN on the lever)",
                    c.beta_deg,
                    0.75 * p.travel * 1e9,
                    p.peak_deflection * 1e9,
                    p.peak_deflection * k * 1e9
                ),
                field: "cantilever.stiffness_n_per_m (stiffer) or friction.particle_substrate_static (lower)".into(),
            });
        }
        let floor = ro.sigma + ro.pert;
        if SET_FRACTION * peak_v < 10.0 * floor {
            return Err(Fails {
                code: "unreadable",
                reason: format!(
                    "at β = {}° the set point, {:.0} % of the peak {:.4} nm, reads {:.1} mV: under 10 × the noise and perturbation ({:.1} mV)",
                    c.beta_deg,
                    SET_FRACTION * 100.0,
                    p.peak_deflection * 1e9,
                    SET_FRACTION * peak_v * 1e3,
                    floor * 1e3
                ),
                field: format!(
                    "sensor.gain_v_per_nm: |gain| ≥ {} V/nm, or a lower sensor.noise_rms_mv",
                    short(gain_nm * 10.0 * floor / (SET_FRACTION * peak_v))
                ),
            });
        }
        let drop_v = (p.peak_deflection - p.settled_deflection) * ro.gain;
        let need_drop = 12.0 * ro.sigma + 2.0 * ro.pert;
        if drop_v < need_drop {
            return Err(Fails {
                code: "unreadable",
                reason: format!(
                    "at β = {}° the drop at t* ({:.3} nm, {:.1} mV) is under 12σ + 2p = {:.1} mV: the separation cannot be told from noise",
                    c.beta_deg,
                    (p.peak_deflection - p.settled_deflection) * 1e9,
                    drop_v * 1e3,
                    need_drop * 1e3
                ),
                field: format!(
                    "sensor.gain_v_per_nm: |gain| ≥ {} V/nm, or a lower sensor.noise_rms_mv",
                    short(gain_nm * need_drop / drop_v.max(1e-12))
                ),
            });
        }
        let settled_v = p.settled_deflection * ro.gain;
        let need_settled = 8.0 * ro.sigma + 2.0 * ro.pert;
        if settled_v < need_settled {
            return Err(Fails {
                code: "unreadable",
                reason: format!(
                    "at β = {}° the settled reading after t* ({:.1} mV) is under 8σ + 2p = {:.1} mV: the push could not be told from a lost particle",
                    c.beta_deg,
                    settled_v * 1e3,
                    need_settled * 1e3
                ),
                field: format!(
                    "sensor.gain_v_per_nm: |gain| ≥ {} V/nm",
                    short(gain_nm * need_settled / settled_v.max(1e-12))
                ),
            });
        }
        if p.release_lift.is_none() {
            return Err(Fails {
                code: "stuck",
                reason: format!(
                    "at β = {}° the tip still holds the particle after a lift to {} µm: the adhesion outlasts any retraction",
                    c.beta_deg,
                    MAX_START * 1e6
                ),
                field: adhesion_field(
                    Pair::TipParticle,
                    &self.scene.push_params_for(self.part).adhesion_ta_sources(),
                ),
            });
        }
        Ok(())
    }

    /// The fields a `deflection_limit` refusal names: a stiffer lever (at most
    /// [`MAX_STIFFNESS`]) or a smaller gain (no smaller than the readout needs to see the touch
    /// of the substrate, [`TOUCH_PRESS`], and the set point, 10 × the noise), each figure "at
    /// the least" when the model's peak was still rising.
    fn deflection_limit_field(&self, p: &PushPrediction, separates: bool, need_k: f64, peak_v: f64) -> String {
        let ro = self.readout;
        let gain_nm = ro.gain * 1e-9;
        let (ge, le, least, least_gain) = if separates {
            ("≥", "≤", "", "")
        } else {
            (
                ">",
                "<",
                " at the least (the model's push had not sheared the particle loose, so no value is known to be enough)",
                " at the least",
            )
        };
        let k_helps = need_k <= MAX_STIFFNESS;
        let stiffer = format!("cantilever.stiffness_n_per_m: k_c {ge} {} N/m needed", short(need_k));
        let k_no = format!("{stiffer}, beyond the {} N/m a scene allows", short(MAX_STIFFNESS));
        let gain_max = gain_nm * 0.9 * ro.room / (PEAK_SPARE * peak_v);
        let threshold = self
            .choices
            .iter()
            .find(|c| c.key == "strategy.substrate_threshold_mv")
            .map_or(0.03, |c| c.value * 1e-3);
        let touch_floor = threshold / (TOUCH_PRESS * 1e9);
        let set_floor = 10.0 * (ro.sigma + ro.pert) / (SET_FRACTION * p.peak_deflection * 1e9);
        let gain_floor = touch_floor.max(set_floor);
        let gain_helps = gain_max >= gain_floor;
        let smaller = format!("|sensor.gain_v_per_nm| {le} {} V/nm", short(gain_max));
        let gain_no = format!(
            "{smaller}, but below {} V/nm the readout does not see the touch of the substrate or the set point",
            short(gain_floor)
        );
        match (k_helps, gain_helps) {
            (true, true) => format!("{stiffer}{least}, or {smaller}{least_gain}"),
            (true, false) => format!("{stiffer}{least} (a smaller gain cannot help: {gain_no})"),
            (false, true) => format!("{smaller}{least} (a stiffer lever cannot help: {k_no})"),
            (false, false) => format!(
                "the particle, its friction or the contact angle: neither a stiffer lever ({k_no}) nor a smaller gain ({gain_no}) can help"
            ),
        }
    }

    /// What the tolerance asks that the instrument may not give: said, not refused (the scan
    /// after the push judges).
    fn tolerance_warnings(&mut self, p: &PushPrediction, pitch: f64) {
        if p.periodic_amplitude > self.tolerance {
            self.warnings.push(format!(
                "the model's push is stick-slip with a {:.1} nm amplitude, more than the {} nm tolerance: pushes may end outside it and be corrected",
                p.periodic_amplitude * 1e9,
                crate::nm_text(self.tolerance)
            ));
        }
        if pitch / 8.0 > self.tolerance {
            self.warnings.push(format!(
                "the local scan's {:.0} nm pitch is coarse for a {} nm tolerance",
                pitch * 1e9,
                crate::nm_text(self.tolerance)
            ));
        }
        let least = crate::control::moves::locate::DONE_WITHIN;
        if self.tolerance < least {
            self.warnings.push(format!(
                "the {} nm tolerance is below the {:.0} nm a push can correct: a move that ends between the two is missed without a correction",
                crate::nm_text(self.tolerance),
                least * 1e9
            ));
        }
    }
}

/// The `[strategy]` in force: the scene's, with every choice's value written in.
fn resolved(scene: &Scene, choices: &[Choice]) -> StrategyFile {
    let mut s = scene.file.strategy.clone();
    for c in choices {
        let v = c.value;
        match c.key {
            "strategy.start_height_um" => s.start_height_um = v,
            "strategy.approach_speed_um_per_s" => s.approach_speed_um_per_s = v,
            "strategy.travel_speed_um_per_s" => s.travel_speed_um_per_s = v,
            "strategy.substrate_threshold_mv" => s.substrate_threshold_mv = v,
            "strategy.step_um" => s.step_um = v,
            "strategy.dwell_ms" => s.dwell_ms = v,
            "strategy.set_point_v" => s.set_point_v = v,
            "strategy.approach_distance_um" => s.approach_distance_um = v,
            "strategy.search_range_um" => s.search_range_um = v,
            "strategy.safety_limit_v" => s.safety_limit_v = v,
            "strategy.lost_threshold_mv" => s.lost_threshold_mv = v,
            "strategy.max_push_um" => s.max_push_um = v,
            "strategy.clearance_um" => s.clearance_um = v,
            "strategy.phase_timeout_s" => s.phase_timeout_s = v,
            "strategy.z_gain_nm_per_v" => s.z_gain_nm_per_v = v,
            _ => {}
        }
    }
    s
}

/// A speed rounded down to three significant digits (µm/s), so the plan prints what it uses.
fn round_down(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return v;
    }
    let scale = 10f64.powi(2 - v.log10().floor() as i32);
    (v * scale).floor() / scale
}

/// A length rounded to the nanometre (m).
fn round_nm(v: f64) -> f64 {
    (v * 1e9).round().max(1.0) * 1e-9
}
