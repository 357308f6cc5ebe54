//! The quasi-static reduction against the full model, on what a push *does*: the friction
//! regime, the shearing time `t*`, the settled offset `y` behind the stage and the settled
//! deflection `ζ_z`, with the particle's rotation on and off.
//!
//! The reduced model puts the particle (y, z, θ) and the cantilever at force balance (zero-mass
//! rows); the full model keeps their inertia (12 states). Both start from the same state, and
//! until the first shear their traces agree to ~1e-15 m: loading at 1 µm/s is quasi-static. They
//! part at the first stick → slip, and the reason is physics, not numerics:
//!
//! **Why the models disagree after `t*`** (an independent, hand-solved argument). At the shear
//! the substrate's friction drops from the static `μˢN` to the kinetic `μᵏN` (0.3 → 0.2 in the
//! paper), so the stored elastic load `ΔF = (μˢ − μᵏ)N` ≈ 0.14 µN is released at once. Take the
//! one-degree-of-freedom spring-slider (mass `m`, stiffness `k`, damping ratio `ζ`, driven at
//! `V`) that both models share in their slowest part:
//! - *with inertia* the slip starts at rest with a force excess `ΔF`; by energy,
//!   `½k(x_s² − x_e²) = μᵏN (x_s − x_e)` for an undamped slider, so the slip overshoots the
//!   kinetic balance by as much again and stops (slip rate zero) with the spring at
//!   `μᵏN − ΔF·e^{−πζ/√(1−ζ²)}`, below the kinetic friction: the contact sticks and must be
//!   loaded again — stick-slip, for every drive slower than the critical velocity
//!   `V_c ~ ΔF/√(km)` (~5 mm/s with the cantilever's mass, against `V` = 1 µm/s). Steady
//!   sliding at `V` would need the slip rate never to reach zero, i.e. every fast oscillation
//!   left by the jump to stay below `V/ω`, 10⁻¹³-10⁻¹² m at 0.1-4 MHz; the jump itself is
//!   ~2 nm;
//! - *without inertia* (zero-mass rows) the jump is instantaneous and lands exactly on the
//!   kinetic balance, where the slip rate is the drive's, `+V`: the contact slides steadily. That
//!   is the overdamped limit (`ζ ≫ 1` in every fast mode), not the limit of the scene's lightly
//!   damped contacts and cantilever (ζ = 0.05, Q = 100).
//!
//! So after the first shear the full model is the right one for the paper's scene: it
//! stick-slips (a ~2 nm jump in ~0.1 µs, during which the tip also slides up the particle,
//! which is why its settled `ζ_z` is of the other sign); the reduced model slides (or rolls)
//! steadily at the kinetic friction. The reduction is exact up to `t*` and for the static
//! phase, which is what the instrument's set point and the strategy's contact detection use.
//! The comparison below measures both, and [`Regime`] names what each does.

use std::time::Instant;

use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::trace::{PushRun, TraceRow, run_push};
use nanopush_instrument::physics::pushing::{Dof, PushModel, PushParams};
use nanopush_proto::accuracy::{PushOutcome, ReductionRow};

/// A drop of the offset `s − y` between two samples larger than this (m) is a jump of the
/// particle (a slip or a roll burst): while it sticks the offset grows with the stage, while it
/// slides or rolls steadily the offset is constant.
pub const JUMP: f64 = 0.05e-9;

/// What the particle does over a push, from its trace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    /// It never moved on the substrate (no shear, no roll, no jump).
    Stuck,
    /// It shears once and slides steadily on the substrate.
    Slides,
    /// It rolls steadily (the substrate contact sticks, the tip contact slips).
    Rolls,
    /// It jumps repeatedly after shearing: the substrate contact slips and sticks again.
    StickSlip,
    /// It jumps repeatedly without ever shearing on the substrate: rolling in bursts.
    StickRoll,
}

impl Regime {
    /// Lower-case name, for tables and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Regime::Stuck => "stuck",
            Regime::Slides => "slides",
            Regime::Rolls => "rolls",
            Regime::StickSlip => "stick-slip",
            Regime::StickRoll => "stick-roll",
        }
    }
}

/// One model's push, summarised.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// What the particle does.
    pub regime: Regime,
    /// Jumps of the offset (see [`JUMP`]) over the whole push.
    pub jumps: usize,
    /// Shearing time `t*` (s): the first stick → slip on the substrate.
    pub shearing_time: Option<f64>,
    /// Friction phase sampled at the end (`stick`, `slip`, `roll`).
    pub final_phase: &'static str,
    /// Mean offset behind the stage, `s − y`, over the tail (m).
    pub settled_y: f64,
    /// Its spread (max − min) over the tail (m).
    pub y_spread: f64,
    /// Mean measured deflection `ζ_z` over the tail (m).
    pub zeta_z: f64,
    /// Its spread over the tail (m).
    pub zeta_z_spread: f64,
    /// Accepted steps.
    pub steps: u64,
    /// Wall time (s).
    pub wall_time: f64,
}

impl From<&Summary> for PushOutcome {
    /// The report's row for one model's push.
    fn from(s: &Summary) -> PushOutcome {
        PushOutcome {
            regime: s.regime.as_str().into(),
            jumps: s.jumps,
            shearing_time: s.shearing_time,
            final_phase: s.final_phase.into(),
            settled_y: s.settled_y,
            y_spread: s.y_spread,
            zeta_z: s.zeta_z,
            zeta_z_spread: s.zeta_z_spread,
            steps: s.steps,
            wall_time: s.wall_time,
        }
    }
}

/// Mean and spread (max − min) of `f` over `rows`.
fn mean_spread(rows: &[TraceRow], f: impl Fn(&TraceRow) -> f64) -> (f64, f64) {
    let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for r in rows {
        let v = f(r);
        lo = lo.min(v);
        hi = hi.max(v);
        sum += v;
    }
    (sum / rows.len().max(1) as f64, hi - lo)
}

/// The number of jumps of the offset `s − y` in a trace.
pub fn jumps(trace: &[TraceRow]) -> usize {
    trace
        .windows(2)
        .filter(|w| (w[0].stage_y - w[0].particle_y) - (w[1].stage_y - w[1].particle_y) > JUMP)
        .count()
}

/// The regime of a push: two jumps or more are stick-slip (or stick-roll if the substrate never
/// slipped); otherwise the phase most sampled in the tail decides (slip: slides, roll: rolls),
/// and a particle that sticks there without having jumped is stuck.
pub fn regime(trace: &[TraceRow], shearing_time: Option<f64>, tail: f64) -> (Regime, usize) {
    let j = jumps(trace);
    if j >= 2 {
        let r = if shearing_time.is_some() {
            Regime::StickSlip
        } else {
            Regime::StickRoll
        };
        return (r, j);
    }
    let tail_rows = &trace[tail_start(trace.len(), tail)..];
    let count = |p: &str| tail_rows.iter().filter(|r| r.phase == p).count();
    let (slip, roll, stick) = (count("slip"), count("roll"), count("stick"));
    let r = if slip >= roll.max(stick) {
        Regime::Slides
    } else if roll >= stick {
        Regime::Rolls
    } else if j == 1 && shearing_time.is_some() {
        // One jump and then sticking for good: it slipped once and stopped.
        Regime::StickSlip
    } else {
        Regime::Stuck
    };
    (r, j)
}

fn tail_start(n: usize, tail: f64) -> usize {
    let k = ((n as f64) * tail).ceil() as usize;
    n - k.clamp(1, n.max(1))
}

/// Summarises a run; `tail` is the fraction of the samples, at the end, whose mean is settled.
pub fn summarize(run: &PushRun, tail: f64, wall_time: f64) -> Summary {
    let (regime, jumps) = regime(&run.trace, run.shearing_time, tail);
    let rows = &run.trace[tail_start(run.trace.len(), tail)..];
    let (settled_y, y_spread) = mean_spread(rows, |r| r.stage_y - r.particle_y);
    let (zeta_z, zeta_z_spread) = mean_spread(rows, |r| r.zeta_z);
    Summary {
        regime,
        jumps,
        shearing_time: run.shearing_time,
        final_phase: run.final_phase,
        settled_y,
        y_spread,
        zeta_z,
        zeta_z_spread,
        steps: run.stats.steps,
        wall_time,
    }
}

/// The scene's parameters with the particle's and the cantilever's degrees of freedom all
/// quasi-static (`full = false`) or all dynamic (`full = true`), the rotation on or off. A DOF
/// the scene leaves out (the particle's z, say) stays out; the stage is as the scene has it.
pub fn variant(p: &PushParams, full: bool, rotation: bool) -> PushParams {
    let mut q = *p;
    let fast = if full { Dof::Dynamic } else { Dof::QuasiStatic };
    q.dofs.particle_y = fast;
    q.dofs.cantilever = fast;
    if q.dofs.particle_z != Dof::Off {
        q.dofs.particle_z = fast;
    }
    q.dofs.particle_rotation = if rotation { fast } else { Dof::Off };
    q
}

/// The reduced and the full model side by side, for one rotation setting.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Whether the particle may rotate.
    pub rotation: bool,
    /// The quasi-static reduction.
    pub reduced: Summary,
    /// The full model, or why it failed.
    pub full: Result<Summary, String>,
    /// The full model again at a 100× finer tolerance (the third integration that tells whether
    /// the full model's regime is numerical), or why it failed; `None` when not asked for.
    pub full_fine: Option<Result<Summary, String>>,
}

impl Comparison {
    /// Whether both models do the same thing (`None` if the full model failed).
    pub fn regime_agrees(&self) -> Option<bool> {
        self.full.as_ref().ok().map(|f| f.regime == self.reduced.regime)
    }

    /// `|t*_reduced − t*_full|` (s); `None` unless both shear.
    pub fn shearing_time_error(&self) -> Option<f64> {
        let f = self.full.as_ref().ok()?;
        Some((self.reduced.shearing_time? - f.shearing_time?).abs())
    }

    /// Whether exactly one of the two shears within the push.
    pub fn shearing_disagrees(&self) -> Option<bool> {
        let f = self.full.as_ref().ok()?;
        Some(self.reduced.shearing_time.is_some() != f.shearing_time.is_some())
    }

    /// Difference of the settled offsets (reduced − full, m).
    pub fn settled_y_error(&self) -> Option<f64> {
        self.full.as_ref().ok().map(|f| self.reduced.settled_y - f.settled_y)
    }

    /// Difference of the settled deflections (reduced − full, m).
    pub fn zeta_z_error(&self) -> Option<f64> {
        self.full.as_ref().ok().map(|f| self.reduced.zeta_z - f.zeta_z)
    }
}

impl From<&Comparison> for ReductionRow {
    /// The report's row: both models, the errors of the reduction, and the full model's failure
    /// (at the report's tolerance, or at the finer one), if it failed.
    fn from(c: &Comparison) -> ReductionRow {
        let fine = c.full_fine.as_ref();
        let failure = match (&c.full, fine) {
            (Err(e), _) => Some(format!("full model: {e}")),
            (_, Some(Err(e))) => Some(format!("full model at rtol/100: {e}")),
            _ => None,
        };
        ReductionRow {
            rotation: c.rotation,
            reduced: PushOutcome::from(&c.reduced),
            full: c.full.as_ref().ok().map(PushOutcome::from),
            full_fine: fine.and_then(|f| f.as_ref().ok()).map(PushOutcome::from),
            failure,
            regime_agrees: c.regime_agrees(),
            shearing_time_error: c.shearing_time_error(),
            settled_y_error: c.settled_y_error(),
            zeta_z_error: c.zeta_z_error(),
        }
    }
}

/// How [`compare`] runs the two models.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompareOptions {
    /// Simulated push (s).
    pub duration: f64,
    /// Trace sample interval (s): short enough that a jump shows between two samples.
    pub sample: f64,
    /// Fraction of the samples, at the end, whose mean is the settled value.
    pub tail: f64,
    /// Relative tolerance of both models.
    pub rtol: f64,
    /// Largest number of integrator steps per advance (the full model rings after each slip,
    /// at up to ~6·10⁴ steps per ms).
    pub max_steps: u64,
    /// Also run the full model at `rtol / 100`.
    pub fine_check: bool,
}

impl CompareOptions {
    /// The report's settings for a push of `duration` seconds: 10 µs samples (a jump lasts
    /// ~0.1-1 µs and the stage moves 0.01 nm per sample at 1 µm/s), the last half as the
    /// tail (it holds several stick-slip periods), rtol 1e-6.
    pub fn report(duration: f64) -> CompareOptions {
        CompareOptions {
            duration,
            sample: (duration / 2000.0).min(1e-5),
            tail: 0.5,
            rtol: 1e-6,
            max_steps: 2_000_000,
            fine_check: true,
        }
    }
}

fn run_summary(p: PushParams, o: &CompareOptions, rtol: f64) -> Result<Summary, String> {
    let start = Instant::now();
    let opts = Options {
        max_steps: o.max_steps,
        ..Options::with_rtol(rtol)
    };
    let run = run_push(PushModel::new(p), Method::Rodas4, opts, o.duration, o.sample).map_err(|e| e.to_string())?;
    Ok(summarize(&run, o.tail, start.elapsed().as_secs_f64()))
}

/// The reduced and the full model on the scene's push, rotation off and on (Rodas4).
pub fn compare(p: &PushParams, o: &CompareOptions) -> Result<Vec<Comparison>, String> {
    let mut out = Vec::new();
    for rotation in [false, true] {
        let reduced = run_summary(variant(p, false, rotation), o, o.rtol).map_err(|e| format!("reduced model: {e}"))?;
        let full = run_summary(variant(p, true, rotation), o, o.rtol);
        let full_fine = o
            .fine_check
            .then(|| run_summary(variant(p, true, rotation), o, o.rtol / 100.0));
        out.push(Comparison {
            rotation,
            reduced,
            full,
            full_fine,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
