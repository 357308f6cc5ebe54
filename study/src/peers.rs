//! Peer solvers from crates.io on the work-precision report's classical problems, so that the
//! report can put our integrators' cost at equal error next to established implementations.
//!
//! The peers are diffsol's BDF, TR-BDF2 and ESDIRK34 (dense nalgebra matrices, LU) and
//! russell_ode's Radau5. Each one integrates the very same [`Problem`]: the wrappers below call
//! our [`Problem::rhs`] and our exact [`Problem::jacobian`], so every method sees the same
//! right-hand side and the same Jacobian.
//!
//! Tolerances follow our convention (`atol_i = rtol · scale(i)`, as in
//! [`Options::with_rtol`](nanopush_instrument::numerics::integrate::Options::with_rtol)):
//! - diffsol takes a per-component absolute tolerance, so it gets `rtol · scale(i)` directly;
//! - russell_ode takes one scalar absolute tolerance (and rejects any below 10 ε), so it
//!   integrates the scaled state `z_i = y_i / scale(i)` with `atol = rtol`: its weight
//!   `rtol + rtol·|z_i|` is then exactly ours, `(rtol·scale(i) + rtol·|y_i|) / scale(i)`. The
//!   scaled system is `z' = S⁻¹ f(t, S z)` with Jacobian `S⁻¹ J S`, built from our `rhs` and
//!   `jacobian`. Radau5 then applies Hairer's usual map of the user tolerance
//!   (`rtol ↦ 0.1 · rtol^(2/3)`), as the Fortran code does.
//!
//! Two settings differ from the peers' defaults, both in the peers' favour: diffsol's cap of 50
//! Newton failures over a whole integration becomes our step limit, and Radau5 solves its two
//! linear systems on the calling thread instead of spawning two threads per Newton iteration.
//! Every other setting is the peer's default. The error is the largest relative component error
//! at the end time against the published reference, as in [`crate::accuracy`].

use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind};

use diffsol::{
    NalgebraContext, NalgebraLU, NalgebraMat, NalgebraVec, OdeBuilder, OdeEquationsImplicit, OdeSolverMethod,
    OdeSolverProblem, OdeSolverStopReason, Vector as _,
};
use russell_lab::Vector;
use russell_ode::{Method as RussellMethod, NoArgs, OdeSolver, Params, System};
use russell_sparse::{CooMatrix, Sym};

use crate::accuracy::{max_relative_error, timed, tolerances};
use nanopush_instrument::numerics::integrate::test_problems::{Robertson, VanDerPol};
use nanopush_instrument::numerics::integrate::{MAX_DIM, Problem};
use nanopush_proto::accuracy::AccuracyPoint;

/// One peer solver on one problem at one tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct PeerPoint {
    /// Problem name (`van-der-pol`, `robertson`: the names of [`crate::accuracy::Point`]).
    pub problem: String,
    /// Peer solver, one of [`SOLVERS`].
    pub solver: String,
    /// Relative tolerance (the absolute tolerance is `rtol · scale(i)`).
    pub rtol: f64,
    /// Largest relative component error at the end time against the reference (NaN on failure).
    pub final_error: f64,
    /// Median wall time of the repetitions (s), problem setup included.
    pub wall_time: f64,
    /// Accepted steps as the peer reports them (0 on failure).
    pub steps: u64,
    /// The peer's error message, or the message of a panic inside it, if the run failed.
    pub failure: Option<String>,
}

impl From<&PeerPoint> for AccuracyPoint {
    /// The report's row: a failed run has no error; a peer reports no trajectory error, no
    /// estimate and no rejected steps.
    fn from(p: &PeerPoint) -> AccuracyPoint {
        AccuracyPoint {
            problem: p.problem.clone(),
            method: p.solver.clone(),
            rtol: p.rtol,
            final_error: p.final_error.is_finite().then_some(p.final_error),
            trajectory_error: None,
            estimated_error: None,
            estimate_rtol: None,
            wall_time: p.wall_time,
            steps: p.steps,
            rejected: 0,
            failure: p.failure.clone(),
        }
    }
}

/// The peer solvers, by the names used in [`PeerPoint::solver`].
pub const SOLVERS: [&str; 4] = ["diffsol-bdf", "diffsol-tr-bdf2", "diffsol-esdirk34", "russell-radau5"];

/// Most steps a peer may take in one run (the default `max_steps` of our own integrators).
const MAX_STEPS: u64 = 1_000_000;

#[derive(Debug, Clone, Copy)]
enum Peer {
    DiffsolBdf,
    DiffsolTrBdf2,
    DiffsolEsdirk34,
    RussellRadau5,
}

impl Peer {
    const ALL: [Peer; 4] = [
        Peer::DiffsolBdf,
        Peer::DiffsolTrBdf2,
        Peer::DiffsolEsdirk34,
        Peer::RussellRadau5,
    ];

    fn name(self) -> &'static str {
        match self {
            Peer::DiffsolBdf => SOLVERS[0],
            Peer::DiffsolTrBdf2 => SOLVERS[1],
            Peer::DiffsolEsdirk34 => SOLVERS[2],
            Peer::RussellRadau5 => SOLVERS[3],
        }
    }
}

/// Final state and accepted steps of one run, or the peer's error message.
type RunResult = Result<(Vec<f64>, u64), String>;

/// The Jacobian of the last point diffsol asked about: diffsol's closure interface wants
/// Jacobian-vector products (one per column when it assembles the matrix), and this keeps our
/// exact Jacobian from being re-evaluated for each of them.
struct JacobianCache {
    valid: bool,
    t: f64,
    y: [f64; MAX_DIM],
    jac: [f64; MAX_DIM * MAX_DIM],
}

type DiffsolMat = NalgebraMat<f64>;

fn run_diffsol<P: Problem>(p: &P, peer: Peer, y0: &[f64], t_end: f64, rtol: f64) -> RunResult {
    let n = p.len();
    if n > MAX_DIM {
        return Err(format!("dimension {n} exceeds {MAX_DIM}"));
    }
    let cache = RefCell::new(JacobianCache {
        valid: false,
        t: 0.0,
        y: [0.0; MAX_DIM],
        jac: [0.0; MAX_DIM * MAX_DIM],
    });
    let builder = OdeBuilder::<DiffsolMat>::new()
        .rtol(rtol)
        .atol((0..n).map(|i| rtol * p.scale(i)))
        .rhs_implicit(
            |y: &[f64], _p: &[f64], t: f64, out: &mut [f64]| p.rhs(t, y, out),
            |y: &[f64], _p: &[f64], t: f64, v: &[f64], out: &mut [f64]| {
                let mut c = cache.borrow_mut();
                if !(c.valid && c.t == t && c.y[..n] == y[..n]) {
                    p.jacobian(t, y, &mut c.jac);
                    c.t = t;
                    c.y[..n].copy_from_slice(&y[..n]);
                    c.valid = true;
                }
                for (i, o) in out[..n].iter_mut().enumerate() {
                    *o = (0..n).map(|j| c.jac[i + j * n] * v[j]).sum();
                }
            },
        )
        .init(|_p: &[f64], _t: f64, y: &mut [f64]| y[..n].copy_from_slice(&y0[..n]), n);
    if (0..n).all(|i| p.mass(i) == 1.0) {
        let mut problem = builder.build().map_err(|e| e.to_string())?;
        solve_diffsol(&mut problem, peer, t_end)
    } else {
        let mut problem = builder
            .mass(|v: &[f64], _p: &[f64], _t: f64, beta: f64, out: &mut [f64]| {
                for i in 0..n {
                    out[i] = p.mass(i) * v[i] + beta * out[i];
                }
            })
            .build()
            .map_err(|e| e.to_string())?;
        solve_diffsol(&mut problem, peer, t_end)
    }
}

fn solve_diffsol<Eqn>(problem: &mut OdeSolverProblem<Eqn>, peer: Peer, t_end: f64) -> RunResult
where
    Eqn: OdeEquationsImplicit<T = f64, V = NalgebraVec<f64>, M = NalgebraMat<f64>, C = NalgebraContext>,
{
    // diffsol counts Newton convergence failures over the whole integration and gives up after
    // 50 by default; our integrators have no such cap (they stop only on the step limit or the
    // minimum step), so the peer gets the same step limit instead.
    problem.ode_options.max_nonlinear_solver_failures = MAX_STEPS as usize;
    let e = |e: diffsol::DiffsolError| e.to_string();
    match peer {
        Peer::DiffsolBdf => step_to(problem.bdf::<NalgebraLU<f64>>().map_err(e)?, t_end),
        Peer::DiffsolTrBdf2 => step_to(problem.tr_bdf2::<NalgebraLU<f64>>().map_err(e)?, t_end),
        Peer::DiffsolEsdirk34 => step_to(problem.esdirk34::<NalgebraLU<f64>>().map_err(e)?, t_end),
        Peer::RussellRadau5 => Err("not a diffsol method".into()),
    }
}

fn step_to<'a, Eqn, S>(mut solver: S, t_end: f64) -> RunResult
where
    Eqn: OdeEquationsImplicit<T = f64, V = NalgebraVec<f64>> + 'a,
    S: OdeSolverMethod<'a, Eqn>,
{
    solver.set_stop_time(t_end).map_err(|e| e.to_string())?;
    let mut taken = 0u64;
    loop {
        match solver.step().map_err(|e| e.to_string())? {
            OdeSolverStopReason::TstopReached => break,
            OdeSolverStopReason::InternalTimestep | OdeSolverStopReason::RootFound(..) => {}
        }
        taken += 1;
        if taken > MAX_STEPS {
            return Err(format!("more than {MAX_STEPS} steps before t = {:e}", solver.state().t));
        }
    }
    let steps = solver.get_statistics().number_of_steps as u64;
    Ok((solver.state().y.clone_as_vec(), steps))
}

fn run_radau5<P: Problem + Sync>(p: &P, y0: &[f64], t_end: f64, rtol: f64) -> RunResult {
    let n = p.len();
    if n > MAX_DIM {
        return Err(format!("dimension {n} exceeds {MAX_DIM}"));
    }
    let s: Vec<f64> = (0..n).map(|i| p.scale(i)).collect();
    let (s_f, s_j) = (s.clone(), s.clone());
    let mut system = System::new(n, move |f: &mut Vector, t: f64, z: &Vector, _: &mut NoArgs| {
        let mut y = [0.0; MAX_DIM];
        let mut out = [0.0; MAX_DIM];
        for i in 0..n {
            y[i] = z[i] * s_f[i];
        }
        p.rhs(t, &y[..n], &mut out[..n]);
        for i in 0..n {
            f[i] = out[i] / s_f[i];
        }
        Ok(())
    });
    system
        .set_jacobian(
            Some(n * n),
            Sym::No,
            move |jj: &mut CooMatrix, alpha: f64, t: f64, z: &Vector, _: &mut NoArgs| {
                let mut y = [0.0; MAX_DIM];
                let mut jac = [0.0; MAX_DIM * MAX_DIM];
                for i in 0..n {
                    y[i] = z[i] * s_j[i];
                }
                p.jacobian(t, &y[..n], &mut jac[..n * n]);
                jj.reset();
                for j in 0..n {
                    for i in 0..n {
                        jj.put(i, j, alpha * jac[i + j * n] * s_j[j] / s_j[i])?;
                    }
                }
                Ok(())
            },
        )
        .map_err(String::from)?;
    if (0..n).any(|i| p.mass(i) != 1.0) {
        // Diagonal, so the scaling leaves it unchanged: S⁻¹ M S = M.
        system
            .set_mass(Some(n), Sym::No, move |mm: &mut CooMatrix| {
                mm.reset();
                for i in 0..n {
                    mm.put(i, i, p.mass(i)).expect("n entries fit the n reserved");
                }
            })
            .map_err(String::from)?;
    }
    let mut params = Params::new(RussellMethod::Radau5);
    params.set_tolerances(rtol, rtol, None).map_err(String::from)?;
    params.step.n_step_max = MAX_STEPS as usize;
    // By default Radau5 factorizes and solves its real and complex systems on two threads it
    // spawns at every factorization and every Newton iteration: for a system of a few
    // components that costs far more than the linear algebra (a thread spawn per iteration),
    // and our integrators run on one thread.
    params.radau5.concurrent = false;
    let mut solver = OdeSolver::new(params, system).map_err(String::from)?;
    let mut z = Vector::from(&y0.iter().zip(&s).map(|(y, s)| y / s).collect::<Vec<f64>>());
    let mut args: NoArgs = 0;
    solver
        .solve(&mut z, 0.0, t_end, None, &mut args, None)
        .map_err(String::from)?;
    let y = (0..n).map(|i| z[i] * s[i]).collect();
    Ok((y, solver.stats().n_accepted as u64))
}

fn run_peer<P: Problem + Sync>(p: &P, peer: Peer, y0: &[f64], t_end: f64, rtol: f64) -> RunResult {
    let run = || match peer {
        Peer::RussellRadau5 => run_radau5(p, y0, t_end, rtol),
        _ => run_diffsol(p, peer, y0, t_end, rtol),
    };
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|panic| Err(format!("panicked: {}", nanopush_instrument::panic_message(&*panic))))
}

#[allow(clippy::too_many_arguments)]
fn problem_points<P: Problem + Sync>(
    name: &str,
    p: &P,
    y0: &[f64],
    t_end: f64,
    reference: &[f64],
    reps: usize,
    min_rtol: f64,
    out: &mut Vec<PeerPoint>,
) {
    for peer in Peer::ALL {
        for rtol in tolerances(min_rtol) {
            let (result, wall) = timed(reps, || run_peer(p, peer, y0, t_end, rtol));
            let (final_error, steps, failure) = match result {
                Ok((y, steps)) => (max_relative_error(&y, reference), steps, None),
                Err(e) => (f64::NAN, 0, Some(e)),
            };
            out.push(PeerPoint {
                problem: name.into(),
                solver: peer.name().into(),
                rtol,
                final_error,
                wall_time: wall,
                steps,
                failure,
            });
        }
    }
}

/// Every peer of [`SOLVERS`] on Van der Pol (ε = 1e-6, t = 2) and Robertson (t = 1e11), at each
/// of the report's tolerances down to `min_rtol`, `reps` timed repetitions each (median kept).
/// A failing or panicking peer gives a point with its message in `failure`.
pub fn peer_points(reps: usize, min_rtol: f64) -> Vec<PeerPoint> {
    let mut out = Vec::new();
    problem_points(
        "van-der-pol",
        &VanDerPol { eps: 1e-6 },
        &VanDerPol::Y0,
        VanDerPol::T_END,
        &VanDerPol::REFERENCE,
        reps,
        min_rtol,
        &mut out,
    );
    problem_points(
        "robertson",
        &Robertson,
        &Robertson::Y0,
        Robertson::T_END,
        &Robertson::REFERENCE,
        reps,
        min_rtol,
        &mut out,
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peer's row of the report: no error for a failed run, and none of what a peer does not
    /// report (trajectory error, estimate, rejected steps).
    #[test]
    fn a_peers_row_has_only_what_the_peer_reports() {
        let failed = PeerPoint {
            problem: "robertson".into(),
            solver: "russell-radau5".into(),
            rtol: 1e-6,
            final_error: f64::NAN,
            wall_time: 0.25,
            steps: 0,
            failure: Some("too many steps".into()),
        };
        let row = AccuracyPoint::from(&failed);
        assert_eq!(
            (row.method.as_str(), row.final_error, row.failure.as_deref()),
            ("russell-radau5", None, Some("too many steps"))
        );
        let solved = PeerPoint {
            final_error: 1e-8,
            steps: 120,
            failure: None,
            ..failed
        };
        let row = AccuracyPoint::from(&solved);
        assert_eq!(
            (row.final_error, row.steps, row.rejected, row.failure),
            (Some(1e-8), 120, 0, None)
        );
        assert_eq!(
            (row.trajectory_error, row.estimated_error, row.estimate_rtol),
            (None, None, None)
        );
    }

    /// A wrong wrapping (transposed Jacobian, unscaled state, wrong tolerance) would show up as
    /// a failure or a large error here.
    #[test]
    fn every_peer_solves_both_classical_problems() {
        let points = peer_points(1, 1e-6);
        let at = |problem: &str, solver: &str| {
            points
                .iter()
                .find(|p| p.problem == problem && p.solver == solver && p.rtol == 1e-6)
                .unwrap_or_else(|| panic!("no point for {problem} / {solver}"))
        };
        for problem in ["van-der-pol", "robertson"] {
            for solver in SOLVERS {
                let p = at(problem, solver);
                assert_eq!(p.failure, None, "{problem} / {solver}");
                assert!(p.final_error < 1e-2, "{problem} / {solver}: error {}", p.final_error);
                assert!(p.steps > 0, "{problem} / {solver}: no steps reported");
            }
        }
        assert_eq!(points.len(), 2 * SOLVERS.len() * tolerances(1e-6).count());
    }

    /// The table for docs/validation.md ("Our default against the best peer at equal error"):
    /// `cargo test --release -p nanopush-study peer_table -- --ignored --nocapture`.
    #[test]
    #[ignore = "slow: every peer down to rtol 1e-10, three repetitions"]
    fn peer_table() {
        println!("| problem | solver | rtol | final error | wall time (s) | steps | failure |");
        println!("|---|---|---|---|---|---|---|");
        for p in peer_points(3, 1e-10) {
            println!(
                "| {} | {} | {:.0e} | {:.3e} | {:.3e} | {} | {} |",
                p.problem,
                p.solver,
                p.rtol,
                p.final_error,
                p.wall_time,
                p.steps,
                p.failure.as_deref().unwrap_or("")
            );
        }
    }
}
