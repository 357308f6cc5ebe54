//! What the pushing model predicts for a push at constant speed from the first touch: the
//! stick-phase peak, the travel to it and to the set point, the settled lag and reading, and
//! what the retraction does to the particle. The estimator of Eq 19 and the plan derive their
//! constants from it.

use crate::numerics::integrate::{Method, Options};
use crate::physics::pushing::trace::{TraceRow, run_push_within};
use crate::physics::pushing::{Advance, PushModel, PushParams, Simulation, SimulationError};

/// What the model predicts for a push at constant speed, for the estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushPrediction {
    /// Settled lag of the particle behind the tip's travel, `δ° = s − y` (m), mean over the
    /// settled tail.
    pub settle_offset: f64,
    /// Peak-to-peak of `s − y` over the tail (m): 0 for a steady push, the stick-slip amplitude
    /// for a periodic one.
    pub periodic_amplitude: f64,
    /// Tip travel from the first touch until `ζ_z` reaches `deflection` (m).
    pub travel_to_deflection: Option<f64>,
    /// Peak `ζ_z` before the separation (m).
    pub peak_deflection: f64,
    /// Tip travel from the first touch to the peak of `ζ_z`, the separation `t*` (m).
    pub travel_to_peak: f64,
    /// Settled mean `ζ_z` (m).
    pub settled_deflection: f64,
    /// Friction phase at the end (`slip`, `roll`, `stick`).
    pub phase: &'static str,
    /// Tip travel of the model push (m).
    pub travel: f64,
    /// Particle displacement along the push while the tip stops, backs off and lifts (m).
    pub retract_shift: f64,
    /// Height the tip had to lift (after the back-off) before it let go of the particle (m);
    /// `None` when it still held the particle at the end of the strategy's lift
    /// ([`RetractPlan::lift`]).
    pub release_lift: Option<f64>,
    /// The side of the lever the deflections above are read on: `ζ_z` itself on the push side,
    /// `−ζ_z` on the pull side.
    pub side: ContactSide,
    /// Whether the push had settled by its end ([`settled`]): the settled constants above hold
    /// for a longer push only then.
    pub settled: bool,
}

/// Which way the contact bends the lever, and so which side of the baseline the strategy reads
/// the contact on: the set point, the safety limit, the peak at `t*` and the lost threshold are
/// all taken as distances from the baseline on this side.
///
/// A push normally bends the lever toward the push side (`ζ_z > 0`: the contact's vertical load
/// lifts the tip). On a tilted lever with a low contact angle and little tip-particle friction,
/// the lateral load's moment about the lever's base outweighs it and the push bends the lever
/// the other way, toward the side the substrate's adhesion pulls it; such a push is read on the
/// pull side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactSide {
    /// `ζ_z > 0`: the reading moves with the gain's sign.
    Push,
    /// `ζ_z < 0`: the reading moves against it.
    Pull,
}

impl ContactSide {
    /// `+1` on the push side, `−1` on the pull side: the factor that turns `ζ_z` (or a
    /// push-side signal) into a distance from the baseline on this side.
    pub fn sign(self) -> f64 {
        match self {
            ContactSide::Push => 1.0,
            ContactSide::Pull => -1.0,
        }
    }

    /// The side a signed `ζ_z` (or push-side signal) lies on (zero: the push side).
    pub fn of(deflection: f64) -> ContactSide {
        if deflection < 0.0 {
            ContactSide::Pull
        } else {
            ContactSide::Push
        }
    }

    /// `push` or `pull`, for the plan's words.
    pub fn name(self) -> &'static str {
        match self {
            ContactSide::Push => "push",
            ContactSide::Pull => "pull",
        }
    }
}

/// Samples of the model push the estimator reads its constants from, whatever the push's
/// duration: a slow stage lengthens the push, never the trace (10 pm of travel per sample over
/// the 40 nm the prediction runs, 160 pm over the longest, 640 nm).
pub const PREDICTION_SAMPLES: f64 = 4000.0;

/// Integrator steps a prediction may take (push and retraction each): the default scene needs
/// ~10³, the stiffest valid scenes ~10⁵; 2·10⁶ is ~10 s of work on one core.
pub const PREDICTION_STEPS: u64 = 2_000_000;

/// The sampling step of a prediction of `duration` (s): 0.1 ms, or longer so that there are
/// at most [`PREDICTION_SAMPLES`].
fn sample_step(duration: f64) -> f64 {
    (duration / PREDICTION_SAMPLES).max(1e-4)
}

/// What the retraction does to the particle: how far it moves it along the push (m), and the
/// lift at which the tip let go (m; `None` if it never did within the plan's lift).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Retraction {
    shift: f64,
    release_lift: Option<f64>,
}

/// The retraction part of [`predict`]: the push again for `duration` (s), then the stop, the
/// back-off and the lift of `plan`, lifted until the tip lets go or the strategy's whole lift
/// ([`RetractPlan::lift`]) is done: a large particle under a wet meniscus holds the tip for
/// micrometres, `(Rₐ + Rₜ)(1 − sin β)` and more, and rolls back with it all the way. Fails with
/// [`SimulationError::Budget`] once the integrator has taken more than `budget` steps
/// ([`PREDICTION_STEPS`] in [`predict`]).
fn predict_retract(
    model: PushModel,
    duration: f64,
    plan: RetractPlan,
    budget: u64,
) -> Result<Retraction, SimulationError> {
    let beta = model.p.beta;
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    let over = |sim: &Simulation| {
        (sim.total.steps > budget).then_some(SimulationError::Budget {
            what: "integrator steps",
            limit: budget,
            t: sim.t,
        })
    };
    // In the prediction's sample steps, so that the step budget is checked while the push
    // runs, not after.
    let pieces = (duration / sample_step(duration)).round().max(1.0) as u32;
    for k in 1..=pieces {
        sim.advance_to(duration * f64::from(k) / f64::from(pieces))?;
        if let Some(e) = over(&sim) {
            return Err(e);
        }
    }
    let y_of = |sim: &Simulation| sim.x[sim.model.layout.particle_y.pos];
    let y0 = y_of(&sim);
    let (sb, cb) = beta.sin_cos();
    let tick = 1e-3;
    let mut t = duration;
    // Stop: the reference halts where it is.
    let (mut yr, mut zr) = (sim.model.drive.y_at(t), sim.model.drive.z_at(t));
    let hold_end = t + plan.hold;
    let back_end = hold_end + plan.back_off / plan.speed;
    // Lift until released, at most the strategy's lift.
    let lift_end = back_end + plan.lift / plan.speed;
    let mut release_lift = None;
    while t < lift_end {
        let t1 = t + tick;
        if t1 > hold_end {
            let dt = t1 - t.max(hold_end);
            if t1 <= back_end {
                yr -= cb * plan.speed * dt;
                zr += sb * plan.speed * dt;
            } else {
                zr += plan.speed * dt;
            }
        }
        let drive = sim.model.drive.ramp_to(t, t1, yr, zr);
        sim.set_drive(drive);
        if sim.advance_or_release(t1)? == Advance::Released {
            release_lift = Some(((t1 - back_end) * plan.speed).max(0.0));
            break;
        }
        if let Some(e) = over(&sim) {
            return Err(e);
        }
        t = t1;
    }
    Ok(Retraction {
        shift: y_of(&sim) - y0,
        release_lift,
    })
}

/// How the strategy ends a push (D → E), for the model to predict what it does to the particle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetractPlan {
    /// Dwell with the stage stopped (s).
    pub hold: f64,
    /// Back-off distance along the line of centres (m).
    pub back_off: f64,
    /// Speed of the back-off and the lift (m/s).
    pub speed: f64,
    /// How high the strategy lifts the tip after the back-off (m): from the parking height to
    /// the start height.
    pub lift: f64,
}

/// Runs the pushing model from the first touch at the push speed for `duration` (s) and
/// extracts the estimator's constants; `deflection` is the set point's `ζ_z` (m). Then, from
/// that settled push, it stops, backs off and lifts the tip as `retract` says until the tip lets
/// go, and reports how far that moved the particle: a free rolling particle follows an adhesive
/// tip until the pull-off, and xy-position control pushes that much further (or less).
pub fn predict(
    params: PushParams,
    duration: f64,
    deflection: f64,
    retract: RetractPlan,
) -> Result<PushPrediction, SimulationError> {
    let side = ContactSide::of(deflection);
    predict_with(params, duration, retract, side, |_| deflection * side.sign())
}

/// [`predict`] with the set point's `ζ_z` given as a function of the push's own stick-phase peak
/// (`deflection_of(ζ_peak)`), so one model push serves a plan that sets its set point from the
/// peak (it was run twice, the second time only to read the travel to the set point). Every
/// deflection is read on `side`.
fn predict_with(
    params: PushParams,
    duration: f64,
    retract: RetractPlan,
    side: ContactSide,
    deflection_of: impl Fn(f64) -> f64,
) -> Result<PushPrediction, SimulationError> {
    let push = predict_push(params, duration, side, deflection_of)?;
    with_retraction(push, params, duration, retract)
}

/// What the retraction after `push` (the model's push for `duration`) does to the particle,
/// added to it.
fn with_retraction(
    mut push: PushPrediction,
    params: PushParams,
    duration: f64,
    retract: RetractPlan,
) -> Result<PushPrediction, SimulationError> {
    let retraction = predict_retract(PushModel::new(params), duration, retract, PREDICTION_STEPS)?;
    push.retract_shift = retraction.shift;
    push.release_lift = retraction.release_lift;
    Ok(push)
}

/// [`predict_with`]'s push alone, its retraction's fields not yet predicted (no shift, no
/// release): what [`past_separation`] judges a push's length by before it predicts the
/// retraction of the one it keeps.
fn predict_push(
    params: PushParams,
    duration: f64,
    side: ContactSide,
    deflection_of: impl Fn(f64) -> f64,
) -> Result<PushPrediction, SimulationError> {
    let run = run_push_within(
        PushModel::new(params),
        Method::Rodas4,
        Options::with_rtol(1e-6),
        duration,
        sample_step(duration),
        PREDICTION_STEPS,
    )?;
    let n = run.trace.len();
    let tail = &run.trace[n / 2..];
    let lag = |r: &TraceRow| r.stage_y - r.particle_y;
    let mean = tail.iter().map(lag).sum::<f64>() / tail.len() as f64;
    let (lo, hi) = tail
        .iter()
        .map(lag)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    // The trace as the reading on `side` sees it: (ζ_z on that side, tip travel).
    let on_side: Vec<(f64, f64)> = run.trace.iter().map(|r| (side.sign() * r.zeta_z, r.stage_y)).collect();
    let highest = *on_side
        .iter()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .expect("a push trace has rows");
    let (peak, travel_to_peak) = first_peak(&on_side, highest.0).unwrap_or(highest);
    let deflection = deflection_of(peak);
    let travel_to_deflection = on_side.iter().find(|r| r.0 >= deflection).map(|r| r.1);
    let settled = side.sign() * tail.iter().map(|r| r.zeta_z).sum::<f64>() / tail.len() as f64;
    let steady = self::settled(tail, peak.abs().max(highest.0.abs()));
    Ok(PushPrediction {
        retract_shift: 0.0,
        release_lift: None,
        settle_offset: mean,
        periodic_amplitude: hi - lo,
        travel_to_deflection,
        peak_deflection: peak,
        travel_to_peak,
        settled_deflection: settled,
        phase: run.final_phase,
        travel: duration * params.speed,
        side,
        settled: steady,
    })
}

/// Whether the second half of a push (`tail`) has settled: the means of its two halves differ
/// by at most a tenth of `peak` in `ζ_z` and by at most a tenth of the lag (at least 2 nm) in
/// the lag `s − y`. A particle that rolls under a tip that sticks to it moves at
/// `1/(1 + sin β)` of the tip's speed: its lag grows the whole time, and its `ζ_z` falls as the
/// contact turns over the top, until it rolls ahead at the tip's speed with no load on the lever
/// (lab campaign seed 11, β = 70°: the lag grows to 87 nm and `ζ_z` falls from 4.9 nm to
/// −0.09 nm over 175 nm of travel). Its constants are those of the end, not a mean over the growth.
fn settled(tail: &[TraceRow], peak: f64) -> bool {
    let half = tail.len() / 2;
    if half == 0 {
        return true;
    }
    let mean = |rows: &[TraceRow], f: fn(&TraceRow) -> f64| rows.iter().map(f).sum::<f64>() / rows.len() as f64;
    let (early, late) = tail.split_at(half);
    let zeta: fn(&TraceRow) -> f64 = |r| r.zeta_z;
    let lag: fn(&TraceRow) -> f64 = |r| r.stage_y - r.particle_y;
    let (lag_early, lag_late) = (mean(early, lag), mean(late, lag));
    (mean(late, zeta) - mean(early, zeta)).abs() <= 0.1 * peak
        && (lag_late - lag_early).abs() <= (0.1 * lag_late.abs()).max(2e-9)
}

/// The stick-phase peak of a model push, from its `(ζ_z, travel)` samples on the side it is read
/// on: the running maximum of `ζ_z` where `ζ_z` first falls below it by a tenth of the push's
/// highest `ζ_z` (the first slip, `t*`). A stick-slip push rises again, sometimes higher; the
/// search and the `t*` detector meet the first peak. `None` when the push never drops that much.
fn first_peak(trace: &[(f64, f64)], highest: f64) -> Option<(f64, f64)> {
    let mut best = *trace.first()?;
    for &r in trace {
        if r.0 > best.0 {
            best = r;
        } else if best.0 - r.0 > 0.1 * highest {
            return Some(best);
        }
    }
    None
}

/// Tip travel of the first model push [`predict_past_separation`] runs (m).
pub const PREDICTED_TRAVEL: f64 = 40e-9;

/// Tip travel of its longest model push (m).
pub const MAX_PREDICTED_TRAVEL: f64 = 640e-9;

/// [`predict`] over a push long enough to pass the separation: 40 nm of travel (at least
/// 20 ms), four times longer while the peak of `ζ_z` lies in the last quarter of the push, at
/// most 640 nm. A soft lever bends tens of nm (its peak deflection, `F_shear / k_c`) before the
/// particle shears loose; the settled constants are read from the push's second half, after
/// the peak.
pub fn predict_past_separation(
    params: PushParams,
    deflection: f64,
    retract: RetractPlan,
) -> Result<PushPrediction, SimulationError> {
    let side = ContactSide::of(deflection);
    past_separation(params, retract, side, |_| deflection * side.sign())
}

/// [`predict_past_separation`] with the set point at `fraction` of the push's stick-phase peak
/// (none when the peak is not on the side it is read on), every deflection read on `side`: what
/// the strategy's plan derives its set point from, in the same model pushes.
pub fn predict_with_set_fraction(
    params: PushParams,
    side: ContactSide,
    fraction: f64,
    retract: RetractPlan,
) -> Result<PushPrediction, SimulationError> {
    past_separation(params, retract, side, |peak| {
        if peak > 0.0 { fraction * peak } else { f64::INFINITY }
    })
}

fn past_separation(
    params: PushParams,
    retract: RetractPlan,
    side: ContactSide,
    deflection_of: impl Fn(f64) -> f64 + Copy,
) -> Result<PushPrediction, SimulationError> {
    let mut travel = PREDICTED_TRAVEL;
    loop {
        let duration = (travel / params.speed).max(0.02);
        let p = predict_push(params, duration, side, deflection_of)?;
        if (p.travel_to_peak <= 0.75 * p.travel && p.settled) || travel >= MAX_PREDICTED_TRAVEL {
            // Only the push kept gets its retraction.
            return with_retraction(p, params, duration, retract);
        }
        travel *= 4.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// The retraction's step budget is checked while the push runs, as `steps ≥ budget`: the
    /// steps pass any budget between two checks.
    #[test]
    fn the_retraction_stops_at_its_step_budget_and_names_it() {
        let plan = RetractPlan {
            hold: 0.05,
            back_off: 100e-9,
            speed: 1e-6,
            lift: 2e-6,
        };
        let model = || PushModel::new(Scene::default_scene().push_params());
        let r = predict_retract(model(), 0.05, plan, PREDICTION_STEPS).expect("within the budget");
        assert!(r.shift.is_finite());
        // Every budget is met, also those the steps jump over between two checks.
        for budget in 1..=300 {
            match predict_retract(model(), 0.05, plan, budget) {
                Err(SimulationError::Budget { what, limit, t }) => {
                    assert_eq!((what, limit), ("integrator steps", budget));
                    assert!(t < 0.05, "caught during the push, at t = {t} s");
                }
                other => panic!("a budget of {budget} steps: {other:?}"),
            }
        }
    }

    /// The stick-phase peak is the first one a tenth of the highest below which `ζ_z` falls: a
    /// stick-slip push that rises higher later keeps its first peak; a steady push that settles
    /// less than that below its maximum has none (the maximum is taken).
    #[test]
    fn the_stick_phase_peak_is_the_first_slip_not_the_highest() {
        let trace = |z: &[f64]| z.iter().enumerate().map(|(i, &z)| (z, i as f64)).collect::<Vec<_>>();
        let slip = trace(&[0.0, 1.0, 2.0, 3.0, 2.5, 4.0, 2.0]);
        assert_eq!(super::first_peak(&slip, 4.0).map(|r| r.1), Some(3.0));
        let steady = trace(&[0.0, 1.0, 2.0, 1.95, 1.9, 1.9]);
        assert_eq!(super::first_peak(&steady, 2.0), None);
    }

    #[test]
    fn the_model_prediction_of_the_default_push() {
        // Default scene: the particle rolls once the tip contact slips (about 5 ms at 1 µm/s);
        // from then on it trails the tip by a constant lag.
        let scene = Scene::default_scene();
        let plan = RetractPlan {
            hold: 0.05,
            back_off: 100e-9,
            speed: 1e-6,
            lift: 2e-6,
        };
        let p = predict(scene.push_params(), 0.05, 1.0e-9, plan).unwrap();
        assert_eq!(p.phase, "roll");
        assert!(
            p.periodic_amplitude < 1e-10,
            "steady, not periodic: {:e}",
            p.periodic_amplitude
        );
        // Fig 7's settled lag, 0.669 nm, to its printed digits.
        assert!(
            (p.settle_offset - 0.669e-9).abs() < 0.002e-9,
            "δ° = {:e}",
            p.settle_offset
        );
        assert!(p.peak_deflection > p.settled_deflection);
        let s = p.travel_to_deflection.unwrap();
        assert!(s > 0.0 && s < p.settle_offset + 5e-9, "travel to 1 nm: {s:e}");
    }

    /// Lab campaign seed 11 at β = 70° (a 115 nm particle under an 11 nm tip, both frictions
    /// near 0.9): the particle rolls under the tip, which sticks to it, at 1/(1 + sin β) of its
    /// speed while the contact turns over the top (`ζ_z` peaks at 4.89 nm after 85 nm of travel,
    /// then falls), until, after 175 nm, it rolls on in front of the tip at its speed with no
    /// load on the lever. The 160 nm push has its peak early enough but has not settled; the
    /// prediction runs on to 640 nm and gives the rolling push's constants: a lag of 86.6 nm
    /// (58.6 nm as the mean over 80-160 nm) and a settled `ζ_z` of −0.09 nm (3.72 nm as that mean).
    #[test]
    fn a_particle_rolling_under_the_tip_is_predicted_once_it_has_settled() {
        let scene = Scene::parse("lab seed 11", include_str!("../derive/scenes/lab-seed-11.toml")).unwrap();
        let mut params = scene.push_params();
        params.beta = 70f64.to_radians();
        params.speed = 1e-6;
        let plan = RetractPlan {
            hold: 0.05,
            back_off: 100e-9,
            speed: 1e-6,
            lift: 2e-6,
        };
        let short = predict_with(params, 0.16, plan, ContactSide::Push, |peak| 0.6 * peak).unwrap();
        assert!(short.travel_to_peak <= 0.75 * short.travel, "{short:?}");
        assert!(!short.settled, "{short:?}");
        assert!((short.peak_deflection / 1e-9 - 4.89).abs() < 0.01, "{short:?}");
        let p = predict_with_set_fraction(params, ContactSide::Push, 0.6, plan).unwrap();
        assert!(p.settled, "{p:?}");
        assert_eq!(p.phase, "roll");
        assert!((p.travel / 1e-9 - 640.0).abs() < 1e-6, "{p:?}");
        assert!((p.peak_deflection / 1e-9 - 4.89).abs() < 0.01, "{p:?}");
        assert!((p.settle_offset / 1e-9 - 86.6).abs() < 0.1, "lag {:e}", p.settle_offset);
        assert!(
            (p.settled_deflection / 1e-9 + 0.09).abs() < 0.01,
            "ζ° {:e}",
            p.settled_deflection
        );
        assert!((short.settle_offset / 1e-9 - 58.6).abs() < 0.1, "{short:?}");
        assert!((short.settled_deflection / 1e-9 - 3.72).abs() < 0.01, "{short:?}");
    }
}
