//! One whole move as the operator asks for it, judged by the instrument: a local scan finds the
//! particle, the legs are planned and pushed, and a scan after the push measures where the
//! particle is. Within the tolerance of the target it is `ok`; outside it, a corrective push
//! from where the scan found it (the retraction's drag, a stick-slip push, a lagging stage),
//! up to [`MoveOptions::attempts`] pushes in all; still outside, `missed`, with the distance.
//! Used by `nanopush push`, the campaigns and the tests; the server runs its legs one tick at a
//! time and judges the same way ([`Verdict::judge`]).

use crate::afm::Afm;
use crate::control::moves::locate::MoveRoute;
use crate::control::moves::locate::{MoveError, MoveTarget, locate_near, route_move};
use crate::control::route::Leg;
use crate::control::strategy::StrategyParams;
use crate::control::strategy::runner::{Prepared, RunError, StrategyRun};
use crate::scan::{HeightImage, Located, ScanParams, Tip};
use crate::scene::Scene;
use std::collections::VecDeque;

/// How a move is judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveOptions {
    /// The particle must end within this of the target, as the scan after measures it (m).
    pub tolerance: f64,
    /// Pushes at most (the first and the corrections).
    pub attempts: u32,
    /// A brief stop during the first push: at this travel (m), for this long (s).
    pub pause: Option<(f64, f64)>,
}

/// Corrective pushes after the first, at most (three pushes in all).
pub const DEFAULT_ATTEMPTS: u32 = 3;

/// The move's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The scan after found the particle within the tolerance of the target.
    Ok {
        /// Its distance from the target, as measured (m).
        error: f64,
    },
    /// The scan after found it outside the tolerance after every attempt.
    Missed {
        /// Its distance from the target, as measured (m).
        error: f64,
    },
    /// A push failed (its code, e.g. `deflection_limit`): the tip retracted, the move stopped.
    Failed {
        /// The failure's code.
        code: &'static str,
    },
    /// The scan after the push did not find the particle.
    NotFound,
}

impl Verdict {
    /// Judges a measured position against the target.
    pub fn judge(measured: (f64, f64), target: (f64, f64), tolerance: f64) -> Verdict {
        let error = (measured.0 - target.0).hypot(measured.1 - target.1);
        if error <= tolerance {
            Verdict::Ok { error }
        } else {
            Verdict::Missed { error }
        }
    }

    /// `ok`, `missed`, `not_found` or the failure's code.
    pub fn code(&self) -> &'static str {
        match self {
            Verdict::Ok { .. } => "ok",
            Verdict::Missed { .. } => "missed",
            Verdict::Failed { code } => code,
            Verdict::NotFound => "not_found",
        }
    }
}

/// One push of a move.
#[derive(Debug, Clone, PartialEq)]
pub struct PushedLeg {
    /// Where the controller believed the particle was (m).
    pub from: (f64, f64),
    /// Where it was sent (m).
    pub to: (f64, f64),
    /// The attempt it belongs to (1 = the first, 2.. corrections).
    pub attempt: u32,
    /// The run.
    pub run: StrategyRun,
}

/// A whole move.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveRun {
    /// The local scan before, and the particle in it.
    pub before: (HeightImage, Located),
    /// The target (m).
    pub target: (f64, f64),
    /// Every push, in order.
    pub legs: Vec<PushedLeg>,
    /// The last scan, and the particle in it (when found).
    pub after: (HeightImage, Option<Located>),
    /// The outcome.
    pub verdict: Verdict,
    /// Pushes made (attempts begun).
    pub attempts: u32,
    /// When a `missed` move was not corrected because the stage's edge cut the last push short
    /// of the retraction's drag (and would cut a correction the same way): by how much (m).
    pub cut_short: Option<f64>,
}

/// How a move finds its particle and routes its legs, before its first push and after each
/// (the scan after), and what it computes once for the particle before pushing it.
pub trait MoveRouting {
    /// The particle believed at `near` (radius about `radius_hint`) located, and its legs to
    /// `target`.
    fn route(
        &mut self,
        afm: &Afm,
        near: (f64, f64),
        radius_hint: f64,
        target: MoveTarget,
    ) -> Result<MoveRoute, MoveError>;

    /// The model's prediction and the contact geometry for particle `id` as located with
    /// `radius` (m).
    fn prepare(&mut self, scene: &Scene, id: u32, radius: f64, params: &StrategyParams) -> Result<Prepared, RunError> {
        Prepared::new(scene, id, radius, params)
    }

    /// A local scan around `estimate` and the particle of radius about `radius` in it: between
    /// the legs of a move, and after a push that failed.
    fn locate(
        &mut self,
        scene: &Scene,
        afm: &Afm,
        estimate: (f64, f64),
        radius: f64,
    ) -> (HeightImage, Result<Located, crate::scan::LocateError>) {
        locate_near(
            &afm.surface(),
            Tip::from_scene(scene),
            ScanParams::from_scene(scene),
            estimate,
            radius,
            scene.file.stage.range_um * 1e-6,
        )
    }
}

/// `nanopush push`'s routing: a local scan finds the particle, and the legs go around the
/// particles the scene's overview scan and the corridors' scans show ([`route_move`]).
pub struct OverviewRouting<'a>(pub &'a Scene);

impl MoveRouting for OverviewRouting<'_> {
    fn route(
        &mut self,
        afm: &Afm,
        near: (f64, f64),
        radius_hint: f64,
        target: MoveTarget,
    ) -> Result<MoveRoute, MoveError> {
        route_move(self.0, &afm.surface(), near, radius_hint, target)
    }
}

/// Moves particle `id` of `scene`, believed at `near` with radius about `radius_hint`, to
/// `target` with the instrument `afm` (its tip at the start height), judged as
/// [`MoveOptions`] says, routed as `nanopush push` routes ([`OverviewRouting`]). The scene's
/// strategy is used as it is (see [`crate::control::derive`] to derive it first).
pub fn move_particle(
    scene: &Scene,
    afm: &mut Afm,
    id: u32,
    near: (f64, f64),
    radius_hint: f64,
    target: MoveTarget,
    options: MoveOptions,
) -> Result<MoveRun, MoveRunError> {
    move_particle_with(
        scene,
        afm,
        id,
        near,
        radius_hint,
        target,
        options,
        &mut OverviewRouting(scene),
    )
}

/// [`move_particle`] with its own routing.
#[allow(clippy::too_many_arguments)]
pub fn move_particle_with(
    scene: &Scene,
    afm: &mut Afm,
    id: u32,
    near: (f64, f64),
    radius_hint: f64,
    target: MoveTarget,
    options: MoveOptions,
    routing: &mut dyn MoveRouting,
) -> Result<MoveRun, MoveRunError> {
    let tick = afm.tick();
    let params = scene.strategy_params(tick);
    let first = routing.route(afm, near, radius_hint, target)?;
    let target = first.target;
    let before = (first.local.clone(), first.located);
    let prepared = routing.prepare(scene, id, first.located.radius, &params)?;
    prepared.check_reach(&first.legs).map_err(MoveError::Route)?;
    let mut legs: Vec<PushedLeg> = Vec::new();
    let mut route = first;
    let mut attempts = 0;
    loop {
        let measured = (route.located.x, route.located.y);
        if attempts > 0 {
            let verdict = Verdict::judge(measured, target, options.tolerance);
            // No legs: within the route's 10 nm, where no leg can correct a tighter tolerance;
            // nor a correction the tip cannot get behind, or that the stage's edge cuts short
            // as it cut this push.
            if matches!(verdict, Verdict::Ok { .. })
                || attempts >= options.attempts
                || route.legs.is_empty()
                || prepared.check_reach(&route.legs).is_err()
                || prepared.short_of_drag(&route.legs).is_some()
            {
                let cut_short = match verdict {
                    Verdict::Missed { .. } if attempts < options.attempts => prepared.short_of_drag(&route.legs),
                    _ => None,
                };
                return Ok(MoveRun {
                    before,
                    target,
                    legs,
                    after: (route.local, Some(route.located)),
                    verdict,
                    attempts,
                    cut_short,
                });
            }
        }
        attempts += 1;
        let mut estimate = measured;
        // The substrate's slope as the latest scan measured it.
        let mut slope = route.located.slope;
        let mut todo: VecDeque<Leg> = route.legs.iter().copied().collect();
        // Where the last leg was to leave the particle, and the re-plans this attempt has left.
        let mut planned = measured;
        let mut replans = route.legs.len();
        let mut first = true;
        // The failure of a push this attempt ended on, when the scan after decides the move.
        let mut lost = None;
        while let Some(mut leg) = todo.pop_front() {
            if !first {
                // Each later leg starts from where a local scan finds the particle, not from the
                // estimate: its search starts a few pixels behind it.
                match routing.locate(scene, afm, estimate, prepared.radius) {
                    (_, Ok(found)) => (estimate, slope) = ((found.x, found.y), found.slope),
                    (img, Err(_)) => {
                        return Ok(ended(before, target, legs, (img, None), Verdict::NotFound, attempts));
                    }
                }
                // A particle the last leg left beyond the tolerance of where it was to go (a
                // rolling particle the tip left behind, one that slid on ahead) is routed again
                // from where it is: held to the old legs, it would fall further behind with each.
                let off = (estimate.0 - planned.0).hypot(estimate.1 - planned.1);
                if off > options.tolerance && replans > 0 {
                    replans -= 1;
                    let again = match routing.route(afm, estimate, radius_hint, MoveTarget::Point(target)) {
                        Ok(r) => r,
                        Err(MoveError::NotFound { .. }) => {
                            let (img, _) = routing.locate(scene, afm, estimate, prepared.radius);
                            return Ok(ended(before, target, legs, (img, None), Verdict::NotFound, attempts));
                        }
                        Err(e) => return Err(e.into()),
                    };
                    (estimate, slope) = ((again.located.x, again.located.y), again.located.slope);
                    // Legs the tip cannot get behind are left to the scan after to judge.
                    if prepared.check_reach(&again.legs).is_err() {
                        break;
                    }
                    todo = again.legs.into_iter().collect();
                    let Some(next) = todo.pop_front() else { break };
                    leg = next;
                }
            }
            first = false;
            let pause = if attempts == 1 && legs.is_empty() {
                options.pause
            } else {
                None
            };
            let Some(request) = prepared.request(id, estimate, leg.to, pause, slope) else {
                continue;
            };
            planned = leg.to;
            let run = prepared.run(afm, &request, params)?;
            let failed = run.summary.failure.map(|f| f.code());
            legs.push(PushedLeg {
                from: estimate,
                to: leg.to,
                attempt: attempts,
                run,
            });
            estimate = legs.last().expect("pushed").run.summary.estimated_particle;
            // A push that read the particle as lost, with a push left to make, is not the move's
            // end: the scan after finds where the particle is (a reading that drifted off the
            // contact loses a particle that is still in front of the tip) and corrects from there.
            if failed == Some("particle_lost") && attempts < options.attempts {
                lost = failed;
                break;
            }
            if let Some(code) = failed {
                let (img, located) = routing.locate(scene, afm, estimate, prepared.radius);
                return Ok(ended(
                    before,
                    target,
                    legs,
                    (img, located.ok()),
                    Verdict::Failed { code },
                    attempts,
                ));
            }
        }
        // The scan after: where the particle is now, and the legs from there.
        // With the radius the target was checked against (the located one differs by a hair).
        match routing.route(afm, estimate, radius_hint, MoveTarget::Point(target)) {
            Ok(p) => route = p,
            Err(MoveError::NotFound { .. }) => {
                let (img, _) = routing.locate(scene, afm, estimate, prepared.radius);
                // Not found after a push that lost it: lost.
                let verdict = lost.map_or(Verdict::NotFound, |code| Verdict::Failed { code });
                return Ok(ended(before, target, legs, (img, None), verdict, attempts));
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// A move that ends before its verdict could be judged the usual way (the particle not found,
/// a push that failed): nothing cut it short.
fn ended(
    before: (HeightImage, Located),
    target: (f64, f64),
    legs: Vec<PushedLeg>,
    after: (HeightImage, Option<Located>),
    verdict: Verdict,
    attempts: u32,
) -> MoveRun {
    MoveRun {
        before,
        target,
        legs,
        after,
        verdict,
        attempts,
        cut_short: None,
    }
}

/// Why a move could not be made at all.
#[derive(Debug, thiserror::Error)]
pub enum MoveRunError {
    /// Finding or routing failed.
    #[error(transparent)]
    Locate(#[from] MoveError),
    /// The run could not be made.
    #[error(transparent)]
    Run(#[from] RunError),
}
