//! Runs the strategy against the simulated instrument tick by tick, recording a trace: what
//! `nanopush push` does, and what the server's loop will do one tick at a time.

use crate::afm::{Afm, AfmError};
use crate::control::estimator::{ContactSide, Hxy, PushPrediction, RetractPlan, predict_past_separation};
use crate::control::moves::locate::DONE_WITHIN;
use crate::control::route::{Leg, travel_on_stage};
use crate::control::strategy::{BACK_OFF, Control, HOLD, PushTask, Strategy, StrategyParams, Summary};
use crate::physics::pushing::SimulationError;
use crate::scene::Scene;
use crate::scene::file::ControlFile;

/// One tick of a strategy run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunRow {
    /// Time (s).
    pub t: f64,
    /// Phase name.
    pub phase: &'static str,
    /// Stage position (m).
    pub stage: [f64; 3],
    /// Reading (V).
    pub volts: f64,
    /// The controller's estimate of the particle's displacement along the push (m).
    pub estimate: f64,
    /// Hidden: the pushed particle's true centre (m), for comparison only.
    pub particle: (f64, f64),
    /// Hidden: friction phase of the push model, or `free`.
    pub contact: &'static str,
}

/// A finished strategy run.
#[derive(Debug, Clone, PartialEq)]
pub struct StrategyRun {
    /// The strategy's own account.
    pub summary: Summary,
    /// The model's prediction the estimator used.
    pub prediction: PushPrediction,
    /// Every tick.
    pub trace: Vec<RunRow>,
    /// The task.
    pub task: PushTask,
    /// Hidden: the particle's true centre before and after (m).
    pub particle_before: (f64, f64),
    /// Hidden: after.
    pub particle_after: (f64, f64),
    /// The tip's final stage position (m).
    pub final_stage: [f64; 3],
    /// Whether the tip ended retracted (off every surface).
    pub retracted: bool,
}

impl StrategyRun {
    /// True displacement of the particle along the push direction (m).
    pub fn true_distance(&self) -> f64 {
        self.along(self.particle_after)
    }

    fn along(&self, p: (f64, f64)) -> f64 {
        let d = self.task.direction;
        (p.0 - self.particle_before.0) * d.0 + (p.1 - self.particle_before.1) * d.1
    }

    /// True displacement along the push before the push phase began, during the approach and
    /// the contact search (m): what the search pushed the particle without the reading
    /// reaching `ζ_set` (a stiff lever, a fast stage, a particle with little friction).
    pub fn search_distance(&self) -> f64 {
        // The rows before the first of the push phase (all of them when it never began).
        let n = self
            .trace
            .iter()
            .position(|r| r.phase == "push")
            .unwrap_or(self.trace.len());
        self.trace[..n].last().map_or(0.0, |r| self.along(r.particle))
    }

    /// The outcome in words: the failure, and what the search pushed when it pushed more than
    /// 10 nm without finding the contact.
    pub fn failure_text(&self) -> Option<String> {
        let f = self.summary.failure.as_ref()?;
        let moved = self.search_distance();
        Some(if self.summary.contact_step.is_none() && moved.abs() > 10e-9 {
            format!(
                "{f}; meanwhile the search pushed the particle {:.3} µm: the reading never reached ζ_set while pushing it",
                moved * 1e6
            )
        } else {
            f.to_string()
        })
    }
}

/// Why a run could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RunError {
    /// The instrument simulation failed.
    #[error(transparent)]
    Afm(#[from] AfmError),
    /// The model prediction for the estimator failed. (Not a `source`: the message carries
    /// the cause once, with the scene fields that drive the model.)
    #[error("model prediction for the estimator failed: {0} ({fields})", fields = crate::physics::pushing::MODEL_FIELDS)]
    Predict(SimulationError),
    /// The run exceeded its tick budget (a bug: every phase has a time-out).
    #[error("the run did not finish within {0} ticks")]
    Budget(u64),
    /// No such particle in the instrument.
    #[error("no particle with id {0}")]
    NoParticle(u32),
    /// The scene cannot be pushed: its model is too stiff for real time, or the strategy's
    /// geometry does not fit its particles (see [`Scene::pushable`]).
    #[error("{0}")]
    NotPushable(String),
}

impl From<SimulationError> for RunError {
    fn from(e: SimulationError) -> RunError {
        RunError::Predict(e)
    }
}

impl Scene {
    /// Whether the instrument can push with this scene's model: not with a dynamic particle or
    /// cantilever, whose contact and cantilever modes (periods of nanoseconds to microseconds)
    /// cost ~10⁴ integrator steps per 1 ms control tick, far too many for a real-time tick.
    /// Such a scene is the reference of `simulate` and `accuracy`; pushes run the quasi-static
    /// reduction.
    ///
    /// And the strategy's geometry (Sec 2.1): travel at the start height must clear every
    /// particle (the tip would run into it), and the parking height that gives the contact
    /// angle β, `h = Rₐ − Rₜ + (Rₐ + Rₜ) sin β`, must put the tip's apex above the substrate
    /// for particle `id`, the one pushed (a smaller particle elsewhere, which the tip never
    /// meets at β, must not refuse the push of a larger one).
    pub fn pushable(&self, id: u32) -> Result<(), RunError> {
        self.model_pushable()?;
        let s = &self.file;
        let tallest = s.particles.iter().map(|p| 2.0 * p.radius_nm * 1e-3).fold(0.0, f64::max);
        if s.strategy.start_height_um <= tallest {
            return Err(RunError::NotPushable(format!(
                "strategy.start_height_um = {} µm does not clear the tallest particle ({tallest} µm high): moves at the start height would run into it; allowed: above {tallest} µm",
                s.strategy.start_height_um
            )));
        }
        let (sin_b, r_t) = (s.push.contact_angle_deg.to_radians().sin(), s.tip.radius_nm);
        for (k, p) in s.particles.iter().enumerate().filter(|(_, p)| p.id == id) {
            let r_a = p.radius_nm;
            if r_a - r_t + (r_a + r_t) * sin_b <= 0.0 {
                let min = ((r_t - r_a) / (r_t + r_a)).asin().to_degrees();
                return Err(RunError::NotPushable(format!(
                    "push.contact_angle_deg = {}°: the tip (radius {r_t} nm) would have to reach below the substrate to meet particles[{k}] (radius {r_a} nm) at that angle (parking height Rₐ − Rₜ + (Rₐ + Rₜ) sin β ≤ 0); allowed: above {min:.2}° for this particle, or a sharper tip",
                    s.push.contact_angle_deg
                )));
            }
        }
        Ok(())
    }

    /// The model part of [`Scene::pushable`]: no dynamic particle or cantilever.
    pub fn model_pushable(&self) -> Result<(), RunError> {
        use crate::scene::file::DofFile;
        let ph = &self.file.physics;
        for (field, dof) in [
            ("particle_y", ph.particle_y),
            ("particle_z", ph.particle_z),
            ("particle_rotation", ph.particle_rotation),
            ("cantilever", ph.cantilever),
        ] {
            if dof == DofFile::Dynamic {
                return Err(RunError::NotPushable(format!(
                    "scene {:?} cannot be pushed: physics.{field} = \"dynamic\" puts modes of nanoseconds to \
                     microseconds into the model (~10⁴ integrator steps per 1 ms control tick); pushes need \
                     the quasi-static reduction (physics.{field} = \"quasi_static\"); `nanopush simulate` and \
                     `nanopush accuracy` run this scene",
                    self.file.name
                )));
            }
        }
        Ok(())
    }

    /// The strategy settings of the scene (`[strategy]`, `[sensor]`, `[push]`), SI.
    pub fn strategy_params(&self, tick: f64) -> StrategyParams {
        let f = &self.file;
        let st = &f.strategy;
        StrategyParams {
            tick,
            start_height: st.start_height_um * 1e-6,
            approach_speed: st.approach_speed_um_per_s * 1e-6,
            travel_speed: st.travel_speed_um_per_s * 1e-6,
            substrate_threshold: st.substrate_threshold_mv * 1e-3,
            step: st.step_um * 1e-6,
            dwell_ticks: (st.dwell_ms * 1e-3 / tick).round() as u32,
            speed: f.push.speed_um_per_s * 1e-6,
            baseline: f.sensor.baseline_v,
            polarity: f.sensor.gain_v_per_nm.signum(),
            set_point: st.set_point_v,
            safety_limit: st.safety_limit_v,
            full_scale: f.sensor.full_scale_v,
            lost_threshold: st.lost_threshold_mv * 1e-3,
            noise: f.sensor.noise_rms_mv * 1e-3,
            search_range: st.search_range_um * 1e-6,
            timeout: st.phase_timeout_s,
            control: match st.control {
                ControlFile::Xy => Control::Xy,
                ControlFile::Z => Control::Z,
                ControlFile::Xyz => Control::Xyz,
            },
            z_gain: st.z_gain_nm_per_v * 1e-9,
            pull_off_rise: crate::control::strategy::pull_off_rise(&self.tip_sample()),
            contact_side: ContactSide::of((st.set_point_v - f.sensor.baseline_v) * f.sensor.gain_v_per_nm.signum()),
            follow_slope: st.follow_slope,
        }
    }
}

/// One push as the operator asks for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushRequest {
    /// Particle id.
    pub id: u32,
    /// Estimated centre (m), from a scan.
    pub particle: (f64, f64),
    /// Estimated radius (m), from a scan.
    pub radius: f64,
    /// Unit push direction in the plane.
    pub direction: (f64, f64),
    /// Distance to push (m).
    pub distance: f64,
    /// A brief stop during the push: at this push travel (m), for this long (s).
    pub pause: Option<(f64, f64)>,
    /// The substrate's slope `(∂z/∂x, ∂z/∂y)` as the scan before the push measured it
    /// ([`crate::scan::Located::slope`]).
    pub slope: (f64, f64),
}

/// What the controller computes once for a particle before pushing it: the model's prediction
/// for the Eq 19 estimator (with the particle's radius as a scan estimated it) and the contact
/// geometry. Reused for every leg of a planned move.
#[derive(Debug, Clone, PartialEq)]
pub struct Prepared {
    /// The model's prediction.
    pub prediction: PushPrediction,
    /// The `t*` detector's margin (V).
    pub margin: f64,
    /// Contact angle aimed for (rad).
    pub beta: f64,
    /// Tip radius (m).
    pub tip_radius: f64,
    /// Estimated particle radius (m).
    pub radius: f64,
    /// Run-up behind the contact point (m).
    pub approach_distance: f64,
    /// Sensor gain (V/m).
    pub gain: f64,
    /// How far above the substrate auto-parking will detect it (m): [`detection_offset`].
    pub detect_offset: f64,
    /// The stage's travel in x and y (m).
    pub range: f64,
}

/// How far above the true substrate auto-parking detects it (m): the tip's piezo distance when
/// the reading first passes `params.substrate_threshold`, approaching in steps of
/// `approach_speed · tick` on the tip-sample force curve. The attraction snaps the tip in a few
/// nm above the surface (3 nm for a 10 nm tip on 0.5 N/m), which on a 14 nm particle is a
/// tenth of its height; a stiff lever that does not snap is detected pressed in
/// (a negative offset of a fraction of a nm).
pub fn detection_offset(scene: &Scene, params: &StrategyParams) -> f64 {
    use crate::physics::force_curve::TipTrack;
    let ts = scene.tip_sample();
    let gain = scene.sensor().gain.abs();
    let step = (params.approach_speed * params.tick).max(1e-12);
    let mut d = 100e-9_f64.min(params.start_height);
    let mut track = TipTrack::far(d);
    // At most 100 nm down and 100 nm into the surface.
    for _ in 0..(200e-9 / step).ceil().min(1e6) as u64 {
        let point = ts.track(&mut track, d);
        if (point.deflection * gain).abs() > params.substrate_threshold {
            return d;
        }
        d -= step;
    }
    0.0
}

impl Prepared {
    /// The model prediction for particle `id` of `scene` with estimated radius `radius` (m).
    pub fn new(scene: &Scene, id: u32, radius: f64, params: &StrategyParams) -> Result<Prepared, RunError> {
        scene.pushable(id)?;
        let f = &scene.file;
        let part = f
            .particles
            .iter()
            .find(|p| p.id == id)
            .ok_or(RunError::NoParticle(id))?;
        let mut model = scene.push_params_for(part);
        model.r_a = radius;
        model.interactions.r_a = radius;
        let sensor = scene.sensor();
        let set_deflection = sensor.deflection(params.set_point);
        // The strategy lifts from the parking height (after the back-off) to the start height.
        let parking = model.r_a - model.r_t + (model.r_a + model.r_t) * model.beta.sin();
        let retract = RetractPlan {
            hold: HOLD,
            back_off: BACK_OFF,
            speed: params.approach_speed,
            lift: (params.start_height - parking - BACK_OFF * model.beta.sin()).max(0.0),
        };
        // Long enough to pass the separation and settle (as the plan's).
        let prediction = predict_past_separation(model, set_deflection, retract)?;
        // The drop at t* that the model predicts, in volts; a third of it (at least 4σ of the
        // noise) tells the peak from noise and from the stage's ringing.
        let drop = (prediction.peak_deflection - prediction.settled_deflection) * sensor.gain.abs();
        let margin = (4.0 * params.noise).max(drop / 3.0).max(1e-4);
        Ok(Prepared {
            detect_offset: detection_offset(scene, params),
            prediction,
            margin,
            beta: model.beta,
            tip_radius: model.r_t,
            radius,
            approach_distance: f.strategy.approach_distance_um * 1e-6,
            gain: sensor.gain,
            range: f.stage.range_um * 1e-6,
        })
    }

    /// [`crate::control::route::check_reach`] for `legs`: the tip reaches the particle's back,
    /// on the stage.
    pub fn check_reach(&self, legs: &[Leg]) -> Result<(), crate::control::RouteError> {
        crate::control::route::check_reach(legs, self.radius + self.tip_radius, self.range)
    }

    /// How much of the retraction's drag the pushes of `legs` cannot make up for (m), because
    /// pushing that much further would carry the particle off the stage
    /// ([`PushTask::max_travel`]): the most any leg falls short by; `None` when none does
    /// by more than [`DONE_WITHIN`]. A target within the drag of the stage's edge ends short by
    /// it, and pushing again ends short again.
    pub fn short_of_drag(&self, legs: &[Leg]) -> Option<f64> {
        let drag = (-self.prediction.retract_shift).max(0.0);
        let short = legs
            .iter()
            .map(|l| l.length() + drag - travel_on_stage(l.from, l.direction(), self.radius, self.range))
            .fold(0.0, f64::max);
        (short > DONE_WITHIN).then_some(short)
    }

    /// A fresh estimator for one push.
    pub fn hxy(&self) -> Hxy {
        Hxy::new(self.prediction, self.margin, self.gain)
    }

    /// The push from where the particle is believed to be (`estimate`) to `to`, or `None` when it
    /// is already within [`DONE_WITHIN`]: each leg of a move starts from the latest estimate, so
    /// errors do not add up. `slope` is the substrate's as the latest scan measured it.
    pub fn request(
        &self,
        id: u32,
        estimate: (f64, f64),
        to: (f64, f64),
        pause: Option<(f64, f64)>,
        slope: (f64, f64),
    ) -> Option<PushRequest> {
        let leg = Leg { from: estimate, to };
        (leg.length() >= DONE_WITHIN).then(|| PushRequest {
            id,
            particle: estimate,
            radius: self.radius,
            direction: leg.direction(),
            distance: leg.length(),
            pause,
            slope,
        })
    }

    /// The task of one push.
    pub fn task(&self, request: &PushRequest, tick: f64) -> PushTask {
        PushTask {
            max_travel: travel_on_stage(request.particle, request.direction, self.radius, self.range),
            particle: request.particle,
            radius: self.radius,
            direction: request.direction,
            distance: request.distance,
            beta: self.beta,
            tip_radius: self.tip_radius,
            approach_distance: self.approach_distance,
            pause: request.pause.map(|(at, secs)| (at, (secs / tick).round() as u32)),
            detect_offset: self.detect_offset,
            slope: request.slope,
        }
    }
}

/// Pushes one particle: the controller knows it only by the request's estimated centre and
/// radius; it is pushed the requested distance along the unit direction. The model
/// prediction for the estimator uses the scene's parameters with the estimated radius. The
/// instrument `afm` carries the truth; its tip must be at the start height.
pub fn push_once(
    scene: &Scene,
    afm: &mut Afm,
    request: &PushRequest,
    params: StrategyParams,
) -> Result<StrategyRun, RunError> {
    Prepared::new(scene, request.id, request.radius, &params)?.run(afm, request, params)
}

impl Prepared {
    /// Runs one push with this preparation (the model prediction is computed once per move,
    /// not per leg) against the instrument, tick by tick, recording a trace.
    pub fn run(&self, afm: &mut Afm, request: &PushRequest, params: StrategyParams) -> Result<StrategyRun, RunError> {
        let id = request.id;
        let index = afm
            .particles()
            .iter()
            .position(|p| p.id == id)
            .ok_or(RunError::NoParticle(id))?;
        let prediction = self.prediction;
        let hxy = self.hxy();
        let task = self.task(request, params.tick);
        let before = afm.particles()[index];
        let first = afm.read();
        let mut strategy = Strategy::new(params, task, hxy, &first);
        let mut reading = first;
        let mut trace = Vec::new();
        let budget = ((8.0 * params.timeout) / params.tick) as u64 + 1000;
        let mut ticks = 0u64;
        while !strategy.done() {
            ticks += 1;
            if ticks > budget {
                return Err(RunError::Budget(budget));
            }
            let target = strategy.tick(&reading);
            let phase = strategy.phase.name();
            let estimate = strategy.summary.estimated_distance;
            reading = afm.step(target)?;
            if let Some(u) = afm.take_fault() {
                strategy.unphysical(u, reading.t);
            }
            let p = afm.particles()[index];
            trace.push(RunRow {
                t: reading.t,
                phase,
                stage: reading.stage,
                volts: reading.volts,
                estimate,
                particle: (p.x, p.y),
                contact: afm.truth().phase,
            });
        }
        let after = afm.particles()[index];
        let truth = afm.truth();
        Ok(StrategyRun {
            summary: strategy.summary,
            prediction,
            trace,
            task,
            particle_before: (before.x, before.y),
            particle_after: (after.x, after.y),
            final_stage: reading.stage,
            retracted: truth.pushing.is_none() && !truth.on_substrate,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::scene::Scene;

    /// A 10 nm particle elsewhere in the scene does not refuse the push of a 500 nm one: the
    /// contact-angle geometry is checked for the pushed particle only, the one the tip meets
    /// at β.
    #[test]
    fn the_contact_geometry_is_checked_for_the_pushed_particle_only() {
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/gold-latex-500nm.toml"))
            .unwrap()
            + "\n[[particles]]\nid = 9\nmaterial = \"gold\"\nradius_nm = 10.0\nx_um = 80.0\ny_um = 80.0\nyoungs_modulus_gpa = 79.0\npoisson_ratio = 0.42\ndensity_kg_per_m3 = 19300.0\nhamaker_zj = 400.0\n";
        let s = Scene::parse("with-a-small-one", &text).unwrap();
        assert!(s.file.push.contact_angle_deg <= 30.0);
        s.pushable(1).expect("the 500 nm particle is met at β");
        let e = s.pushable(9).unwrap_err().to_string();
        assert!(e.contains("to meet particles[3] (radius 10 nm)"), "{e}");
    }
}
