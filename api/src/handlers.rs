//! REST handlers (`docs/api.md`, `GET /api/openapi.json`; their routes are `routes::ROUTES`). Reads answer from the latest published
//! snapshot; changes go to the fleet loop as commands and are answered once it applied them.

use super::answers::{
    GoalSet, Health, HealthStatus, Landing, Metrics, Ownership, Paused, Policies, PolicySet, Reached,
    RerunSelection, ScenarioLoaded, Stopped, StreamReport, UavAdded,
};
use super::error::{ApiError, ApiJson, NoBody};
use super::state::{AppState, json_of};
use axum::Json;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use engine::command::{Command, Outcome};
use engine::snapshot::{Snapshot, UavSnapshot};
use engine::stats::LoopMetrics;
use fleet::Scenario;
use serde::{Deserialize, Serialize};
use uav::Vec2;

/// A loop that has not finished a tick for this long is reported stalled.
pub const STALLED_AFTER: std::time::Duration = std::time::Duration::from_secs(1);

/// `ok`; `degraded` (200: flying, but changes are refused because they cannot be saved);
/// `stalled` (503: no tick for [`STALLED_AFTER`]); `loop_stopped` (503).
pub(crate) async fn healthz(State(app): State<AppState>) -> Response {
    let tick = app.engine.snapshots.borrow().tick;
    let age = app.engine.clock.tick_age();
    let tick_age_ms = age.as_secs_f64() * 1e3;
    let mut problems = Vec::new();
    let status = if app.engine.stopped() {
        problems.push("the fleet loop has stopped".to_string());
        HealthStatus::LoopStopped
    } else if age > STALLED_AFTER {
        problems.push(format!("no tick for {:.1} s", age.as_secs_f64()));
        HealthStatus::Stalled
    } else if let Some(reason) = app.engine.storage.refusal() {
        problems.push(format!("changes cannot be saved: {reason}"));
        HealthStatus::Degraded
    } else {
        HealthStatus::Ok
    };
    let flying = matches!(status, HealthStatus::Ok | HealthStatus::Degraded);
    let code = if flying { StatusCode::OK } else { StatusCode::SERVICE_UNAVAILABLE };
    (code, Json(Health { status, tick, tick_age_ms, problems })).into_response()
}

pub(crate) async fn openapi() -> Response {
    ([(header::CONTENT_TYPE, "application/json")], super::openapi::text()).into_response()
}

/// Most UAVs one page of `GET /api/uavs` holds (and its default size once any parameter is given).
pub const MAX_PAGE: usize = 1000;

/// Query of `GET /api/uavs`: without any, the whole fleet (as before pages existed).
#[derive(Debug, Default, Deserialize, schemars::JsonSchema)]
pub(crate) struct ListQuery {
    /// `x0,y0,x1,y1` (m): only the UAVs inside this box; four decimal numbers (read as 32-bit
    /// floats, so finite within ±3.4e38), with x0 ≤ x1 and y0 ≤ y1 (the order is beyond the schema:
    /// a box with x0 > x1 or y0 > y1 is refused with 422).
    #[schemars(pattern(super::binary::bbox_pattern()))]
    bbox: Option<String>,
    /// At most this many (default 1000 when any parameter is given).
    #[schemars(range(min = 1, max = MAX_PAGE))]
    limit: Option<usize>,
    /// Start after the UAV with this id, in fleet order (the last id of the previous page); an id
    /// of no UAV is refused with 422.
    #[schemars(with = "Option<uav::schema::UavId>")]
    pub(crate) after: Option<String>,
}

/// One page of `GET /api/uavs`: at most `limit` UAVs, only those inside `bbox` if given.
pub(crate) struct Page {
    /// Most UAVs.
    pub(crate) limit: usize,
    bbox: Option<super::binary::Bbox>,
}

impl ListQuery {
    /// The page asked for (None: no parameter, the whole list), or the 422 naming the parameter.
    pub(crate) fn page(&self) -> Result<Option<Page>, ApiError> {
        if self.bbox.is_none() && self.limit.is_none() && self.after.is_none() {
            return Ok(None);
        }
        let limit = self.limit.unwrap_or(MAX_PAGE);
        if !(1..=MAX_PAGE).contains(&limit) {
            return Err(ApiError::invalid("limit", format!("must be between 1 and {MAX_PAGE}")));
        }
        let bbox = self
            .bbox
            .as_deref()
            .map(super::binary::parse_bbox)
            .transpose()
            .map_err(|e| ApiError::invalid("bbox", e))?;
        Ok(Some(Page { limit, bbox }))
    }
}

impl Page {
    /// Whether position `p` is on this page's viewport (compared as the binary stream's f32).
    pub(crate) fn shows(&self, p: [f64; 2]) -> bool {
        self.bbox.is_none_or(|[x0, y0, x1, y1]| {
            let (x, y) = (p[0] as f32, p[1] as f32);
            x >= x0 && x <= x1 && y >= y0 && y <= y1
        })
    }
}

/// 422 for an `after` naming no UAV.
pub(crate) fn no_uav_after(id: &str) -> ApiError {
    ApiError::invalid("after", format!("no UAV `{id}`"))
}

/// `GET /api/uavs[?bbox=x0,y0,x1,y1][&limit=N][&after=ID]`: the UAVs in fleet order, those inside
/// `bbox` only, starting after the UAV `after`, at most `limit` (1–1000, default 1000 when any
/// parameter is given). The next page starts after the last id of this one.
pub(crate) async fn list_uavs(
    State(app): State<AppState>,
    query: Result<axum::extract::Query<ListQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<Vec<UavSnapshot>>, ApiError> {
    let axum::extract::Query(q) = query.map_err(|e| ApiError::invalid("limit", e.body_text()))?;
    let snapshot = app.engine.snapshots.borrow().clone();
    let Some(page) = q.page()? else { return Ok(Json(snapshot.uavs.clone())) };
    let start = match &q.after {
        None => 0,
        Some(id) => position_of(&app, &snapshot, id).ok_or_else(|| no_uav_after(id))? + 1,
    };
    let shown = snapshot.uavs[start..].iter().filter(|u| page.shows(u.p));
    Ok(Json(shown.take(page.limit).cloned().collect()))
}

pub(crate) async fn get_uav(
    State(app): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<UavSnapshot>, ApiError> {
    let snapshot = app.engine.snapshots.borrow().clone();
    let found = position_of(&app, &snapshot, &id).and_then(|k| snapshot.uavs.get(k));
    found.cloned().map(Json).ok_or_else(|| ApiError::unknown_uav(&id))
}

/// Where UAV `id` is in `snapshot`: from the roster index of the latest frame, without a scan of the
/// fleet; only while the serialiser is still a tick behind and the roster changed does it scan.
pub(crate) fn position_of(app: &AppState, snapshot: &Snapshot, id: &str) -> Option<usize> {
    let frame = app.frames.borrow();
    let indexed = frame.binary.index.get(id).copied();
    if frame.tick() == snapshot.tick {
        return indexed;
    }
    match indexed {
        Some(k) if snapshot.uavs.get(k).is_some_and(|u| *u.id == *id) => Some(k),
        _ => snapshot.uavs.iter().position(|u| *u.id == *id),
    }
}

/// `POST /api/uavs` body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NewUav {
    /// Its id, unique in the fleet.
    #[schemars(with = "uav::schema::UavId")]
    id: String,
    /// Where it starts, at rest.
    #[schemars(with = "roads::schema::Point")]
    pub(crate) position: [f64; 2],
    /// A policy this server has loaded (`GET /api/policies`: `pd` and `rl` always, more with
    /// `serve --model NAME=FILE.onnx`); null or absent: the server's default (`serve --policy`).
    #[serde(default)]
    #[schemars(example = &"pd")]
    policy: Option<String>,
    /// Its goal; null or absent: it hovers.
    #[serde(default)]
    #[schemars(with = "Option<roads::schema::Point>")]
    goal: Option<[f64; 2]>,
    /// How it is flown; null or absent: `sim`.
    #[serde(default)]
    #[schemars(with = "Option<links::schema::LinkText>")]
    link: Option<String>,
}

/// A point of a request: two finite coordinates within the range roads may have.
fn point(field: &str, x: [f64; 2]) -> Result<Vec2, ApiError> {
    let limit = roads::MAX_COORDINATE_M;
    if x.iter().all(|c| c.is_finite() && c.abs() <= limit) {
        Ok(Vec2::new(x[0], x[1]))
    } else {
        Err(ApiError::invalid(field, format!("must be two finite numbers within ±{limit} m")))
    }
}

pub(crate) async fn add_uav(
    State(app): State<AppState>,
    ApiJson(new): ApiJson<NewUav>,
) -> Result<Response, ApiError> {
    uav::check_uav_id(&new.id).map_err(|reason| ApiError::invalid("id", reason))?;
    let position = point("position", new.position)?;
    let goal = new.goal.map(|g| point("goal", g)).transpose()?;
    if let Some(link) = &new.link {
        links::check_link_with(link, &app.link_rules).map_err(|reason| ApiError::invalid("link", reason))?;
    }
    let (id, link) = (new.id.clone(), new.link.clone());
    app.apply(Command::AddUav { id: new.id, position, policy: new.policy, goal, link: new.link }).await?;
    let link = link.unwrap_or_else(|| links::SIM_LINK.into());
    let location = format!("/api/uavs/{id}");
    let body = UavAdded { id, position: new.position, goal: new.goal, link };
    Ok((StatusCode::CREATED, [(header::LOCATION, location)], Json(body)).into_response())
}

pub(crate) async fn remove_uav(
    State(app): State<AppState>,
    Path(id): Path<String>,
    NoBody: NoBody,
) -> Result<StatusCode, ApiError> {
    app.apply(Command::RemoveUav(id)).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `PUT /api/uavs/{id}/goal` body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GoalBody {
    /// Where it flies to.
    #[schemars(with = "roads::schema::Point")]
    goal: [f64; 2],
}

pub(crate) async fn set_goal(
    State(app): State<AppState>,
    Path(id): Path<String>,
    ApiJson(body): ApiJson<GoalBody>,
) -> Result<Json<GoalSet>, ApiError> {
    let goal = point("goal", body.goal)?;
    app.apply(Command::SetGoal(id.clone(), Some(goal))).await?;
    Ok(Json(GoalSet { id, goal: body.goal }))
}

pub(crate) async fn clear_goal(
    State(app): State<AppState>,
    Path(id): Path<String>,
    NoBody: NoBody,
) -> Result<StatusCode, ApiError> {
    app.apply(Command::SetGoal(id, None)).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `PUT /api/uavs/{id}/policy` body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PolicyBody {
    /// A policy this server has loaded: `GET /api/policies` lists them (`pd` and `rl` always, more
    /// with `serve --model NAME=FILE.onnx`).
    #[schemars(example = &"pd")]
    policy: String,
}

pub(crate) async fn set_policy(
    State(app): State<AppState>,
    Path(id): Path<String>,
    ApiJson(body): ApiJson<PolicyBody>,
) -> Result<Json<PolicySet>, ApiError> {
    app.apply(Command::SetPolicy(id.clone(), body.policy.clone())).await?;
    Ok(Json(PolicySet { id, policy: body.policy }))
}

pub(crate) async fn list_policies(State(app): State<AppState>) -> Json<Policies> {
    Json(Policies { policies: app.policies.clone(), default: app.default_policy.clone() })
}

pub(crate) async fn load_scenario(
    State(app): State<AppState>,
    ApiJson(scenario): ApiJson<Scenario>,
) -> Result<Json<ScenarioLoaded>, ApiError> {
    // Refused before any validation work: the loop must be able to tick the fleet in dt.
    if scenario.uavs.len() > app.max_uavs {
        let full = engine::command::ChangeError::FleetFull { wanted: scenario.uavs.len(), max: app.max_uavs };
        return Err(full.into());
    }
    let rules = app.link_rules.clone();
    let valid = app
        .validate(move || {
            scenario.validate_with(&rules).map_err(|e| match e {
                fleet::ScenarioError::Invalid { field, reason } => ApiError::invalid(field, reason),
                other => ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_body", other.to_string()),
            })
        })
        .await?;
    let (name, count) = (valid.name.clone(), valid.uavs.len());
    let tick = match app.apply(Command::LoadScenario(Box::new(valid))).await? {
        Outcome::ScenarioLoaded { tick } => tick,
        _ => app.engine.snapshots.borrow().tick,
    };
    Ok(Json(ScenarioLoaded { name, uavs: count, loaded_after_tick: tick }))
}

pub(crate) async fn pause(State(app): State<AppState>, NoBody: NoBody) -> Result<Json<Paused>, ApiError> {
    app.apply(Command::Pause(true)).await?;
    Ok(Json(Paused { paused: true }))
}

pub(crate) async fn resume(State(app): State<AppState>, NoBody: NoBody) -> Result<Json<Paused>, ApiError> {
    app.apply(Command::Pause(false)).await?;
    Ok(Json(Paused { paused: false }))
}

pub(crate) async fn land_uav(
    State(app): State<AppState>,
    Path(id): Path<String>,
    NoBody: NoBody,
) -> Result<Json<Landing>, ApiError> {
    app.apply_urgent(Command::Land(Some(id.clone()))).await?;
    Ok(Json(Landing { landing: Reached::Uavs(vec![id]) }))
}

pub(crate) async fn land_fleet(
    State(app): State<AppState>,
    NoBody: NoBody,
) -> Result<Json<Landing>, ApiError> {
    app.apply_urgent(Command::Land(None)).await?;
    Ok(Json(Landing { landing: Reached::ALL }))
}

pub(crate) async fn stop_fleet(
    State(app): State<AppState>,
    NoBody: NoBody,
) -> Result<Json<Stopped>, ApiError> {
    // Straight to every Crazyflie's radio session first: that works even while the loop is stalled.
    let direct = app.engine.stops.stop_all();
    match app.apply_urgent(Command::EmergencyStop).await {
        Ok(_) => Ok(Json(Stopped { stopped: Reached::ALL })),
        Err(mut e) => {
            if direct > 0 {
                e.message = format!("{}; {direct} Crazyflies were sent the stop directly", e.message);
            }
            Err(e)
        }
    }
}

pub(crate) async fn get_state(State(app): State<AppState>) -> Response {
    let frame = app.frames.borrow().clone();
    let snapshot = app.engine.snapshots.borrow().clone();
    // The serialiser may still be on the previous tick: an answered change must show at once.
    let text = if frame.tick() == snapshot.tick { frame.json() } else { json_of(&snapshot) };
    ([(header::CONTENT_TYPE, "application/json")], axum::body::Bytes::from(text)).into_response()
}

/// `PUT /api/rerun/selection` body.
#[derive(Debug, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "RerunSelection")]
pub(crate) struct SelectionBody {
    /// UAV ids (at most 64; duplicates are dropped).
    #[schemars(with = "Vec<uav::schema::UavId>", length(max = rerun_sink::MAX_SELECTED))]
    ids: Vec<String>,
}

pub(crate) async fn get_rerun_selection(State(app): State<AppState>) -> Json<RerunSelection> {
    Json(RerunSelection { ids: app.rerun_selection.borrow().clone() })
}

/// Which UAVs keep their own Rerun entities when the fleet is logged as one batch. View state, like
/// the dashboard's selection: applied at once, not saved (a restart starts with none).
pub(crate) async fn put_rerun_selection(
    State(app): State<AppState>,
    ApiJson(body): ApiJson<SelectionBody>,
) -> Result<Json<RerunSelection>, ApiError> {
    use rerun_sink::MAX_SELECTED;
    if body.ids.len() > MAX_SELECTED {
        return Err(ApiError::invalid("ids", format!("at most {MAX_SELECTED} UAVs, got {}", body.ids.len())));
    }
    let mut ids: Vec<String> = Vec::with_capacity(body.ids.len());
    for id in body.ids {
        if !ids.contains(&id) {
            ids.push(id);
        }
    }
    // One pass over the fleet, whatever its size.
    let mut unseen: std::collections::HashSet<&str> = ids.iter().map(String::as_str).collect();
    for u in &app.engine.snapshots.borrow().uavs {
        unseen.remove(&*u.id);
    }
    if let Some(id) = ids.iter().find(|id| unseen.contains(id.as_str())) {
        return Err(ApiError::invalid("ids", format!("no UAV `{id}`")));
    }
    let ids: std::sync::Arc<[String]> = ids.into();
    app.rerun_selection.send_replace(ids.clone());
    Ok(Json(RerunSelection { ids }))
}

/// `GET /api/region/ownership`: this region's ownership intervals (404 without `--region`).
pub(crate) async fn get_ownership(State(app): State<AppState>) -> Result<Json<Ownership>, ApiError> {
    let Some(region) = &app.region else {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "no_region",
            "this server flies no region (--region)",
        ));
    };
    let (intervals, forgotten) = region.ownership.intervals();
    Ok(Json(Ownership { region: region.name.clone(), intervals, forgotten }))
}

pub(crate) async fn get_metrics(State(app): State<AppState>) -> Json<Metrics> {
    use std::sync::atomic::Ordering::Relaxed;
    let s = &app.stream;
    let mut fleet_loop = LoopMetrics::clone(&app.engine.metrics.borrow());
    fleet_loop.links.list_errors(&app.engine.snapshots.borrow());
    Json(Metrics {
        fleet_loop,
        stream: StreamReport {
            clients: s.clients.load(Relaxed),
            frames_sent: s.frames_sent.load(Relaxed),
            frames_skipped: s.frames_skipped.load(Relaxed),
            clients_dropped: s.clients_dropped.load(Relaxed),
            clients_refused: s.clients_refused.load(Relaxed),
            max_clients: app.max_stream_clients,
        },
        connections: app.connections.report(),
        auth: app.auth_failures.report(),
        storage: app.engine.storage.report(),
        mocap: app.mocap.report(),
        rerun: app.rerun.report(),
        region: app.region.as_ref().map(|r| r.report(std::time::Instant::now())),
        tick_age_ms: app.engine.clock.tick_age().as_secs_f64() * 1e3,
        max_uavs: app.max_uavs,
    })
}
