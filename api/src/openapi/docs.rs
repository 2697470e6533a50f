//! What the document says of each route of `routes::ROUTES` beyond what its types and its access
//! state: a summary, what no schema can express, its success and the refusals of its own.

use super::{Body, Doc, SchemaOf, answer, refusal, schema_of};
use crate::answers::{
    AuditLog, GoalSet, Health, Landing, Metrics, Ownership, Paused, Policies, PolicySet, RerunSelection,
    RoadReplaced, ScenarioLoaded, Stopped, UavAdded,
};
use crate::audit::AuditParams;
use crate::federate::ScopeQuery;
use crate::handlers::{GoalBody, ListQuery, NewUav, PolicyBody, SelectionBody};
use engine::RoadView;
use engine::snapshot::{Snapshot, UavSnapshot};
use fleet::Scenario;
use roads::AirspaceLayout;
use schemars::{Schema, SchemaGenerator, json_schema};

/// Any JSON object (the document itself).
fn object(_: &mut SchemaGenerator) -> Schema {
    json_schema!({"type": "object"})
}

/// A read without parameters; each route's doc replaces what it says.
const READ: Doc = Doc { id: "", summary: "", description: None, query: &[], body: Body::None, answers: &[] };
/// A change without data.
const EMPTY: Doc = Doc { body: Body::Empty, ..READ };
const SCOPE: SchemaOf = schema_of::<ScopeQuery>;
const BAD_SCOPE: &str = "a bad `scope`; `field` names it";

/// `GET /healthz`.
pub const HEALTHZ: Doc = Doc {
    id: "healthz",
    summary: "Health: 200 `ok` or `degraded` (flying; changes refused because they cannot be saved), 503 `stalled` (no tick for 1 s) or `loop_stopped`",
    answers: &[
        answer(200, "flying", schema_of::<Health>),
        answer(503, "the fleet loop is stalled or stopped", schema_of::<Health>),
    ],
    ..READ
};

/// `GET /api/openapi.json`.
pub const OPENAPI: Doc = Doc {
    id: "openapi",
    summary: "This document",
    answers: &[answer(200, "OpenAPI 3.1 document", object)],
    ..READ
};

/// `GET /api/road`.
pub const GET_ROAD: Doc = Doc {
    id: "getRoad",
    summary: "The road layout, or the network layout, as put",
    answers: &[answer(200, "layout", schema_of::<AirspaceLayout>)],
    ..READ
};

/// `PUT /api/road`.
pub const PUT_ROAD: Doc = Doc {
    id: "putRoad",
    summary: "Replace the road, with one road (`segments`) or a road network (`roads`, `junctions`)",
    description: Some(
        "Beyond the schema (geometry no JSON schema can state, so only here and in the 422 description): each quad strictly convex with edges of at least 1 mm, consecutive segments joined seamlessly without folding back, no two non-adjacent segments overlapping, and `regions` covering every segment exactly once with unique names. A network: each road's segments as a chain's, each junction strictly convex, the names unique among the roads and among the junctions, at most 20000 cells (segments and junctions), cells meeting only along whole shared edges (an edge of no more than two cells), not overlapping, all connected, every passage at least `min_passage_m` of `GET /api/road/geometry` wide (2·D_s + D_c and margins with the fleet's parameters), no two walls meeting at less than 90°; a network has no regions. With `serve --region` (one road divided into regions: a network is refused there with 422 naming `regions`) it applies to every region of the deployment at one instant, or to none (docs/regions.md); the answer then adds `regions` and `switch_at_ms`, and a region's refusal keeps its status with `error.region` naming it.",
    ),
    body: Body::Json(schema_of::<AirspaceLayout>),
    answers: &[
        answer(200, "applied; goals outside the new road were cleared", schema_of::<RoadReplaced>),
        refusal(
            422,
            "`invalid_road`: the layout breaks a rule (`rule` names it, `field` and `segment` where: `segments[3]`, `regions[1].segments`, `roads[2].segments[3]`, `roads[0].name`, `junctions[1].polygon`, ...): the schema's (no segment, more than 10000, a coordinate beyond ±1e6 m) or the geometry's (not_convex, degenerate_edge, seamless_join, folds_back, overlap, and for regions reversed_region, region_out_of_range, region_overlap, region_gap, duplicate_region_name; for a network also too_many_segments, duplicate_name, shared_by_three, partial_edge, disconnected, narrow_passage, sharp_corner); `invalid_value` with `field` `regions` for a network with regions, or with `field` `roads` when the fleet's parameters changed since the network was checked (put it again)",
        ),
        refusal(409, "a flying UAV would be outside the new road or network or closer than D_s to a wall"),
    ],
    ..READ
};

/// `GET /api/road/geometry`.
pub const GET_ROAD_GEOMETRY: Doc = Doc {
    id: "getRoadGeometry",
    summary: "The road's walls and centre line, or a network's walls and cells, for drawing",
    answers: &[answer(200, "geometry", schema_of::<RoadView>)],
    ..READ
};

/// `GET /api/uavs`.
pub const LIST_UAVS: Doc = Doc {
    id: "listUavs",
    summary: "Every UAV as in the latest snapshot; with any parameter, one page of at most `limit` (default 1000), optionally only those inside `bbox`",
    description: Some(
        "Beyond the schema (so only here and in the 422 description): `after` must name a UAV of the fleet now (state-dependent), and `bbox` must have x0 ≤ x1 and y0 ≤ y1 with each number finite as a 32-bit float.",
    ),
    query: &[schema_of::<ListQuery>, SCOPE],
    answers: &[
        answer(200, "UAVs", schema_of::<Vec<UavSnapshot>>),
        refusal(
            422,
            "a bad `bbox` (not four numbers, or x0 > x1 or y0 > y1), `limit`, `after` (an id of no UAV: state-dependent) or `scope`; `field` names it",
        ),
    ],
    ..READ
};

/// `POST /api/uavs`.
pub const ADD_UAV: Doc = Doc {
    id: "addUav",
    summary: "Add a simulated UAV at rest",
    description: Some(
        "Beyond the schema (state-dependent, so only here and in the 422 description): `position` must be inside the road flown now, at least D_s (braking margin) from its walls and D_c from every other UAV; `goal` inside that road at least D_s from its walls; `policy` one this server has loaded (`GET /api/policies`); a UDP link's host as `Link` says (`--allow-link-host`); and the fleet must have room (`--max-uavs`).",
    ),
    body: Body::Json(schema_of::<NewUav>),
    answers: &[
        answer(201, "added", schema_of::<UavAdded>),
        refusal(
            422,
            "a field has an invalid value; `field` names it: `unsafe` for a `position` outside the road flown now or closer than D_s to a wall or D_c to a UAV, or a `goal` outside the road or closer than D_s to a wall; `unknown_policy` for a policy this server has not loaded; `invalid_value` for a bad `id`, a point beyond ±1e6 m or a refused `link`; `fleet_full` when the fleet would exceed --max-uavs",
        ),
        refusal(409, "duplicate id"),
    ],
    ..READ
};

/// `GET /api/uavs/{id}`.
pub const GET_UAV: Doc = Doc {
    id: "getUav",
    summary: "One UAV",
    answers: &[answer(200, "UAV", schema_of::<UavSnapshot>)],
    ..READ
};

/// `DELETE /api/uavs/{id}`.
pub const REMOVE_UAV: Doc = Doc {
    id: "removeUav",
    summary: "Remove a UAV",
    answers: &[super::Answer { status: 204, description: "removed", schema: None }],
    ..EMPTY
};

/// `PUT /api/uavs/{id}/goal`.
pub const SET_GOAL: Doc = Doc {
    id: "setGoal",
    summary: "Send a UAV to a goal",
    description: Some(
        "Beyond the schema (state-dependent, so only here and in the 422 description): the goal must be inside the road flown now, at least D_s from its walls (no UAV can get nearer to one).",
    ),
    body: Body::Json(schema_of::<GoalBody>),
    answers: &[
        answer(200, "set", schema_of::<GoalSet>),
        refusal(
            422,
            "a field has an invalid value; `field` names it: `unsafe` for a goal outside the road flown now or closer than D_s to a wall",
        ),
    ],
    ..READ
};

/// `DELETE /api/uavs/{id}/goal`.
pub const CLEAR_GOAL: Doc = Doc {
    id: "clearGoal",
    summary: "Clear a UAV's goal (it hovers)",
    answers: &[super::Answer { status: 204, description: "cleared", schema: None }],
    ..EMPTY
};

/// `PUT /api/uavs/{id}/policy`.
pub const SET_POLICY: Doc = Doc {
    id: "setPolicy",
    summary: "Give a UAV another loaded policy",
    description: Some(
        "Beyond the schema (state-dependent, so only here and in the 422 description): the policy must be one this server has loaded, as `GET /api/policies` lists them (`pd` and `rl` always, more with `serve --model NAME=FILE.onnx`).",
    ),
    body: Body::Json(schema_of::<PolicyBody>),
    answers: &[
        answer(200, "set", schema_of::<PolicySet>),
        refusal(422, "`unknown_policy`: a policy this server has not loaded; `field` is `policy`"),
    ],
    ..READ
};

/// `POST /api/uavs/{id}/land`.
pub const LAND_UAV: Doc = Doc {
    id: "landUav",
    summary: "Land one UAV, ahead of any queued change (a Crazyflie lands with its high-level commander; an in-process UAV settles in 1 s)",
    answers: &[answer(200, "landing", schema_of::<Landing>)],
    ..EMPTY
};

/// `GET /api/policies`.
pub const LIST_POLICIES: Doc = Doc {
    id: "listPolicies",
    summary: "Loaded policies and the default",
    answers: &[answer(200, "policies", schema_of::<Policies>)],
    ..READ
};

/// `POST /api/scenario`.
pub const LOAD_SCENARIO: Doc = Doc {
    id: "loadScenario",
    summary: "Replace road, parameters and fleet with a scenario (the `airroads run` format)",
    description: Some(
        "Beyond the schema (only here and in the 422 description): the road or network must pass the geometry rules of `PUT /api/road` (a network's passages wide enough for this scenario's parameters); each UAV's start and goal must be inside that road at least D_s from its walls, the starts D_c apart and the ids unique; a UDP link's host as `Link` says; and the fleet must not exceed `--max-uavs` (a setting of the server). With `serve --region` (one road divided into regions: a network is refused there with 422 naming `regions`) it applies to every region of the deployment at one instant, or to none (docs/regions.md); the answer then adds `regions` and `switch_at_ms`, and a region's refusal keeps its status with `error.region` naming it.",
    ),
    body: Body::Json(schema_of::<Scenario>),
    answers: &[
        answer(200, "loaded", schema_of::<ScenarioLoaded>),
        refusal(
            422,
            "a field has an invalid value; `field` names it (`params.dt`, `segments[3]`, `roads[0].segments[2]`, `junctions[1].polygon`, `uavs[1].start`, ...): out of the schema's ranges, a road or network that breaks a geometry rule (the rule's name ends the message in brackets), a start or goal outside the road or closer than D_s to a wall, starts closer than D_c, a duplicate id, a refused link; `fleet_full` when the fleet would exceed --max-uavs",
        ),
    ],
    ..READ
};

/// `POST /api/fleet/pause`.
pub const PAUSE: Doc = Doc {
    id: "pause",
    summary: "Hold: every UAV brakes to a hover (the filter keeps running)",
    answers: &[answer(200, "holding", schema_of::<Paused>)],
    ..EMPTY
};

/// `POST /api/fleet/resume`.
pub const RESUME: Doc = Doc {
    id: "resume",
    summary: "Fly the policies again",
    answers: &[answer(200, "flying", schema_of::<Paused>)],
    ..EMPTY
};

/// `POST /api/fleet/land`.
pub const LAND_FLEET: Doc = Doc {
    id: "landFleet",
    summary: "Land every UAV, ahead of any queued change",
    answers: &[answer(200, "landing", schema_of::<Landing>)],
    ..EMPTY
};

/// `POST /api/fleet/stop`.
pub const STOP_FLEET: Doc = Doc {
    id: "stopFleet",
    summary: "Emergency stop: every UAV's motors off at once, ahead of any queued change",
    answers: &[answer(200, "stopped", schema_of::<Stopped>)],
    ..EMPTY
};

/// `GET /api/state`.
pub const GET_STATE: Doc = Doc {
    id: "getState",
    summary: "The latest snapshot (also streamed by GET /ws); with `serve --region`, every region's UAVs merged (`regions` says which answered)",
    query: &[SCOPE],
    answers: &[answer(200, "snapshot", schema_of::<Snapshot>), refusal(422, BAD_SCOPE)],
    ..READ
};

/// `GET /api/metrics`.
pub const GET_METRICS: Doc = Doc {
    id: "getMetrics",
    summary: "Fleet-loop statistics",
    answers: &[answer(200, "metrics", schema_of::<Metrics>)],
    ..READ
};

/// `GET /api/audit`.
pub const AUDIT: Doc = Doc {
    id: "audit",
    summary: "The audit log: every change request with time, route, client and outcome; newest first, or oldest first after `after` (needs the token when one is configured)",
    query: &[schema_of::<AuditParams>],
    answers: &[
        answer(200, "entries", schema_of::<AuditLog>),
        refusal(422, "an invalid query parameter (`field` names it; `query` for an unknown one)"),
        refusal(503, "the audit log cannot be read now"),
    ],
    ..READ
};

/// `GET /api/region/ownership`.
pub const GET_OWNERSHIP: Doc = Doc {
    id: "getRegionOwnership",
    summary: "This region's ownership intervals (`--region`)",
    description: Some(
        "Per UAV, the intervals in which this region's fleet loop commanded it, on the wall clock (s since the Unix epoch): from the server's start, a handover or an addition over REST to a handover or a removal. The regions' logs of one UAV never overlap; a handover leaves it unowned for at most 0.25 s (docs/regions.md). At most 10,000 closed intervals are kept (`forgotten` counts the older ones).",
    ),
    answers: &[
        answer(200, "the intervals", schema_of::<Ownership>),
        refusal(404, "this server flies no region (`no_region`)"),
    ],
    ..READ
};

/// `GET /api/rerun/selection`.
pub const GET_RERUN_SELECTION: Doc = Doc {
    id: "getRerunSelection",
    summary: "The UAVs that keep their own Rerun entities in a batched fleet",
    answers: &[answer(200, "the selection", schema_of::<RerunSelection>)],
    ..READ
};

/// `PUT /api/rerun/selection`.
pub const PUT_RERUN_SELECTION: Doc = Doc {
    id: "setRerunSelection",
    summary: "Choose the UAVs that keep their own Rerun entities when the fleet is logged as one batch (view state: applied at once, not saved)",
    description: Some(
        "Beyond the schema (state-dependent, so only here and in the 422 description): every id must name a UAV of the fleet now.",
    ),
    body: Body::Json(schema_of::<SelectionBody>),
    answers: &[
        answer(200, "the selection now", schema_of::<RerunSelection>),
        refusal(
            422,
            "more than 64 ids, or an id of no UAV in the fleet now (state-dependent); `field` is `ids`",
        ),
    ],
    ..READ
};
