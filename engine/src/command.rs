//! Changes requested by REST handlers, applied by the fleet loop between two ticks, each answered
//! through a one-shot channel once it is applied and durable (or refused, having changed nothing).

use super::store::AuditRecord;
use fleet::{EditError, ValidScenario};
use roads::{Airspace, Road};

/// `road of 4 segments` or `network of 3 roads and 1 junctions (13 cells)`.
fn what_road(road: &Airspace) -> String {
    match road {
        Airspace::Road(road) => format!("road of {} segments", road.quads().len()),
        Airspace::Network(net) => format!(
            "network of {} roads and {} junctions ({} cells)",
            net.layout().roads.len(),
            net.layout().junctions.len(),
            net.cells().len()
        ),
    }
}
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use tokio::sync::oneshot;
use uav::Vec2;

/// A change to the fleet.
#[derive(Debug)]
pub enum Command {
    /// Replace the road or network (already validated).
    SetRoad(Box<NewRoad>),
    /// A standby takes its owner's road (`region::road_follow`); refused by an owner's loop
    /// like nothing else, applied as [`Command::SetRoad`].
    FollowRoad(Box<NewRoad>),
    /// Check that every UAV in the air would be safe on this road, changing nothing (the prepare
    /// step of a deployment-wide road, `serve::deploy`).
    CheckRoad(Box<Airspace>),
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
    /// Pause (true: every UAV brakes to a hover) or resume (false).
    Pause(bool),
    /// Land one UAV (Some) or all (None). Sent on the urgent channel, never persisted.
    Land(Option<String>),
    /// Emergency stop of every UAV: motors off. Sent on the urgent channel, never persisted.
    EmergencyStop,
    /// A UAV another server gave this one (a region's handover or takeover; never from a client).
    Adopt(Box<super::hook::Arrival>),
}

impl Command {
    /// The HTTP status of its success (for the audit entry written with the change).
    pub fn success_status(&self) -> u16 {
        match self {
            Command::AddUav { .. } => 201,
            Command::RemoveUav(_) | Command::SetGoal(_, None) => 204,
            _ => 200,
        }
    }

    /// One line saying what it changes (the audit entry's detail).
    pub fn describe(&self) -> String {
        match self {
            Command::SetRoad(new) => what_road(&new.road),
            Command::FollowRoad(new) => format!("the owner's {}", what_road(&new.road)),
            Command::CheckRoad(road) => format!("check of a {}", what_road(road)),
            Command::AddUav { id, position, .. } => {
                format!("added `{id}` at [{}, {}]", position.x, position.y)
            }
            Command::RemoveUav(id) => format!("removed `{id}`"),
            Command::SetGoal(id, Some(g)) => format!("goal of `{id}` set to [{}, {}]", g.x, g.y),
            Command::SetGoal(id, None) => format!("goal of `{id}` cleared"),
            Command::SetPolicy(id, policy) => format!("policy of `{id}` set to `{policy}`"),
            Command::LoadScenario(s) => format!("scenario `{}` with {} UAVs", s.name, s.uavs.len()),
            Command::Pause(true) => "fleet paused".into(),
            Command::Pause(false) => "fleet resumed".into(),
            Command::Land(Some(id)) => format!("land `{id}`"),
            Command::Land(None) => "land all".into(),
            Command::EmergencyStop => "emergency stop".into(),
            Command::Adopt(a) => format!("adopted `{}` at [{}, {}]", a.id, a.state.p.x, a.state.p.y),
        }
    }
}

/// A road or network a handler validated, for [`Command::SetRoad`].
#[derive(Debug)]
pub struct NewRoad {
    /// The road or network.
    pub road: Airspace,
    /// The narrowest passage a network was validated with (m; `fleet::min_passage_m` of the
    /// parameters then): the loop refuses it if the fleet's parameters need more by now.
    pub checked_passage_m: f64,
}

impl NewRoad {
    /// A chain road (no passage rule).
    pub fn road(road: Road) -> Self {
        Self { road: Airspace::Road(road), checked_passage_m: 0.0 }
    }
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

/// Why a command was not applied; in every case nothing changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChangeError {
    /// The fleet refused it.
    #[error(transparent)]
    Edit(#[from] EditError),
    /// It could not be made durable (the reason says why); it was taken back.
    #[error("the change could not be saved: {0}")]
    NotDurable(String),
    /// The fleet would exceed the configured maximum.
    #[error("the fleet would have {wanted} UAVs, more than the maximum of {max} (--max-uavs)")]
    FleetFull {
        /// UAVs the change would make.
        wanted: usize,
        /// The configured maximum.
        max: usize,
    },
    /// The client gave up before the loop took it.
    #[error("the request was withdrawn before it was applied")]
    Withdrawn,
    /// This server is the standby of its region: changes go to the owner.
    #[error("this server is the standby of region `{0}`; send changes to its owner")]
    Standby(String),
}

/// Where a queued request is: the handler and the loop race to claim it exactly once.
#[derive(Debug, Default)]
pub struct Claim(AtomicU8);

const QUEUED: u8 = 0;
const TAKEN: u8 = 1;
const WITHDRAWN: u8 = 2;

impl Claim {
    /// The loop takes it; false when the handler withdrew it first (then it must not be applied).
    pub fn take(&self) -> bool {
        self.0.compare_exchange(QUEUED, TAKEN, Ordering::AcqRel, Ordering::Acquire).is_ok()
    }

    /// The handler withdraws it; false when the loop took it already (then its outcome will come).
    pub fn withdraw(&self) -> bool {
        self.0.compare_exchange(QUEUED, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire).is_ok()
    }
}

/// The answer to a request.
pub type Reply = oneshot::Sender<Result<Outcome, ChangeError>>;

/// A command and where its answer goes.
#[derive(Debug)]
pub struct Request {
    /// The change.
    pub command: Command,
    /// Receives the outcome (dropped if the client went away: the change still applies).
    pub reply: Reply,
    /// Who asked, for the audit entry committed with the change (None: not audited, e.g. tests).
    pub audit: Option<AuditRecord>,
    /// Taken by the loop or withdrawn by the handler, exactly once.
    pub claim: Arc<Claim>,
}

impl Request {
    /// A request without audit information.
    pub fn new(command: Command, reply: Reply) -> Self {
        Self { command, reply, audit: None, claim: Arc::default() }
    }
}
