//! The engine of `airroads serve`: the fleet loop on its own thread ([`fleet_loop`]), the changes it
//! applies between ticks with their undo records ([`changes`], [`command`]), their durability
//! ([`durable`], [`store`], [`persist`]), the snapshots, road and statistics it publishes
//! ([`snapshot`], [`road_view`], [`stats`]), and the links it opens ([`linking`], [`mocap`]); [`start`] runs it and
//! [`EngineHandle`] is all a client of the loop holds. It knows no HTTP, no Zenoh and no
//! Rerun: readers watch its channels, and regions plug in through one hook ([`hook`]).

pub mod changes;
pub mod command;
pub mod durable;
pub mod fleet_loop;
pub mod handle;
pub mod hook;
pub mod linking;
pub mod mocap;
pub mod persist;
pub mod road_view;
pub mod snapshot;
pub mod stats;
pub mod store;
mod tick_counts;

pub use fleet_loop::{Engine, LoopChannels, LoopClock};
pub use handle::{ApplyError, EngineConfig, EngineHandle, RunningEngine, start};
pub use road_view::RoadView;

/// The scenario `airroads serve` flies when it has no saved state and no `--scenario`.
pub const DEMO_SCENARIO: &str = include_str!("../../scenarios/demo.json");

/// The embedded demo scenario, validated.
pub fn demo_scenario() -> anyhow::Result<fleet::ValidScenario> {
    use anyhow::Context as _;
    let scenario = fleet::Scenario::from_json(DEMO_SCENARIO).context("embedded demo scenario")?;
    scenario.validate().context("embedded demo scenario")
}
