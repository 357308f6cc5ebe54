//! The dense LU with partial pivoting of the implicit methods and the DAE consistency solves,
//! for their ≤ 12 × 12 matrices: nalgebra's fixed-size `SMatrix::<f64, N, N>::lu()`, which
//! allocates nothing (its permutation is fixed-size too), behind a run-time size `n`
//! dispatched once to the compile-time one. It replaced a hand-written LU: on the shipped scenes'
//! iteration matrices a Rodas4 step's factor + 6 solves takes 431 ns against 866 ns (n = 7,
//! paper-default) and 1.38 µs against 1.39 µs (n = 12); factor + 1 solve is 217 ns against 198 ns
//! (`benches/lu.rs`, one run on 2026-11-26, docs/own-or-crate.md). For finite matrices the two
//! pick the same pivots and do the same operations in the same order: the solutions are the same
//! bit for bit (the bench checks it on every shipped scene). A matrix holding a NaN can differ:
//! the old LU skipped zero multipliers and could call it regular and solve to NaN, where
//! nalgebra's LU carries the NaN to a pivot and [`Lu::factor`] reports it singular; either way the
//! integrator's step is rejected.

use nalgebra::linalg::LU;
use nalgebra::{Const, SMatrix, SVectorViewMut};

use super::problem::MAX_DIM;

/// An LU factorization `P A = L U` of an `n × n` matrix (`n` ≤ [`MAX_DIM`]) stored column-major.
#[derive(Debug, Clone, Copy, Default)]
pub struct Lu(Factors);

/// nalgebra's factorization at each compile-time size; `Empty` before the first `factor` (and
/// for `n` = 0, a system with nothing to solve).
#[derive(Debug, Clone, Copy, Default)]
enum Factors {
    #[default]
    Empty,
    N1(LU<f64, Const<1>, Const<1>>),
    N2(LU<f64, Const<2>, Const<2>>),
    N3(LU<f64, Const<3>, Const<3>>),
    N4(LU<f64, Const<4>, Const<4>>),
    N5(LU<f64, Const<5>, Const<5>>),
    N6(LU<f64, Const<6>, Const<6>>),
    N7(LU<f64, Const<7>, Const<7>>),
    N8(LU<f64, Const<8>, Const<8>>),
    N9(LU<f64, Const<9>, Const<9>>),
    N10(LU<f64, Const<10>, Const<10>>),
    N11(LU<f64, Const<11>, Const<11>>),
    N12(LU<f64, Const<12>, Const<12>>),
}

// One arm per size of `Factors`.
const _: () = assert!(MAX_DIM == 12);

/// Expands `$body` once per size, with `$lu` bound to the factorization and `$n` to its size.
macro_rules! each_size {
    ($f:expr, |$lu:ident, $n:ident| $body:expr, empty => $empty:expr) => {
        match $f {
            Factors::Empty => $empty,
            Factors::N1($lu) => {
                const $n: usize = 1;
                $body
            }
            Factors::N2($lu) => {
                const $n: usize = 2;
                $body
            }
            Factors::N3($lu) => {
                const $n: usize = 3;
                $body
            }
            Factors::N4($lu) => {
                const $n: usize = 4;
                $body
            }
            Factors::N5($lu) => {
                const $n: usize = 5;
                $body
            }
            Factors::N6($lu) => {
                const $n: usize = 6;
                $body
            }
            Factors::N7($lu) => {
                const $n: usize = 7;
                $body
            }
            Factors::N8($lu) => {
                const $n: usize = 8;
                $body
            }
            Factors::N9($lu) => {
                const $n: usize = 9;
                $body
            }
            Factors::N10($lu) => {
                const $n: usize = 10;
                $body
            }
            Factors::N11($lu) => {
                const $n: usize = 11;
                $body
            }
            Factors::N12($lu) => {
                const $n: usize = 12;
                $body
            }
        }
    };
}

impl Lu {
    /// Factorizes `a` (column-major `n × n`). Returns `false` when it is singular: a pivot is
    /// zero or not finite.
    pub fn factor(&mut self, n: usize, a: &[f64]) -> bool {
        fn mat<const N: usize>(a: &[f64]) -> SMatrix<f64, N, N> {
            SMatrix::from_column_slice(&a[..N * N])
        }
        self.0 = match n {
            0 => Factors::Empty,
            1 => Factors::N1(mat::<1>(a).lu()),
            2 => Factors::N2(mat::<2>(a).lu()),
            3 => Factors::N3(mat::<3>(a).lu()),
            4 => Factors::N4(mat::<4>(a).lu()),
            5 => Factors::N5(mat::<5>(a).lu()),
            6 => Factors::N6(mat::<6>(a).lu()),
            7 => Factors::N7(mat::<7>(a).lu()),
            8 => Factors::N8(mat::<8>(a).lu()),
            9 => Factors::N9(mat::<9>(a).lu()),
            10 => Factors::N10(mat::<10>(a).lu()),
            11 => Factors::N11(mat::<11>(a).lu()),
            12 => Factors::N12(mat::<12>(a).lu()),
            _ => panic!("LU of a {n} × {n} matrix: at most {MAX_DIM} × {MAX_DIM}"),
        };
        // The pivots are U's diagonal, read in place (`u()` would copy the matrix). nalgebra
        // skips a zero pivot's column and goes on; NaN and ±∞ pass through. Either is singular
        // here, as the caller then rejects the step.
        each_size!(&self.0, |f, N| {
            let packed = f.lu_internal();
            (0..N).all(|i| packed[(i, i)] != 0.0 && packed[(i, i)].is_finite())
        }, empty => true)
    }

    /// The determinant of the last factorized matrix (1 for `n` = 0): the product of the pivots,
    /// signed by the row permutation.
    pub fn determinant(&self) -> f64 {
        each_size!(&self.0, |f, _N| f.determinant(), empty => 1.0)
    }

    /// Solves `A x = b` in place with the last factorization (`b[..n]`).
    pub fn solve(&self, b: &mut [f64]) {
        each_size!(&self.0, |f, N| {
            // Singular factors are not solved with (`factor` said `false`), so this is `true`.
            let _ = f.solve_mut(&mut SVectorViewMut::<f64, N>::from_slice(&mut b[..N]));
        }, empty => ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_pivoting_system() {
        // [[0, 2, 1], [1, 1, 0], [3, 0, 1]] x = [5, 3, 6] → x = [1.5, 1.5, 1.5]... checked below.
        let rows = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]];
        let mut a = [0.0; 9];
        for (i, r) in rows.iter().enumerate() {
            for (j, v) in r.iter().enumerate() {
                a[j * 3 + i] = *v;
            }
        }
        let x = [1.0, -2.0, 0.5];
        let mut b: Vec<f64> = rows
            .iter()
            .map(|r| r.iter().zip(&x).map(|(a, b)| a * b).sum())
            .collect();
        let mut lu = Lu::default();
        assert!(lu.factor(3, &a));
        lu.solve(&mut b);
        for (u, v) in b.iter().zip(&x) {
            assert!((u - v).abs() < 1e-14);
        }
    }

    #[test]
    fn detects_singular() {
        let mut lu = Lu::default();
        assert!(!lu.factor(2, &[1.0, 2.0, 2.0, 4.0]));
        // A non-finite pivot is singular too.
        assert!(!lu.factor(2, &[f64::NAN, 1.0, 1.0, 1.0]));
        assert!(!lu.factor(2, &[1.0, 0.0, 0.0, f64::INFINITY]));
        // Nothing to solve.
        assert!(lu.factor(0, &[]));
        lu.solve(&mut []);
    }

    #[test]
    fn every_size_solves() {
        // A non-symmetric, pivoting-prone (small diagonal) system at every size up to MAX_DIM.
        for n in 1..=MAX_DIM {
            let mut a = [0.0; MAX_DIM * MAX_DIM];
            for j in 0..n {
                for i in 0..n {
                    a[j * n + i] = ((i * 7 + j * 3) % 11) as f64 - 5.0 + if i == j { 0.5 } else { 0.0 };
                }
            }
            let x: Vec<f64> = (0..n).map(|i| 1.0 + i as f64 * 0.25).collect();
            let mut b: Vec<f64> = (0..n).map(|i| (0..n).map(|j| a[j * n + i] * x[j]).sum()).collect();
            let mut lu = Lu::default();
            assert!(lu.factor(n, &a[..n * n]), "n = {n}");
            lu.solve(&mut b);
            for (u, v) in b.iter().zip(&x) {
                assert!((u - v).abs() < 1e-10, "n = {n}: {u} vs {v}");
            }
        }
    }
}
