//! The fleet loop as plain synchronous code: one [`Fleet::tick`] reads states from the links, picks
//! targets (navigation and traffic rules), finds neighbours, runs the policies batched, filters every command through
//! the CBF-QP and sends it. Also the scenario file format, safety metrics and headless runs.
//!
//! No async, no I/O beyond what a [`links::Link`] does: the server wraps this in its 20 Hz task.

mod condition;
mod edit;
pub mod families;
mod filtering;
mod fleet;
pub mod following;
mod foreign;
mod histogram;
mod lost;
mod margins;
mod metrics;
mod neighbours;
pub mod passing;
pub mod paths;
mod pipeline;
pub mod progress;
mod ragged;
mod repair;
mod rows;
mod run;
mod scenario;
pub mod sections;
pub mod speed;
pub mod stress;
pub mod traffic;
pub mod trunk;
mod undo;
mod yielding;
pub mod zones;

pub use condition::Condition;
pub use edit::EditError;
pub use fleet::{CollisionShare, Fleet, FleetConfig, PARALLEL_FROM_UAVS, StageTimes, Uav, UavTick};
pub use foreign::ForeignUav;
pub use histogram::DurationHistogram;
pub use margins::{collision_margin, road_margin, road_margin_in};
pub use metrics::{MetricsRecorder, QpMetrics, RunMetrics, Stall};
pub use ragged::Ragged;
pub use run::{
    RunOptions, RunOutcome, TAKEOFF_TIMEOUT_S, TRAJECTORY_HEADER, run_scenario, run_scenario_on,
    run_scenario_on_truth,
};
/// The reach disk of a neighbour that does not run the filter (moved to `safety`; kept here for users of `fleet`).
pub use safety::{ReachDisk, WATCHDOG_HOLD_S, flown_reach_disk, obstacle_row, point_disk, reach_disk};
pub use scenario::{Scenario, ScenarioError, ScenarioUav, UavSpec, ValidScenario};
pub use undo::Undo;
