//! Control: the manipulation strategy of Sec 2.1 and the force-controlled pushing of Sec 3.

pub mod bilateral;
pub mod estimator;
pub mod move_plan;
pub mod plan;
mod run;
pub mod strategy;

pub use bilateral::{Bilateral, BilateralParams};
pub use estimator::{Hxy, PeakDetector, PushPrediction, RetractPlan, predict};
pub use plan::{Leg, Obstacle, PlanError, Planner};
pub use run::{Prepared, PushRequest, RunError, RunRow, StrategyRun, push_once};
pub use strategy::{Control, Failure, Phase, PushTask, Strategy, StrategyParams, Summary};

#[cfg(test)]
mod tests;
pub use move_plan::{MoveError, MovePlan, MoveTarget, locate_near, plan_move};
