//! Forward-mode dual numbers: ours (`numerics::dual::{Dual, DualN}`) against the `num-dual`
//! crate (`Dual64`, `DualSVec64<N>`), in the same run, on the physics' own code: the force laws
//! and the JKR contact are generic over `Real`, so both types run the very same functions (the
//! crate's types through a zero-cost newtype that forwards every operation to num-dual's own
//! `DualNum` rules: `sqrt`, `ln`, `powf`, `atan2`, `recip`).
//!
//! - `derivative/*`: `f(h)` and `f'(h)` of one force law, one scalar dual (what the force curve's
//!   `derivative` does): the default scene's tip-particle + particle-substrate long-range forces at
//!   a 1 nm gap, and its particle-substrate JKR load at 0.2 nm indentation.
//! - `lanes{N}/*`: the pushing model's Jacobian pass in miniature (the model's `eval` is private):
//!   the contact geometry of the model (tip from stage and deflection, particle position, the gap
//!   as a distance, the contact angle by `atan2`), both long-range forces and both JKR loads on
//!   those gaps, with the states seeded in `N`-lane duals as `PushModel::derivatives` does
//!   (N = 9 for 5..=8 states, 13 for 9..=12).
//!
//! Run: `nice -n 10 cargo bench -p nanopush-instrument --bench dual -- --warm-up-time 1 --measurement-time 3`.
//! Results and the decision: docs/own-or-crate.md.

use std::hint::black_box;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

use criterion::{Criterion, criterion_group, criterion_main};
use nanopush_instrument::numerics::dual::{Dual, DualN, Real, derivative};
use nanopush_instrument::physics::forces::capillary::Meniscus;
use nanopush_instrument::physics::pushing::params::PushParams;
use num_dual::{Dual64, DualNum, DualSVec64};

mod common;

/// num-dual's scalar dual, as a `Real`.
#[derive(Clone, Copy, Debug)]
struct Nd(Dual64);
/// num-dual's `N`-lane dual, as a `Real`.
#[derive(Clone, Copy, Debug)]
struct NdN<const N: usize>(DualSVec64<N>);

macro_rules! forward_ops {
    ($t:ident $(, $n:ident)?) => {
        impl<$(const $n: usize)?> Add for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn add(self, o: Self) -> Self { $t(self.0 + o.0) }
        }
        impl<$(const $n: usize)?> Sub for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn sub(self, o: Self) -> Self { $t(self.0 - o.0) }
        }
        impl<$(const $n: usize)?> Mul for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn mul(self, o: Self) -> Self { $t(self.0 * o.0) }
        }
        impl<$(const $n: usize)?> Div for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn div(self, o: Self) -> Self { $t(self.0 / o.0) }
        }
        impl<$(const $n: usize)?> Neg for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn neg(self) -> Self { $t(-self.0) }
        }
        impl<$(const $n: usize)?> AddAssign for $t<$($n)?> {
            #[inline]
            fn add_assign(&mut self, o: Self) { self.0 += o.0 }
        }
        impl<$(const $n: usize)?> Add<f64> for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn add(self, o: f64) -> Self { $t(self.0 + o) }
        }
        impl<$(const $n: usize)?> Sub<f64> for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn sub(self, o: f64) -> Self { $t(self.0 - o) }
        }
        impl<$(const $n: usize)?> Mul<f64> for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn mul(self, o: f64) -> Self { $t(self.0 * o) }
        }
        impl<$(const $n: usize)?> Div<f64> for $t<$($n)?> {
            type Output = Self;
            #[inline]
            fn div(self, o: f64) -> Self { $t(self.0 / o) }
        }
        impl<$(const $n: usize)?> PartialEq for $t<$($n)?> {
            fn eq(&self, o: &Self) -> bool { self.0.re == o.0.re }
        }
        impl<$(const $n: usize)?> PartialOrd for $t<$($n)?> {
            fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> { self.0.re.partial_cmp(&o.0.re) }
        }
        impl<$(const $n: usize)?> Real for $t<$($n)?> {
            #[inline]
            fn cst(v: f64) -> Self { $t(DualNum::from_re(v)) }
            #[inline]
            fn re(self) -> f64 { self.0.re }
            #[inline]
            fn sqrt(self) -> Self { $t(DualNum::sqrt(&self.0)) }
            #[inline]
            fn ln(self) -> Self { $t(DualNum::ln(&self.0)) }
            #[inline]
            fn powf(self, n: f64) -> Self { $t(DualNum::powf(&self.0, n)) }
            #[inline]
            fn recip(self) -> Self { $t(DualNum::recip(&self.0)) }
            #[inline]
            fn atan2(self, x: Self) -> Self { $t(DualNum::atan2(&self.0, x.0)) }
        }
    };
}
forward_ops!(Nd);
forward_ops!(NdN, N);

fn params() -> PushParams {
    common::shipped_scene("paper-default").push_params()
}

/// Both long-range forces at gap `h` (N).
fn long_range<T: Real>(p: &PushParams, h: T) -> T {
    p.interactions.tip_particle_force(h, Meniscus::Formed) + p.interactions.particle_substrate_force(h)
}

/// The model's contact geometry and force laws on six states (stage, two deflections, particle
/// y, z, rotation): four outputs, as the rows of the right-hand side that carry the forces.
fn model_like<T: Real>(p: &PushParams, x: &[T; 6]) -> [T; 4] {
    let (s, zy, zz, y, z, th) = (x[0], x[1], x[2], x[3], x[4], x[5]);
    let (ca, sa) = (p.cantilever.tilt.cos(), p.cantilever.tilt.sin());
    // Tip centre from the stage and the deflection in the tilted cantilever axes.
    let ty = s + zy * ca - zz * sa - p.r_t * p.beta.cos();
    let tz = zy * sa + zz * ca + (p.r_t + p.r_a) * p.beta.sin();
    let (dy, dz) = (y - ty, z - tz);
    let dist = (dy * dy + dz * dz).sqrt();
    let gap_ta = dist - (p.r_t + p.r_a);
    let gap_as = z + p.interactions.a0;
    let angle = dz.atan2(dy);
    let a0 = p.interactions.a0;
    let f_ta = p.interactions.tip_particle_force(gap_ta.max_c(a0), Meniscus::Formed)
        + p.jkr_ta.load_from_indentation(-gap_ta).unwrap_or(T::cst(0.0));
    let f_as = p.interactions.particle_substrate_force(gap_as.max_c(a0))
        + p.jkr_as.load_from_indentation(-z).unwrap_or(T::cst(0.0));
    let (c, sn) = (dy / dist, dz / dist);
    [
        f_ta * c - (s - y) * p.k_as_t,
        f_ta * sn + f_as - z * p.k_as_t,
        (th * p.r_a - y) * p.k_ta_t + angle * f_ta,
        f_as * (p.mu_as_k + 1.0) - zz * p.cantilever.k_c,
    ]
}

/// A state 20 nm into a push: tip touching the particle with a little indentation.
fn state(p: &PushParams) -> [f64; 6] {
    let ca = p.cantilever.tilt.cos();
    let s = 20e-9;
    let ty = s - p.r_t * p.beta.cos();
    let y = ty + (p.r_t + p.r_a - 0.2e-9) * p.beta.cos() * ca.signum();
    [s, 1e-9, -2e-9, y, -0.1e-9, 3e-3]
}

fn ours_lanes<const N: usize>(p: &PushParams, x: &[f64; 6], jac: &mut [[f64; 6]; 4]) {
    let xd: [DualN<N>; 6] = std::array::from_fn(|j| DualN::seed(x[j], j));
    let out = model_like(p, &xd);
    for (row, o) in jac.iter_mut().zip(out) {
        row.copy_from_slice(&o.eps[..6]);
    }
}

fn crate_lanes<const N: usize>(p: &PushParams, x: &[f64; 6], jac: &mut [[f64; 6]; 4]) {
    let xd: [NdN<N>; 6] = std::array::from_fn(|j| NdN(DualSVec64::<N>::from_re(x[j]).derivative(j)));
    let out = model_like(p, &xd);
    for (row, o) in jac.iter_mut().zip(out) {
        match &o.0.eps.0 {
            Some(e) => row.copy_from_slice(&e.as_slice()[..6]),
            None => *row = [0.0; 6],
        }
    }
}

fn duals(c: &mut Criterion) {
    let p = params();
    let mut group = c.benchmark_group("dual");

    // One scalar dual through one force law.
    let h = 1e-9;
    let (v1, d1) = derivative(|h| long_range(&p, h), h);
    let d2 = long_range(&p, Nd(Dual64::from_re(h).derivative()));
    assert!((v1 - d2.0.re).abs() <= 1e-12 * v1.abs() && (d1 - d2.0.eps).abs() <= 1e-9 * d1.abs());
    group.bench_function("derivative/long_range/ours", |b| {
        b.iter(|| derivative(|h| long_range(&p, h), black_box(h)))
    });
    group.bench_function("derivative/long_range/num_dual", |b| {
        b.iter(|| {
            let d = long_range(&p, Nd(Dual64::from_re(black_box(h)).derivative()));
            (d.0.re, d.0.eps)
        })
    });
    let delta = 0.2e-9;
    let jkr = |d: Dual| p.jkr_as.load_from_indentation(d).expect("in contact");
    let jkr_nd = |d: Nd| p.jkr_as.load_from_indentation(d).expect("in contact");
    let (w1, e1) = derivative(jkr, delta);
    let w2 = jkr_nd(Nd(Dual64::from_re(delta).derivative()));
    assert!((w1 - w2.0.re).abs() <= 1e-12 * w1.abs() && (e1 - w2.0.eps).abs() <= 1e-9 * e1.abs());
    group.bench_function("derivative/jkr/ours", |b| b.iter(|| derivative(jkr, black_box(delta))));
    group.bench_function("derivative/jkr/num_dual", |b| {
        b.iter(|| {
            let d = jkr_nd(Nd(Dual64::from_re(black_box(delta)).derivative()));
            (d.0.re, d.0.eps)
        })
    });

    // The Jacobian pass, N lanes.
    let x = state(&p);
    let (mut j1, mut j2) = ([[0.0; 6]; 4], [[0.0; 6]; 4]);
    ours_lanes::<13>(&p, &x, &mut j1);
    crate_lanes::<13>(&p, &x, &mut j2);
    for (r1, r2) in j1.iter().zip(&j2) {
        for (a, b) in r1.iter().zip(r2) {
            assert!(
                (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300),
                "{j1:?}\n{j2:?}"
            );
        }
    }
    group.bench_function("lanes9/ours", |b| {
        b.iter(|| ours_lanes::<9>(&p, black_box(&x), &mut j1))
    });
    group.bench_function("lanes9/num_dual", |b| {
        b.iter(|| crate_lanes::<9>(&p, black_box(&x), &mut j2))
    });
    group.bench_function("lanes13/ours", |b| {
        b.iter(|| ours_lanes::<13>(&p, black_box(&x), &mut j1))
    });
    group.bench_function("lanes13/num_dual", |b| {
        b.iter(|| crate_lanes::<13>(&p, black_box(&x), &mut j2))
    });
    group.finish();
}

criterion_group!(benches, duals);
criterion_main!(benches);
