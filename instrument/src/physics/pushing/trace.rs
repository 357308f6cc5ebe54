//! A push at constant stage speed, sampled into a trace: what `nanopush simulate` runs and the
//! accuracy report measures.

use crate::numerics::integrate::{Method, Options, Stats};
use crate::physics::pushing::{PushModel, Simulation, SimulationError};

/// One sample of a push.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRow {
    /// Time (s).
    pub t: f64,
    /// Stage travel `s` (m).
    pub stage_y: f64,
    /// Particle y (m).
    pub particle_y: f64,
    /// Particle z (m); the frozen value when the DOF is off.
    pub particle_z: f64,
    /// Particle rotation θ (rad); 0 when the DOF is off.
    pub theta: f64,
    /// Cantilever deflection `ζ_y'` (m).
    pub zeta_y: f64,
    /// Measured deflection `ζ_z'` (m).
    pub zeta_z: f64,
    /// Tip-particle normal force `F_ta` (N).
    pub normal_ta: f64,
    /// Tip-particle friction `f_ta` (N).
    pub friction_ta: f64,
    /// Particle-substrate normal load `A_as + F_l` (N).
    pub load_as: f64,
    /// Particle-substrate friction `f_as` (N).
    pub friction_as: f64,
    /// Friction phase.
    pub phase: &'static str,
}

/// The result of a push.
#[derive(Debug, Clone, PartialEq)]
pub struct PushRun {
    /// Samples at `t = 0, dt, 2dt, …`.
    pub trace: Vec<TraceRow>,
    /// Integrator work, summed.
    pub stats: Stats,
    /// Shearing time `t*` (s).
    pub shearing_time: Option<f64>,
    /// Final state.
    pub final_state: Vec<f64>,
    /// Phase at the end.
    pub final_phase: &'static str,
}

impl PushRun {
    /// Final particle y (m).
    pub fn final_particle_y(&self) -> f64 {
        self.trace.last().map_or(0.0, |r| r.particle_y)
    }
    /// Final measured deflection (m).
    pub fn final_zeta_z(&self) -> f64 {
        self.trace.last().map_or(0.0, |r| r.zeta_z)
    }
    /// Mean `ζ_z` over the last 20 % of the samples (m).
    pub fn steady_zeta_z(&self) -> f64 {
        let n = self.trace.len();
        let tail = &self.trace[n - (n / 5).max(1)..];
        tail.iter().map(|r| r.zeta_z).sum::<f64>() / tail.len() as f64
    }
}

fn sample(sim: &Simulation) -> TraceRow {
    let m = &sim.model;
    let n = m.len();
    let x = &sim.x[..n];
    let p = m.probe(sim.t, x, &sim.mode);
    let l = &m.layout;
    TraceRow {
        t: sim.t,
        stage_y: p.stage,
        particle_y: x[l.particle_y.pos],
        particle_z: l.particle_z.map_or(m.frozen_particle_z(), |s| x[s.pos]),
        theta: l.rotation.map_or(0.0, |s| x[s.pos]),
        zeta_y: p.zeta_y,
        zeta_z: p.zeta_z,
        normal_ta: p.normal_ta,
        friction_ta: p.friction_ta,
        load_as: p.load_as,
        friction_as: p.friction_as,
        phase: sim.phase().as_str(),
    }
}

/// Most samples a trace may hold (~100 bytes each: 200 MB): a trace is sized by
/// `duration / dt`, both from the user, and is refused above this, never allocated.
pub const MAX_SAMPLES: u64 = 2_000_000;

/// Pushes for `duration` seconds at the scene's speed, sampling every `dt`; at most
/// [`MAX_SAMPLES`] samples, with no limit on the integrator's steps.
pub fn run_push(
    model: PushModel,
    method: Method,
    opts: Options,
    duration: f64,
    dt: f64,
) -> Result<PushRun, SimulationError> {
    run_push_within(model, method, opts, duration, dt, u64::MAX)
}

/// [`run_push`] that fails with [`SimulationError::Budget`] once the integrator has taken more
/// than `max_steps` accepted steps: the bound on time for work done on behalf of a client.
pub fn run_push_within(
    model: PushModel,
    method: Method,
    opts: Options,
    duration: f64,
    dt: f64,
    max_steps: u64,
) -> Result<PushRun, SimulationError> {
    let mut sim = Simulation::new(model, method, opts);
    let samples = (duration / dt).round().max(1.0);
    if samples.is_nan() || samples > MAX_SAMPLES as f64 {
        return Err(SimulationError::Budget {
            what: "trace samples",
            limit: MAX_SAMPLES,
            t: 0.0,
        });
    }
    let steps = samples as usize;
    let mut trace = Vec::with_capacity(steps + 1);
    trace.push(sample(&sim));
    for k in 1..=steps {
        sim.advance_to(duration * k as f64 / steps as f64)?;
        if sim.total.steps > max_steps {
            return Err(SimulationError::Budget {
                what: "integrator steps",
                limit: max_steps,
                t: sim.t,
            });
        }
        trace.push(sample(&sim));
    }
    let n = sim.model.len();
    Ok(PushRun {
        trace,
        stats: sim.total,
        shearing_time: sim.shearing_time,
        final_state: sim.x[..n].to_vec(),
        final_phase: sim.phase().as_str(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::integrate::{Method, Options};
    use crate::physics::pushing::{Dof, PushModel};
    use crate::scene::Scene;

    /// docs/model.md's `nanopush simulate` and Fig 7 figures ("`nanopush simulate`", "The paper's
    /// figures"), pinned: the default scene pushed 50 ms at 1 µm/s (Rodas4, rtol 1e-6) —
    /// the tip contact slips at 5.2 ms (the switch located to 1 µs; the first 0.1 ms sample that
    /// rolls is 5.3 ms) and the particle rolls from then on, 49.3 nm of travel for 50.0 nm of
    /// stage, the offset behind the stage settling at 0.669 nm after peaking at 1.33 nm; with
    /// rotation off it shears at t* = 6.2 ms and settles at 4.47 nm with a steady `ζ_z` (mean of
    /// the last 20 %, as `simulate` prints it) of −1.98 nm. Each to half a unit of docs/model.md's
    /// last digit.
    #[test]
    fn fig7_settling_and_the_simulate_figures() {
        let scene = Scene::default_scene();
        let mut sim = Simulation::new(
            PushModel::new(scene.push_params()),
            Method::Rodas4,
            Options::with_rtol(1e-6),
        );
        sim.advance_to(5.0e-3).unwrap();
        assert_eq!(sim.phase().as_str(), "stick", "slipped before 5.0 ms");
        let mut k = 0;
        while sim.phase().as_str() == "stick" && k < 1000 {
            k += 1;
            sim.advance_to(5.0e-3 + k as f64 * 1e-6).unwrap();
        }
        assert_eq!(sim.phase().as_str(), "roll");
        let slip = sim.t;
        assert!((slip - 5.2e-3).abs() < 0.05e-3, "the tip slips at {slip:e} s");

        let run = run_push(
            PushModel::new(scene.push_params()),
            Method::Rodas4,
            Options::with_rtol(1e-6),
            0.05,
            1e-4,
        )
        .unwrap();
        let first = run.trace.iter().position(|r| r.phase == "roll").expect("it rolls");
        assert!(
            run.trace[first..].iter().all(|r| r.phase == "roll"),
            "it rolls from then on"
        );
        assert_eq!(run.shearing_time, None, "it never slides on the substrate");
        let y = run.final_particle_y();
        assert!((y - 49.3e-9).abs() < 0.05e-9, "particle travel {y:e} m");
        let last = run.trace.last().unwrap();
        let offset = last.stage_y - last.particle_y;
        assert!((offset - 0.669e-9).abs() < 0.0005e-9, "settled offset {offset:e} m");
        let peak = run.trace.iter().map(|r| r.stage_y - r.particle_y).fold(0.0, f64::max);
        assert!((peak - 1.33e-9).abs() < 0.005e-9, "peak offset {peak:e} m");

        let mut p = scene.push_params();
        p.dofs.particle_rotation = Dof::Off;
        let run = run_push(PushModel::new(p), Method::Rodas4, Options::with_rtol(1e-6), 0.05, 1e-4).unwrap();
        let t_star = run.shearing_time.expect("it shears");
        assert!((t_star - 6.2e-3).abs() < 0.05e-3, "t* {t_star:e} s");
        let last = run.trace.last().unwrap();
        let offset = last.stage_y - last.particle_y;
        assert!(
            (offset - 4.47e-9).abs() < 0.005e-9,
            "settled offset without rotation {offset:e} m"
        );
        let zeta_z = run.steady_zeta_z();
        assert!(
            (zeta_z + 1.98e-9).abs() < 0.005e-9,
            "steady ζ_z without rotation {zeta_z:e} m"
        );
    }

    /// docs/model.md, "`nanopush simulate`": the run (its defaults: the default scene, 50 ms,
    /// Rodas4 at rtol 1e-6, 0.1 ms samples): 518 steps, 50.0 nm of stage travel, and an estimated
    /// global error of 1.5 fm: the difference in final particle y from the rerun at rtol/100 with
    /// the same sampling, as `simulate` computes it.
    #[test]
    fn simulates_step_count_and_error_estimate_are_pinned() {
        let push = |rtol: f64| {
            let model = PushModel::new(Scene::default_scene().push_params());
            run_push(model, Method::Rodas4, Options::with_rtol(rtol), 0.05, 1e-4).unwrap()
        };
        let (run, fine) = (push(1e-6), push(1e-8));
        assert_eq!(run.stats.steps, 518);
        let stage = run.trace.last().unwrap().stage_y;
        assert!((stage - 50.0e-9).abs() < 0.05e-9, "stage travel {stage:e} m");
        let estimate = (run.final_particle_y() - fine.final_particle_y()).abs();
        assert!((estimate - 1.5e-15).abs() < 0.05e-15, "estimated error {estimate:e} m");
    }
}
