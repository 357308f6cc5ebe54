//! A dense LU with partial pivoting on fixed-size storage: for the ≤ 12 × 12 iteration
//! matrices of the implicit methods, with no allocation (nalgebra's LU allocates its
//! permutation).

// Numerical kernels index several arrays with one loop variable: index loops are clearer.
#![allow(clippy::needless_range_loop)]

use super::problem::MAX_DIM;

/// An LU factorization `P A = L U` of an `n × n` matrix stored column-major.
#[derive(Debug, Clone, Copy)]
pub struct Lu {
    n: usize,
    a: [f64; MAX_DIM * MAX_DIM],
    piv: [usize; MAX_DIM],
}

impl Default for Lu {
    fn default() -> Self {
        Lu {
            n: 0,
            a: [0.0; MAX_DIM * MAX_DIM],
            piv: [0; MAX_DIM],
        }
    }
}

impl Lu {
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
    }
}
