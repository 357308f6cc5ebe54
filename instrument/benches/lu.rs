//! The dense LU of the implicit integrators: the hand-written one that
//! `numerics/integrate/linalg.rs` carried (frozen here, `mod hand`) against nalgebra's fixed-size
//! `SMatrix::<f64, N, N>::lu()` + `LU::solve_mut` (no allocation either) as `linalg.rs` now ships
//! it, in the same run, on the real workload: the Rodas4 iteration matrix `M/(hγ) − J` with the
//! exact Jacobian `J` of each shipped scene in steady pushing (20 ms in, as `benches/tick.rs`),
//! `h` = 1 µs, `γ` = 0.25. The state dimension is a run-time value (3..=12), so the nalgebra side
//! dispatches once on it to the matching compile-time size.
//!
//! Two workloads per scene: factor + one solve (what `equilibrate`/`state_rate` do), and factor +
//! six solves (one Rodas4 step: one factorization, six stage solves).
//!
//! Run: `nice -n 10 cargo bench -p nanopush-instrument --bench lu -- --warm-up-time 1 --measurement-time 3`.
//! Results and the decision: docs/own-or-crate.md.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};

mod common;

/// What `linalg.rs`'s `use super::problem::MAX_DIM` finds.
mod problem {
    pub use nanopush_instrument::numerics::integrate::MAX_DIM;
}
/// The shipped LU (nalgebra's, dispatched on the size), compiled from the crate's own source file
/// (it is crate-private).
#[allow(dead_code, unused_imports)]
#[path = "../src/numerics/integrate/linalg.rs"]
mod linalg;

/// The hand-written LU as it was in `numerics/integrate/linalg.rs` before nalgebra's replaced it
/// (column-major storage, partial pivoting, rank-1 updates over column slices).
#[allow(clippy::needless_range_loop)]
mod hand {
    use super::problem::MAX_DIM;

    /// An LU factorization `P A = L U` of an `n × n` matrix stored column-major.
    #[derive(Debug, Clone, Copy)]
    pub struct HandLu {
        n: usize,
        a: [f64; MAX_DIM * MAX_DIM],
        piv: [usize; MAX_DIM],
    }

    impl Default for HandLu {
        fn default() -> Self {
            HandLu {
                n: 0,
                a: [0.0; MAX_DIM * MAX_DIM],
                piv: [0; MAX_DIM],
            }
        }
    }

    impl HandLu {
        /// Factorizes `a` (column-major `n × n`). Returns `false` when it is singular.
        pub fn factor(&mut self, n: usize, a: &[f64]) -> bool {
            self.n = n;
            self.a[..n * n].copy_from_slice(&a[..n * n]);
            let m = &mut self.a[..n * n];
            for k in 0..n {
                // Pivot: the largest entry of column k at or below the diagonal.
                let col_k = &m[k * n..k * n + n];
                let (mut p, mut best) = (k, col_k[k].abs());
                for (i, v) in col_k.iter().enumerate().skip(k + 1) {
                    if v.abs() > best {
                        best = v.abs();
                        p = i;
                    }
                }
                self.piv[k] = p;
                if best == 0.0 || !best.is_finite() {
                    return false;
                }
                if p != k {
                    for j in 0..n {
                        m.swap(j * n + k, j * n + p);
                    }
                }
                // Multipliers, then the rank-1 update of the trailing columns.
                let (left, right) = m.split_at_mut((k + 1) * n);
                let col_k = &mut left[k * n..];
                let inv = 1.0 / col_k[k];
                for l in &mut col_k[k + 1..] {
                    *l *= inv;
                }
                let lk = &col_k[k + 1..];
                for col_j in right.chunks_exact_mut(n) {
                    let f = col_j[k];
                    if f != 0.0 {
                        for (c, &l) in col_j[k + 1..].iter_mut().zip(lk) {
                            *c -= l * f;
                        }
                    }
                }
            }
            true
        }

        /// Solves `A x = b` in place (forward and back substitution over column slices).
        pub fn solve(&self, b: &mut [f64]) {
            let n = self.n;
            let b = &mut b[..n];
            for k in 0..n {
                b.swap(k, self.piv[k]);
            }
            for j in 0..n {
                let bj = b[j];
                if bj != 0.0 {
                    let col = &self.a[j * n + j + 1..j * n + n];
                    for (bi, &l) in b[j + 1..].iter_mut().zip(col) {
                        *bi -= l * bj;
                    }
                }
            }
            for j in (0..n).rev() {
                let col = &self.a[j * n..j * n + j + 1];
                b[j] /= col[j];
                let bj = b[j];
                for (bi, &u) in b[..j].iter_mut().zip(&col[..j]) {
                    *bi -= u * bj;
                }
            }
        }
    }
}
use hand::HandLu;

/// An LU to benchmark: factor an `n`×`n` column-major matrix, solve in place.
trait Factor {
    fn factor(&mut self, n: usize, a: &[f64]) -> bool;
    fn solve(&self, b: &mut [f64]);
}

impl Factor for HandLu {
    fn factor(&mut self, n: usize, a: &[f64]) -> bool {
        HandLu::factor(self, n, a)
    }
    fn solve(&self, b: &mut [f64]) {
        HandLu::solve(self, b)
    }
}

/// nalgebra's fixed-size LU, as shipped (`linalg::Lu`: the run-time size dispatched to the
/// compile-time one, a zero or non-finite pivot reported as singular).
impl Factor for linalg::Lu {
    fn factor(&mut self, n: usize, a: &[f64]) -> bool {
        linalg::Lu::factor(self, n, a)
    }
    fn solve(&self, b: &mut [f64]) {
        linalg::Lu::solve(self, b)
    }
}

/// Factor + `solves` solves.
fn factor_and_solve(lu: &mut impl Factor, n: usize, a: &[f64], b: &[f64], solves: usize, x: &mut [f64]) -> bool {
    if !lu.factor(n, a) {
        return false;
    }
    for _ in 0..solves {
        x[..n].copy_from_slice(&b[..n]);
        lu.solve(&mut x[..n]);
    }
    true
}

/// The Rodas4 iteration matrix `M/(hγ) − J` (column-major) and a right-hand side `f(t, x)` of a
/// shipped scene, 20 ms into a push.
fn workload(scene: &str) -> (usize, Vec<f64>, Vec<f64>) {
    let sim = common::warmed_up(scene);
    let (m, t, x, mode) = (&sim.model, sim.t, sim.x, sim.mode);
    let n = m.len();
    let mut jac = vec![0.0; n * n];
    m.jacobian(t, &x[..n], &mode, &mut jac);
    let mass = m.mass_diagonal();
    let (h, gamma) = (1e-6, 0.25);
    let mut a = vec![0.0; n * n];
    for j in 0..n {
        for i in 0..n {
            a[j * n + i] = -jac[j * n + i];
        }
        a[j * n + j] += mass[j] / (h * gamma);
    }
    let mut f = vec![0.0; n];
    m.rhs(t, &x[..n], &mode, &mut f);
    (n, a, f)
}

fn lu(c: &mut Criterion) {
    let mut group = c.benchmark_group("lu");
    for scene in [
        "minimal",
        "paper-default",
        "gold-14nm",
        "gold-latex-500nm",
        "paper-full-dynamics",
    ] {
        let (n, a, b) = workload(scene);
        // Same answer, bit for bit (same pivots, same operations in the same order).
        let (mut x1, mut x2) = ([0.0; 12], [0.0; 12]);
        let (mut ours, mut theirs) = (HandLu::default(), linalg::Lu::default());
        assert!(factor_and_solve(&mut ours, n, &a, &b, 1, &mut x1));
        assert!(factor_and_solve(&mut theirs, n, &a, &b, 1, &mut x2));
        assert_eq!(x1[..n], x2[..n], "{scene}: the two LUs disagree");
        for solves in [1, 6] {
            let name = format!("{scene}_n{n}/factor+{solves}solve");
            let mut x = [0.0; 12];
            group.bench_function(format!("{name}/hand_written"), |bch| {
                bch.iter(|| factor_and_solve(&mut ours, n, black_box(&a), black_box(&b), solves, &mut x))
            });
            group.bench_function(format!("{name}/nalgebra_smatrix"), |bch| {
                bch.iter(|| factor_and_solve(&mut theirs, n, black_box(&a), black_box(&b), solves, &mut x))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, lu);
criterion_main!(benches);
