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
        let m = &mut self.a;
        for k in 0..n {
            let mut p = k;
            let mut best = m[k * n + k].abs();
            for i in k + 1..n {
                let v = m[k * n + i].abs();
                if v > best {
                    best = v;
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
            let inv = 1.0 / m[k * n + k];
            for i in k + 1..n {
                m[k * n + i] *= inv;
            }
            for j in k + 1..n {
                let f = m[j * n + k];
                if f != 0.0 {
                    for i in k + 1..n {
                        m[j * n + i] -= m[k * n + i] * f;
                    }
                }
            }
        }
        true
    }

    /// Solves `A x = b` in place.
    pub fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        let m = &self.a;
        for k in 0..n {
            b.swap(k, self.piv[k]);
        }
        for j in 0..n {
            let bj = b[j];
            if bj != 0.0 {
                for i in j + 1..n {
                    b[i] -= m[j * n + i] * bj;
                }
            }
        }
        for j in (0..n).rev() {
            b[j] /= m[j * n + j];
            let bj = b[j];
            for i in 0..j {
                b[i] -= m[j * n + i] * bj;
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
