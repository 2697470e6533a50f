//! Changes requested by REST handlers, applied by the fleet loop between two ticks, each answered
//! through a one-shot channel.

use fleet::{EditError, ValidScenario};
use roads::Road;
use tokio::sync::oneshot;
use uav::Vec2;

/// A change to the fleet.
#[derive(Debug)]
pub enum Command {
    /// Replace the road (already validated).
    SetRoad(Road),
    /// Add a simulated UAV at rest at `position`.
    AddUav {
        /// Unique id.
        id: String,
        /// Start position (m).
        position: Vec2,
        /// Policy name (None: the server's default policy).
        policy: Option<String>,
        /// Goal (None: hover).
        goal: Option<Vec2>,
        /// `sim` (None) or a Crazyflie URI.
        link: Option<String>,
    },
    /// Remove a UAV.
    RemoveUav(String),
    /// Set (Some) or clear (None) the goal of a UAV.
    SetGoal(String, Option<Vec2>),
    /// Give a UAV another policy.
    SetPolicy(String, String),
    /// Replace road, parameters and fleet with a validated scenario.
    LoadScenario(Box<ValidScenario>),
    /// Hold (true: every UAV brakes to a hover) or resume (false).
    Hold(bool),
    /// Land one UAV (Some) or all (None). Sent on the urgent channel.
    Land(Option<String>),
    /// Emergency stop of every UAV: motors off. Sent on the urgent channel.
    EmergencyStop,
}

/// What a command did.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Applied.
    Done,
    /// The scenario replaced the fleet after tick `tick` (its first tick is `tick + 1`).
    ScenarioLoaded {
        /// The last tick before the scenario.
        tick: u64,
    },
    /// The road was replaced; these UAVs' goals fell outside it and were cleared.
    RoadReplaced {
        /// Ids of the UAVs now hovering.
        cleared_goals: Vec<String>,
    },
}

/// A command and where its answer goes.
#[derive(Debug)]
pub struct Request {
    /// The change.
    pub command: Command,
    /// Receives the outcome (dropped if the client went away: the change still applies).
    pub reply: oneshot::Sender<Result<Outcome, EditError>>,
}
