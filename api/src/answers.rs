//! What the REST handlers answer, one type each (docs/api.md, `GET /api/openapi.json`): every
//! handler returns one of these (or a snapshot, a road, a UAV), never an untyped JSON value.

use super::auth::AuthReport;
use super::listener::ConnectionsReport;
use engine::durable::StorageReport;
use engine::mocap::MocapReport;
use engine::stats::LoopMetrics;
use rerun_sink::RerunReport;
use serde::Serialize;
use std::sync::Arc;

/// `PUT /api/road`: the road's new version and the UAVs whose goals it had no room for.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct RoadReplaced {
    /// The road's version now.
    pub version: u64,
    /// The UAVs now hovering: their goals fell outside the new road.
    pub cleared_goals: Vec<String>,
}

/// `POST /api/uavs` (201): the UAV as added.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct UavAdded {
    /// Its id.
    pub id: String,
    /// Where it starts.
    pub position: [f64; 2],
    /// Its goal (None: it hovers).
    pub goal: Option<[f64; 2]>,
    /// `sim` or its Crazyflie URI.
    pub link: String,
}

/// `PUT /api/uavs/{id}/goal`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct GoalSet {
    /// The UAV.
    pub id: String,
    /// Its goal now.
    pub goal: [f64; 2],
}

/// `PUT /api/uavs/{id}/policy`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PolicySet {
    /// The UAV.
    pub id: String,
    /// Its policy now.
    pub policy: String,
}

/// `GET /api/policies`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Policies {
    /// The loaded policies.
    pub policies: Arc<[String]>,
    /// The policy of UAVs added without one.
    pub default: Arc<str>,
}

/// `POST /api/scenario`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ScenarioLoaded {
    /// The scenario's name.
    pub name: String,
    /// Its UAVs.
    pub uavs: usize,
    /// The last tick before it (its first tick is the next).
    pub loaded_after_tick: u64,
}

/// `POST /api/fleet/pause` and `/resume`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Paused {
    /// The fleet holds now.
    pub paused: bool,
}

/// Which UAVs a land or stop reached: a list of ids, or every one (`"all"`).
#[derive(Debug, Serialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Reached {
    /// These UAVs.
    Uavs(Vec<String>),
    /// `"all"`.
    All(&'static str),
}

impl Reached {
    /// Every UAV of the fleet.
    pub const ALL: Reached = Reached::All("all");
}

/// `POST /api/uavs/{id}/land` and `POST /api/fleet/land`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Landing {
    /// The UAVs landing.
    pub landing: Reached,
}

/// `POST /api/fleet/stop`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Stopped {
    /// The UAVs whose motors were cut.
    pub stopped: Reached,
}

/// `GET` and `PUT /api/rerun/selection`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct RerunSelection {
    /// The UAVs that keep their own Rerun entities in a batched fleet.
    pub ids: Arc<[String]>,
}

/// `GET /api/region/ownership`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Ownership {
    /// This server's region.
    pub region: String,
    /// Per UAV, when this region's loop commanded it.
    pub intervals: Vec<regions::ownership::Interval>,
    /// Closed intervals no longer kept.
    pub forgotten: u64,
}

/// `stream` of `GET /api/metrics`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct StreamReport {
    /// Connected clients.
    pub clients: usize,
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames skipped by clients slower than the loop.
    pub frames_skipped: u64,
    /// Clients dropped because a send stalled.
    pub clients_dropped: u64,
    /// Clients refused because the most were connected.
    pub clients_refused: u64,
    /// Most clients at once.
    pub max_clients: usize,
}

/// `GET /api/metrics`: the fleet loop's statistics and every bounded resource's counters.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Metrics {
    /// The loop's statistics (ticks, timing, margins, QP, links, ...), at the top level.
    #[serde(flatten)]
    pub fleet_loop: LoopMetrics,
    /// The WebSocket stream.
    pub stream: StreamReport,
    /// The HTTP connections.
    pub connections: ConnectionsReport,
    /// The token check.
    pub auth: AuthReport,
    /// The storage.
    pub storage: StorageReport,
    /// Motion capture.
    pub mocap: MocapReport,
    /// The Rerun sink.
    pub rerun: RerunReport,
    /// The region (`--region` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub region: Option<regions::RegionReport>,
    /// Time since the last tick finished (ms).
    pub tick_age_ms: f64,
    /// Most UAVs the fleet may have.
    pub max_uavs: usize,
}

/// `GET /healthz`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct Health {
    /// How the server is.
    pub status: HealthStatus,
    /// The last tick.
    pub tick: u64,
    /// Time since it finished (ms).
    pub tick_age_ms: f64,
    /// What is wrong, in words.
    pub problems: Vec<String>,
}

/// `GET /api/audit`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct AuditLog {
    /// The entries asked for.
    pub entries: Vec<engine::store::AuditEntry>,
}

/// How the server is (`status` of `GET /healthz`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum HealthStatus {
    /// Flying (200).
    Ok,
    /// Flying, changes refused because they cannot be saved (200).
    Degraded,
    /// No tick for 1 s (503).
    Stalled,
    /// The fleet loop has stopped (503).
    LoopStopped,
}
