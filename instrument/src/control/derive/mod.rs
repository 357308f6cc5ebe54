//! The strategy of Sec 2.1 derived from the scene's model, instead of tuned by hand for each
//! scene (`nanopush plan`; `push` and the server use it for every setting the scene does not
//! give by hand).
//!
//! The model's push at constant speed ([`predict`](crate::control::estimator::predict)) gives what the strategy needs: the
//! stick-phase peak deflection `ζ_peak` before the particle-substrate separation `t*`, the tip
//! travel to it, the settled deflection `ζ°` after it, and, lifting the tip until it lets go,
//! the lift that takes and the drag it causes. From these, with the readout (gain `g`, noise
//! `σ`, periodic perturbation `p`, full scale) and the stage (`f_y`):
//!
//! - **β**: the first of 30°, 45°, 20°, 60°, 15°, 70°, 10°, 80° whose parking height
//!   `h = Rₐ − Rₜ + (Rₐ + Rₜ) sin β` keeps the apex above the substrate, lies above the height
//!   where the tip snaps in to it (auto-parking detects the substrate there, and the tip rises
//!   from it to `h`: a 50 nm particle at 99 % humidity has none), and whose predicted push
//!   passes every check below (the paper's 30° first).
//! - **set point** `ζ_set = 0.6 ζ_peak`: reached before the particle moves; its reading must be
//!   at least `10 (σ + p)` from the baseline.
//! - **safety limit**: `max(2.5 ζ_peak g, ζ_peak g + 10σ)` from the baseline, and on the push
//!   side beyond what auto-parking reads at the touch of the substrate (the substrate threshold
//!   plus 1.5 ticks of the approach, `1.5 v_z Δt g`), within 90 % of the readout's room on the
//!   push side, which must hold twice the peak.
//! - **`t*` is seen**: the drop `(ζ_peak − ζ°) g` at least `12σ + 2p` (the detector's margin
//!   is a third of it, at least 4σ); **particle lost** at half the settled reading, which
//!   must be at least `8σ + 2p`, or no lost-particle test (0) when the model's settled push
//!   rolls the particle on in front of the tip with a reading under that (at the baseline, or
//!   past it on the other side); such a plan is pushed under xy control only, and dry-run across
//!   the slope too. The model's push is run until it has settled (its lag and `ζ_z` steady).
//! - **V**: at most the paper's 1 µm/s; at most the travel between the set point and the peak
//!   in 1.5 ticks of 1 ms (the search stops before the particle shears); at most
//!   `tolerance · 2π f_y / 4`, so the stage's ringing at the stop (`≈ V/(2π f_y)`) stays
//!   within a quarter of the tolerance.
//! - **Δ** `= (Rₐ + Rₜ)/4` within [5, 100] nm; **approach distance**: the clearance the tip
//!   needs to touch down beside the particle, `2√(Rₐ Rₜ) − (Rₐ + Rₜ) cos β` when positive,
//!   plus four local-scan pixels (where the scan may have put it) and two steps; **search
//!   range**: twice that plus the model's travel to the set point and four steps.
//! - **start height** (the retraction's): above the tallest particle by a quarter of its height
//!   (at least 0.5 µm) plus the substrate's rise over the stage's diagonal (the tip travels at
//!   a fixed height: `|tilt| · √2 · range`) and four RMS of roughness, and above the parking
//!   height plus 1.25 × the lift the model needs to let go, plus 0.2 µm; at most 50 µm.
//! - **adhesion**: the pull-off from the substrate after auto-parking bends the lever the
//!   other way by up to the tip's adhesion over `k_c`, and may saturate the readout on that
//!   side: the strategy rides that out while it rises, until the tip lets go, within
//!   `1.5 (F_ad/k_c + L_t + δ_b + a₀) + 10 nm` of the detected substrate
//!   ([`crate::control::strategy::pull_off`]); that rise must be at most the 50 µm the
//!   strategy may lift.
//! - **stage**: settled within 0.1 s of a step, `Q/(π f_y) ≤ 0.1 s` (the paper's stage:
//!   25 ms). A stage softer than `20 max(k_y, k_z)` (the paper's is 86 times stiffer than its
//!   lever) is warned about, not refused: it yields under the push, but the pushing model
//!   (Eq 13, the load through the stage's stiffness) predicts that yield, and the dry run judges
//!   the result.
//! - **longest push**: the substrate's slope moves the contact angle by at most 5° a push,
//!   `|slope| · L ≤ 0.087 (Rₐ + Rₜ) cos β`, within [0.2, 20] µm (where the least push breaks the
//!   bound, the reason says by how much); longer moves are split and each leg re-parks.
//! - **time-out**: three times the longest phase (the longest push at V, the approach from
//!   twice the start height), within [120, 600] s.
//!
//! Each angle whose predicted push passes these checks gets its settings and a **dry run**: the
//! whole strategy (local scan, park, search, push, retract, scan after, corrections) on the
//! scene's model with another noise and roughness realization, a push of the longest leg the
//! plan allows (within [0.3, 1] µm) up the substrate's slope and one down it, each judged like a
//! real one. The first angle whose dry run
//! ends `ok` is the plan; the checks say why a scene fails in the model's terms, the dry run
//! catches what they do not (a true peak above twice the model's, a particle lost in the noise).
//!
//! A value the scene gives by hand ([`crate::scene::hand_set`]) wins; when it fails a check, the
//! plan warns. When no derived strategy can pass, the plan is refused, naming the field to
//! change and the value it would need ([`Refusal`]).

mod adhesion_field;
mod advice;
mod choice;
mod contact_angle;
mod derivation;
mod dry_run;
mod push_checks;
mod readout;
mod scene_checks;
mod settings;
#[cfg(test)]
mod tests;

pub use choice::{Advice, AdviceKey, Choice, DerivedStrategy, Refusal, SWITCHES, short};

use crate::control::estimator::PushPrediction;
use crate::control::strategy::BACK_OFF;
use crate::scene::Scene;
use derivation::Derivation;

/// The default tolerance of a push (m): `ok` within [`nanopush_proto::push::TOLERANCE_NM`] of
/// the target.
pub const DEFAULT_TOLERANCE: f64 = nanopush_proto::push::TOLERANCE_NM * 1e-9;

/// The set point as a fraction of the stick-phase peak deflection.
pub const SET_FRACTION: f64 = 0.6;

/// Contact angles tried, in order (degrees): the paper's 30° first.
pub const BETAS_DEG: [f64; 8] = [30.0, 45.0, 20.0, 60.0, 15.0, 70.0, 10.0, 80.0];

/// The least the tip's apex may park below the particle's top on a smooth substrate (m): the
/// detected substrate's own error (the snap-in's estimate, the noise at the touch).
pub const OVER_TOP_MARGIN: f64 = 1e-9;

/// The shortest push the plan splits a move into when a longer one loses the particle in its
/// dry run (m).
pub const MIN_PUSH: f64 = 0.1e-6;

/// Below this many times the lever's stiffness the stage's yield under the push is warned about.
pub const STAGE_STIFFNESS_RATIO: f64 = 20.0;

/// The stage's ringing must die within this (s): the paper's stage (250 Hz, Q = 20) takes 25 ms.
pub const STAGE_SETTLE: f64 = 0.1;

/// The longest a derived phase time-out may be (s): a slower push fails with a time-out.
pub const MAX_TIMEOUT: f64 = 600.0;

/// The longest simulated time a dry run may take (s): a slower plan is not dry-run (and says so).
pub const MAX_DRY_RUN: f64 = 60.0;

/// Highest start height the scene allows (m), `strategy.start_height_um`'s upper bound.
const MAX_START: f64 = crate::scene::START_HEIGHT_UM.hi() * 1e-6;

/// The paper's stage speed (m/s), the plan's upper bound.
const PAPER_SPEED: f64 = 1e-6;
/// The most the tip may press into the substrate before the reading shows the touch (m).
const TOUCH_PRESS: f64 = 10e-9;
/// The stiffest lever a scene allows (N/m).
const MAX_STIFFNESS: f64 = crate::scene::STIFFNESS_N_PER_M.hi();

/// Control tick (s).
const TICK: f64 = 1e-3;

/// The readout must hold this many times the model's stick-phase peak: the instrument's peak
/// exceeds the model's where its contact angle or its substrate differ a little.
const PEAK_SPARE: f64 = 2.0;

/// What a predicted push at one β says of the strategy: the numbers the settings derive from.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    beta_deg: f64,
    parking: f64,
    prediction: PushPrediction,
}

/// Why a candidate fails, before it is a [`Refusal`].
#[derive(Clone)]
struct Fails {
    code: &'static str,
    /// The values `field` names, unchecked.
    advice: Vec<Advice>,
    reason: String,
    field: String,
}

/// Derives the strategy for pushing particle `id` of `scene` to within `tolerance` (m).
/// A refusal that names values has each checked ([`advice::check`]): the plan is derived again
/// with the value, and its field says which value passes the dry run.
pub fn derive(scene: &Scene, id: u32, tolerance: f64) -> Result<DerivedStrategy, Refusal> {
    Derivation::new(scene, id, tolerance)?
        .run()
        .map_err(|r| advice::check(scene, id, tolerance, r))
}
