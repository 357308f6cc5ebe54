//! The particle-position feedback `H_xy` of Eq 19 (Sec 3, Fig 6):
//!
//! ```text
//! H_xy = (x_s, y_s)   if t ≤ t*     (the particle has not left its place on the substrate)
//!        (x°, y°)     otherwise     (the settling position, estimated from the model)
//! ```
//!
//! Only the instrument's measurements enter: the stage position and the deflection reading.
//! `t*`, the particle-substrate separation, is the peak of `ζ_z` (detected in real time: the
//! smoothed reading falls from its running maximum by more than a noise-proof margin). After
//! `t*` the particle trails the tip by the settled offset `δ° = s − y` that the pushing model
//! predicts (Fig 7); when the model's motion is periodic (stick-slip) the mean over its period
//! is used, as the paper says. Before `t*` the particle sits where the contact found it (in our
//! frame the tip moves over a fixed substrate, so "the stage position" of the paper, whose stage
//! carries the particle, becomes "no displacement").

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
    let model = PushModel::new(params);
    let run = run_push_within(
        model.clone(),
        Method::Rodas4,
        Options::with_rtol(1e-6),
        duration,
        sample_step(duration),
        PREDICTION_STEPS,
    )?;
    let retraction = predict_retract(model, duration, retract, PREDICTION_STEPS)?;
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
        retract_shift: retraction.shift,
        release_lift: retraction.release_lift,
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
        let p = predict_with(params, duration, retract, side, deflection_of)?;
        if (p.travel_to_peak <= 0.75 * p.travel && p.settled) || travel >= MAX_PREDICTED_TRAVEL {
            return Ok(p);
        }
        travel *= 4.0;
    }
}

/// Samples in the detector's moving mean.
const WINDOW: usize = 4;

/// Real-time detection of `t*` as the peak of the deflection reading.
#[derive(Debug, Clone, PartialEq)]
pub struct PeakDetector {
    window: [f64; WINDOW],
    filled: usize,
    next: usize,
    max: f64,
    max_t: f64,
    margin: f64,
    /// The detected `t*` (s) and the peak reading (deflection side, V).
    pub peak: Option<(f64, f64)>,
}

impl PeakDetector {
    /// A detector that declares the peak once the 4-sample moving mean of the deflection
    /// signal (V, positive = the push's side) falls `margin` (V) below its running maximum.
    pub fn new(margin: f64) -> PeakDetector {
        PeakDetector {
            window: [0.0; WINDOW],
            filled: 0,
            next: 0,
            max: f64::NEG_INFINITY,
            max_t: 0.0,
            margin,
            peak: None,
        }
    }

    /// The moving mean now (V).
    pub fn mean(&self) -> f64 {
        self.window.iter().sum::<f64>() / WINDOW as f64
    }

    /// Feeds one sample; returns `t*` when this sample reveals the peak.
    pub fn feed(&mut self, t: f64, signal: f64) -> Option<f64> {
        if self.peak.is_some() {
            return None;
        }
        if self.filled == 0 {
            // The push starts from the contact search's stop: its level is the first maximum.
            self.window = [signal; WINDOW];
        }
        self.window[self.next] = signal;
        self.next = (self.next + 1) % WINDOW;
        self.filled = (self.filled + 1).min(WINDOW);
        let mean = self.window.iter().sum::<f64>() / self.window.len() as f64;
        if mean > self.max {
            self.max = mean;
            // The moving mean lags the samples by half its window.
            self.max_t = t;
        } else if mean < self.max - self.margin {
            self.peak = Some((self.max_t, self.max));
            return Some(self.max_t);
        }
        None
    }
}

/// The estimator of Eq 19 during one push.
#[derive(Debug, Clone, PartialEq)]
pub struct Hxy {
    /// The model's prediction.
    pub prediction: PushPrediction,
    /// Tip travel from the first touch to where the contact search stopped (m): the model's
    /// travel to the set point.
    pub travel_at_contact: f64,
    /// The `t*` detector.
    pub detector: PeakDetector,
    /// The settled reading the model predicts, as a deflection signal (V).
    pub settled_signal: f64,
}

impl Hxy {
    /// An estimator for a push whose contact search stopped at the set point.
    /// `gain` (V/m, magnitude) turns the model's settled deflection into a reading.
    pub fn new(prediction: PushPrediction, margin: f64, gain: f64) -> Hxy {
        Hxy {
            travel_at_contact: prediction.travel_to_deflection.unwrap_or(0.0),
            settled_signal: prediction.settled_deflection * gain.abs(),
            prediction,
            detector: PeakDetector::new(margin),
        }
    }

    /// Feeds a reading; `travel` is the stage's travel along the push since the contact search
    /// stopped (m). Returns the estimated particle displacement along the push (m): 0 up to `t*`,
    /// then the travel since the first touch less the settled lag `δ°`.
    ///
    /// When the contact search stopped past the peak (a fast search: the whole stick phase fits
    /// in a tick or two), no peak is left to see; then `t*` is taken where the travel since the
    /// touch has passed the model's travel to the peak (plus 10 nm) and the reading has settled
    /// within the margin of the model's settled level.
    pub fn update(&mut self, t: f64, signal: f64, travel: f64) -> f64 {
        if self.detector.feed(t, signal).is_none() && self.detector.peak.is_none() {
            let past_peak = self.travel_at_contact + travel > self.prediction.travel_to_peak + 10e-9;
            let settled = (self.detector.mean() - self.settled_signal).abs() < self.detector.margin;
            if past_peak && settled && self.detector.filled >= WINDOW {
                self.detector.peak = Some((t, signal));
            }
        }
        self.estimate(travel)
    }

    /// The estimated displacement (m) at which the push must stop so that the particle ends
    /// `distance` from its start once the tip has retracted.
    pub fn stop_at(&self, distance: f64) -> f64 {
        distance - self.prediction.retract_shift
    }

    /// The estimate for a travel (m), without feeding a sample.
    pub fn estimate(&self, travel: f64) -> f64 {
        if self.detector.peak.is_none() {
            return 0.0;
        }
        (self.travel_at_contact + travel - self.prediction.settle_offset).max(0.0)
    }

    /// Whether `t*` has been detected.
    pub fn separated(&self) -> bool {
        self.detector.peak.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn peak_detector_finds_the_peak_of_a_noisy_rise_and_fall() {
        // A ramp to 1 V at t = 50 ms, then a drop to 0.5 V, with ±5 mV alternating "noise".
        let mut d = PeakDetector::new(0.05);
        let mut found = None;
        for k in 0..200 {
            let t = k as f64 * 1e-3;
            let s = if k <= 50 { k as f64 / 50.0 } else { 0.5 } + if k % 2 == 0 { 0.005 } else { -0.005 };
            if let Some(ts) = d.feed(t, s) {
                found = Some((k, ts));
                break;
            }
        }
        let (k, ts) = found.expect("peak found");
        // Declared within a window after the drop; t* at the top of the ramp (moving mean).
        assert!((51..=60).contains(&k), "declared at sample {k}");
        assert!((ts - 0.051).abs() <= 0.004, "t* = {ts}");
    }

    /// docs/manipulation.md's `t*` detector ("Manipulation: `nanopush push` (Sec 2.1 strategy,
    /// Sec 3 force control)"): "a 4-sample mean falling [the margin] below its running
    /// maximum". From a level of 1 V with a margin of 0.25 V, one sample 0.99 V lower moves a
    /// 4-sample mean by 0.2475 V (no peak), one 1.01 V lower by 0.2525 V (the peak, dated at the
    /// level's first sample, where the running maximum was first reached); a 3-sample mean would
    /// fire on the first, a 5-sample one on neither.
    #[test]
    fn the_t_star_detector_is_a_short_mean_falling_below_its_maximum() {
        assert_eq!(WINDOW, 4);
        for (drop, fires) in [(0.99, false), (1.01, true)] {
            let mut d = PeakDetector::new(0.25);
            for k in 0..10 {
                assert_eq!(d.feed(k as f64 * 1e-3, 1.0), None);
            }
            assert_eq!(d.feed(10e-3, 1.0 - drop).is_some(), fires, "a drop of {drop} V");
            if fires {
                assert_eq!(d.peak, Some((0.0, 1.0)), "t* at the first sample of the level");
            }
        }
    }

    #[test]
    fn no_peak_on_a_monotone_rise() {
        let mut d = PeakDetector::new(0.05);
        for k in 0..500 {
            assert!(d.feed(k as f64 * 1e-3, k as f64 * 1e-3).is_none());
        }
    }

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

    /// A prediction whose settled reading is 0.5 V at a gain of 5e8 V/m, with its peak 20 nm
    /// after the first touch and the contact search stopped 2 nm after it.
    fn fallback_prediction() -> PushPrediction {
        PushPrediction {
            settle_offset: 1e-9,
            periodic_amplitude: 0.0,
            travel_to_deflection: Some(2e-9),
            peak_deflection: 3e-9,
            travel_to_peak: 20e-9,
            settled_deflection: 1e-9,
            phase: "roll",
            retract_shift: 0.0,
            release_lift: Some(0.0),
            travel: 40e-9,
            side: super::ContactSide::Push,
            settled: true,
        }
    }

    /// A fast contact search that stopped past the peak leaves no peak to see: `t*` is taken
    /// once the travel since the touch is past the model's peak plus 10 nm, the 4-sample mean
    /// is within the margin of the settled level, and the window is full; each part of this
    /// fallback and the detector's mean is checked.
    #[test]
    fn a_search_stopped_past_the_peak_separates_once_settled() {
        let (margin, gain) = (0.05, 5e8);
        // Past the peak from the first sample, at the settled level: the fourth sample fills
        // the window, and only then is t* taken.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        assert_eq!(h.settled_signal, 0.5);
        for k in 0..4 {
            let t = k as f64 * 1e-3;
            let estimate = h.update(t, 0.5, 40e-9);
            assert_eq!(h.separated(), k == 3, "sample {k}");
            if k == 3 {
                assert_eq!(h.detector.peak, Some((t, 0.5)));
                assert_eq!(h.detector.mean(), 0.5);
                assert!((estimate - (2e-9 + 40e-9 - 1e-9)).abs() < 1e-18, "{estimate:e}");
            } else {
                assert_eq!(estimate, 0.0, "no displacement before t*");
            }
        }
        // Settled, travel rising 1 nm a sample from 0.5 nm: 2 + 28.5 nm is the first past
        // 20 + 10 nm.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        let first = (0..60)
            .find(|&k| {
                h.update(k as f64 * 1e-3, 0.5, (k as f64 + 0.5) * 1e-9);
                h.separated()
            })
            .expect("separates");
        assert_eq!(first, 28);
        // Past the peak but not settled (0.1 V off the settled level, twice the margin): no t*.
        let mut h = Hxy::new(fallback_prediction(), margin, gain);
        for k in 0..20 {
            h.update(k as f64 * 1e-3, 0.6, 40e-9);
        }
        assert!(!h.separated(), "0.6 V is not within 0.05 V of 0.5 V");
    }

    /// A peak the detector saw is t*, and later settled samples past the model's peak do not
    /// move it.
    #[test]
    fn a_detected_peak_is_kept_while_the_push_goes_on() {
        let mut h = Hxy::new(fallback_prediction(), 0.05, 5e8);
        for k in 0..4 {
            h.update(k as f64 * 1e-3, 1.0, 0.0);
        }
        assert!(!h.separated());
        h.update(4e-3, 0.5, 40e-9);
        assert_eq!(h.detector.peak, Some((0.0, 1.0)), "the mean fell 0.125 V below 1.0 V");
        for k in 5..20 {
            h.update(k as f64 * 1e-3, 0.5, 40e-9);
        }
        assert_eq!(h.detector.peak, Some((0.0, 1.0)));
        // A fall that lands the (then frozen) mean inside the settled band at once: 3 × 1.0
        // and −0.9 V average 0.525 V, within 0.05 V of 0.5 V, past the model's peak. The
        // fallback must not take t* again (its guard is a conjunction).
        let mut h = Hxy::new(fallback_prediction(), 0.05, 5e8);
        for k in 0..4 {
            h.update(k as f64 * 1e-3, 1.0, 0.0);
        }
        h.update(4e-3, -0.9, 40e-9);
        assert_eq!(h.detector.peak, Some((0.0, 1.0)));
        assert!((h.detector.mean() - 0.525).abs() < 1e-12);
        for k in 5..10 {
            h.update(k as f64 * 1e-3, 0.5, 40e-9);
        }
        assert_eq!(h.detector.peak, Some((0.0, 1.0)), "t* is where the peak was");
    }

    /// "Falls by more than the margin": a mean exactly the margin below the maximum is not yet
    /// the peak.
    #[test]
    fn a_fall_of_exactly_the_margin_is_not_the_peak() {
        let mut d = PeakDetector::new(0.25);
        assert_eq!(d.feed(0.0, 1.0), None);
        for k in 1..=4 {
            // Means 0.9375, 0.875, 0.8125, 0.75: exact in binary.
            assert_eq!(d.feed(k as f64 * 1e-3, 0.75), None, "sample {k}");
        }
        assert_eq!(d.mean(), 0.75);
        assert_eq!(d.feed(5e-3, 0.75), None, "still exactly the margin below");
        assert!(d.feed(6e-3, 0.74).is_some(), "the mean 2.5 mV further down");
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
        let scene = Scene::parse("lab seed 11", include_str!("derive/scenes/lab-seed-11.toml")).unwrap();
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
