//! Control: the manipulation strategy of Sec 2.1 and the force-controlled pushing of Sec 3.
//!
//! - [`strategy`]: the strategy's state machine (Fig 2) and its runner;
//! - [`estimator`]: the particle-position feedback of Eq 19 and the model's prediction of a push;
//! - [`route`]: the legs of a path of straight pushes around the other particles;
//! - [`moves`]: a whole move (locate, route, push, judge by the scan after);
//! - [`derive`](mod@derive): the strategy's settings derived from the scene's model, and its dry run;
//! - [`bilateral`]: the haptic z-control law;
//! - [`held_push`](mod@held_push): a push on a controller that holds the force itself (a real
//!   microscope's Z feedback), through the instrument interface.

pub mod bilateral;
pub mod derive;
pub mod estimator;
pub mod held_push;
pub mod moves;
pub mod route;
pub mod strategy;

pub use bilateral::{Bilateral, BilateralParams};
pub use estimator::{Hxy, PeakDetector, PushPrediction, RetractPlan, predict};
pub use held_push::{HeldError, HeldOutcome, HeldPhase, HeldPush, HeldReport, held_push};
pub use moves::{
    DEFAULT_ATTEMPTS, MoveError, MoveOptions, MoveRoute, MoveRun, MoveRunError, MoveTarget, PushedLeg, Verdict,
};
pub use moves::{locate_near, move_particle, route_move};
pub use route::{Leg, Obstacle, RouteError, Router};
pub use strategy::{Control, Failure, Phase, PushTask, Strategy, StrategyParams, Summary};
pub use strategy::{Prepared, PushRequest, RunError, RunRow, StrategyRun, push_once};
