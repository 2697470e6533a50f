//! The fleet loop as plain synchronous code: one [`Fleet::tick`] reads states from the links, picks
//! targets (navigation and traffic rules), finds neighbours, runs the policies batched, filters every command through
//! the CBF-QP and sends it. Also the scenario file format, safety metrics and headless runs.
//!
//! No async, no I/O beyond what a [`links::Link`] does: the server wraps this in its 20 Hz task.

mod condition;
mod config;
mod edits;
mod fleet;
mod foreign;
mod member;
pub mod progress;
mod ragged;
mod runs;
mod scenario;
mod scenario_regions;
mod tick;
pub mod traffic;

pub use runs::{city, families, paths, split, stress, trunk};
pub use traffic::{following, passing, sections, speed, zones};

pub use condition::Condition;
pub use config::{CollisionShare, FleetConfig};
pub use edits::undo::Undo;
pub use edits::{Applied, Edit, EditError};
pub use fleet::Fleet;
pub use member::ForeignUav;
pub use member::{Uav, UavPolicy, UavTick};
pub use ragged::Ragged;
pub use runs::histogram::DurationHistogram;
pub use runs::margins::{TickMargins, collision_margin, road_margin, road_margin_in};
pub use runs::metrics::{MetricsRecorder, QpMetrics, RunMetrics, Stall};
pub use runs::run::{
    RunOptions, RunOutcome, TAKEOFF_TIMEOUT_S, TRAJECTORY_HEADER, run_scenario, run_scenario_on,
    run_scenario_on_truth,
};
/// The reach disk of a neighbour that does not run the filter (moved to `safety`; kept here for users of `fleet`).
pub use safety::{ReachDisk, WATCHDOG_HOLD_S, flown_reach_disk, obstacle_row, point_disk, reach_disk};
pub use scenario::{
    Scenario, ScenarioError, ScenarioRegions, ScenarioUav, UavSpec, ValidScenario, min_passage_m,
};
pub use tick::{PARALLEL_FROM_UAVS, StageTimes};
