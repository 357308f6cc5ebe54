//! The measures of one closed haptic cycle, computed from the rows of a trace and independent of
//! the program's own observers, with the grid of settings and operators they are taken over (the
//! in-process grid test, the end-to-end grid, the `nanopush-haptic-grid` benchmark):
//!
//! ```text
//! E        = −Σ F[n−1]·(x[n] − x[n−1])             the raw port's energy over the cycle (J)
//! chatter  = #{n : |F[n] − 2F[n−1] + F[n−2]| > 0.05 N}
//! tip      = max over 20-sample windows held in contact of max|F_tip − mean| / |mean|
//! ```
//!
//! A cell passes with `E ≥ −1 µJ`, `|F| ≤` the device's limit, `chatter ≤ 50` and `tip ≤ 0.1`.

use crate::bridge::CycleRow;

/// The position scales of the grid (nm/mm).
pub const GRID_NM_PER_MM: [f64; 4] = [1.0, 10.0, 100.0, 1000.0];
/// The pull-off scales of the grid (N).
pub const GRID_PULL_OFF_N: [f64; 4] = [0.1, 1.0, 2.5, 10.0];
/// The operators of the grid (`--operator`).
pub const GRID_OPERATORS: [&str; 5] = ["press", "tap", "stiff-grip", "loose-grip", "let-go"];
/// Lowest raw port energy a cell may end with (J).
pub const MIN_ENERGY: f64 = -1e-6;
/// Second difference of the hand force that counts as a chatter cycle (N).
pub const CHATTER_STEP: f64 = 0.05;
/// Chatter cycles a cell may have.
pub const MAX_CHATTER: usize = 50;
/// The tip-force window (samples at 1 kHz: 20 ms).
pub const TIP_WINDOW: usize = 20;
/// Largest swing of the tip force about its window's mean, as a fraction of the mean.
pub const TIP_SWING: f64 = 0.1;
/// A window counts as held in contact when every tip force in it is repulsive beyond this (N):
/// the law's contact threshold for the paper scene's lever (8 N/m × 0.2 nm).
pub const TIP_CONTACT: f64 = 1.6e-9;

/// One cell's measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellVerdict {
    /// Raw port energy at the end of the cycle (J).
    pub energy: f64,
    /// Chatter cycles.
    pub chatter: usize,
    /// Largest hand force (N).
    pub max_force: f64,
    /// The device's limit (N).
    pub force_limit: f64,
    /// Worst tip-force swing over the windows held in contact (fraction of the mean).
    pub tip_swing: f64,
    /// Windows held in contact.
    pub tip_windows: usize,
}

impl CellVerdict {
    /// Whether the cell meets every bound.
    pub fn passes(&self) -> bool {
        self.energy >= MIN_ENERGY
            && self.max_force <= self.force_limit + 1e-9
            && self.chatter <= MAX_CHATTER
            && self.tip_swing <= TIP_SWING
    }
}

impl std::fmt::Display for CellVerdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "E {:+.3e} J, chatter {}, |F| ≤ {:.2} N, tip swing {:.3} over {} windows: {}",
            self.energy,
            self.chatter,
            self.max_force,
            self.tip_swing,
            self.tip_windows,
            if self.passes() { "pass" } else { "FAIL" }
        )
    }
}

/// [`judge`] of a device running `per_tick` cycles per 1 ms tick: the energy from every row
/// (it is exact at any rate), the chatter, the force and the tip from every `per_tick`-th row
/// (the measures are defined on 1 ms samples).
pub fn judge_at(rows: &[CycleRow], per_tick: usize, force_limit: f64) -> CellVerdict {
    let every: Vec<CycleRow> = rows.iter().step_by(per_tick.max(1)).copied().collect();
    CellVerdict {
        energy: judge(rows, force_limit).energy,
        max_force: rows.iter().map(|r| r.force.abs()).fold(0.0, f64::max),
        ..judge(&every, force_limit)
    }
}

/// The measures of a cycle's rows (one per 1 kHz device cycle; rows without a handle sample are
/// skipped) on a device whose force limit is `force_limit` (N).
pub fn judge(rows: &[CycleRow], force_limit: f64) -> CellVerdict {
    let rows: Vec<&CycleRow> = rows.iter().filter(|r| r.handle.is_finite()).collect();
    let energy = -rows
        .windows(2)
        .map(|w| w[0].force * (w[1].handle - w[0].handle))
        .sum::<f64>();
    let chatter = rows
        .windows(3)
        .filter(|w| (w[2].force - 2.0 * w[1].force + w[0].force).abs() > CHATTER_STEP)
        .count();
    let max_force = rows.iter().map(|r| r.force.abs()).fold(0.0, f64::max);
    let (mut tip_swing, mut tip_windows) = (0.0f64, 0);
    for w in rows.chunks_exact(TIP_WINDOW) {
        if w.iter().all(|r| r.holding && r.tip_force > TIP_CONTACT) {
            let mean = w.iter().map(|r| r.tip_force).sum::<f64>() / TIP_WINDOW as f64;
            let swing = w.iter().map(|r| (r.tip_force - mean).abs()).fold(0.0, f64::max);
            tip_swing = tip_swing.max(swing / mean);
            tip_windows += 1;
        }
    }
    CellVerdict {
        energy,
        chatter,
        max_force,
        force_limit,
        tip_swing,
        tip_windows,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(handle: f64, force: f64, tip_force: f64, holding: bool) -> CycleRow {
        CycleRow {
            handle,
            force,
            tip_force,
            holding,
            ..CycleRow::default()
        }
    }

    /// A spring held over each step gives back more than it took (the hold's leak): seen as a
    /// negative energy; a force flipping ±0.1 N every cycle is chatter; a tip force swinging
    /// 20 % in a held window fails the bound.
    #[test]
    fn the_measures_see_a_leaking_spring_a_buzz_and_a_swinging_tip() {
        let k = 2000.0;
        let xs: Vec<f64> = (0..=100).chain((0..100).rev()).map(|i| -1e-5 * f64::from(i)).collect();
        let rows: Vec<CycleRow> = xs.iter().map(|&x| row(x, -k * x, 0.0, false)).collect();
        let v = judge(&rows, 2.5);
        // −Σ F Δx over the out-and-back path: −k/2 Σ Δx² = −1000 · 200 · 1e-10 J.
        assert!((v.energy + 2e-5).abs() < 1e-9, "{v:?}");
        assert!(!v.passes());
        let buzz: Vec<CycleRow> = (0..100)
            .map(|i| row(0.0, if i % 2 == 0 { 0.1 } else { -0.1 }, 0.0, false))
            .collect();
        assert_eq!(judge(&buzz, 2.5).chatter, 98);
        let tip: Vec<CycleRow> = (0..40)
            .map(|i| row(0.0, 0.0, if i == 30 { 12e-9 } else { 10e-9 }, true))
            .collect();
        let v = judge(&tip, 2.5);
        assert_eq!(v.tip_windows, 2);
        assert!(v.tip_swing > 0.1 && !v.passes(), "{v:?}");
        let calm: Vec<CycleRow> = (0..40).map(|_| row(0.0, 0.5, 10e-9, true)).collect();
        assert!(judge(&calm, 2.5).passes());
    }
}
