//! Control: the manipulation strategy of Sec 2.1 and the force-controlled pushing of Sec 3.

pub mod bilateral;
pub mod estimator;
pub mod legs;
pub mod locate_and_plan;
pub mod strategy;
pub mod strategy_plan;
pub mod strategy_run;
pub mod whole_move;

pub use bilateral::{Bilateral, BilateralParams};
pub use estimator::{Hxy, PeakDetector, PushPrediction, RetractPlan, predict};
pub use legs::{Leg, Obstacle, PlanError, Planner};
pub use strategy::{Control, Failure, Phase, PushTask, Strategy, StrategyParams, Summary};
pub use strategy_run::{Prepared, PushRequest, RunError, RunRow, StrategyRun, push_once};

#[cfg(test)]
mod pull_off_tests;
#[cfg(test)]
mod tests;
pub use locate_and_plan::{MoveError, MovePlan, MoveTarget, locate_near, plan_move};
pub use whole_move::{DEFAULT_ATTEMPTS, MoveOptions, MoveRun, MoveRunError, PushedLeg, Verdict, move_particle};
