//! A road or a scenario for the whole deployment (`--region`; docs/regions.md, One
//! fleet): `PUT /api/road` and `POST /api/scenario` sent to any region's owner apply to every region
//! at the same instant, or to none.
//!
//! Two steps over the regions' queryables. *Prepare*: every region validates the change against its
//! own fleet (a road: every UAV in the air safe on it, `Command::CheckRoad`; a scenario: its share of
//! the UAVs, those starting in its region, fits under `--max-uavs`) and says yes or why not. Any
//! refusal, or a region that does not answer, ends it: nothing was changed anywhere, and the answer
//! is that region's, with its name. *Commit*: every region gets the change with one tick boundary
//! at least [`SWITCH_DELAY`] ahead (regions tick on the wall clock's multiples of dt, `engine.rs`),
//! queues it half a tick before and so applies it in the gap at that boundary: every region
//! switches at the same tick boundary (with clocks in sync), then answers once the change is
//! applied and on disk. If a region fails at the commit (its fleet moved into a conflict since the
//! prepare, or it died), the regions that switched to the new road are switched back to the old one
//! and the answer is 502 `deployment_failed`; a scenario cannot be taken back (its fleet replaced the
//! old one) and the answer names the regions that loaded it.

use super::answers::{RoadReplaced, ScenarioLoaded};
use super::error::ApiError;
use super::federate_merge::RegionAnswer;
use super::request::ApiRequest;
use super::state::AppState;
use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use engine::command::{Command, NewRoad, Outcome};
use engine::fleet_loop::now_ms;
use fleet::{Scenario, ValidScenario};
use regions::federation::{Answer, ApiQuery, ApiReply, Federation, Kind, Step};
use roads::{Airspace, AirspaceLayout};

use serde_json::{Map, Value, json};
use std::collections::BTreeMap;
use std::time::Duration;

/// How far ahead of the commit the regions switch: room for every region to receive it.
pub const SWITCH_DELAY: Duration = Duration::from_millis(500);
/// How long a region may take to answer a commit (the delay, one tick, the disk).
pub const COMMIT_TIMEOUT: Duration = Duration::from_secs(5);

/// A scenario's refusal as the API gives it (422 naming the field).
fn scenario_refused(e: fleet::ScenarioError) -> ApiError {
    match e {
        fleet::ScenarioError::Invalid { field, reason } => ApiError::invalid(field, reason),
        other => ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_body", other.to_string()),
    }
}

/// The layout of a step's body (a road or network, or a scenario's) and the narrowest passage a
/// network of it must have: `min_passage_m` (the fleet's now) for a road, the scenario's own
/// parameters' for a scenario.
fn layout_of(kind: Kind, body: &str, min_passage_m: f64) -> Result<(AirspaceLayout, f64), ApiError> {
    match kind {
        Kind::Road => Ok((super::road::parse_layout(body.as_bytes())?, min_passage_m)),
        Kind::Scenario => {
            let scenario = super::error::parse::<Scenario>(body.as_bytes())?;
            let layout = scenario.layout().map_err(scenario_refused)?;
            Ok((layout, fleet::min_passage_m(&scenario.params)))
        }
    }
}

/// 422 unless `new` (a road or network) keeps the regions of `old` and their neighbours (each
/// region's server subscribes to its neighbours once, at its start).
fn check_same_regions(old: &Airspace, new: &Airspace) -> Result<(), ApiError> {
    let (before, after) = (old.region_names(), new.region_names());
    let mut sorted = (before.clone(), after.clone());
    sorted.0.sort();
    sorted.1.sort();
    if sorted.0 != sorted.1 {
        let message = format!(
            "a road for the whole deployment keeps its regions ({}); this one has ({})",
            before.join(", "),
            after.join(", ")
        );
        return Err(ApiError::invalid("regions", message));
    }
    for &name in &before {
        let (a, b) = (regions::neighbours_of(old, name), regions::neighbours_of(new, name));
        if a != b {
            let message = format!(
                "the neighbours of region `{name}` would change ({} → {}): restart its servers for that",
                a.unwrap_or_default().join(", "),
                b.unwrap_or_default().join(", ")
            );
            return Err(ApiError::invalid("regions", message));
        }
    }
    Ok(())
}

/// The scenario of `body`, validated, with only the UAVs that start in region `own`.
fn scenario_for(rules: &links::LinkRules, body: &str, own: &str) -> Result<ValidScenario, ApiError> {
    let scenario = super::error::parse::<Scenario>(body.as_bytes())?;
    let mut valid = scenario.validate_with(rules).map_err(scenario_refused)?;
    let road = &valid.road;
    valid.uavs.retain(|u| road.region_at(&u.start) == Some(own));
    Ok(valid)
}

/// This region's side of `step` (asked by the coordinator, which may be this server).
pub async fn answer(app: &AppState, own: &str, step: Step) -> Response {
    match run_step(app, own, step).await {
        Ok(body) => Json(body).into_response(),
        Err(e) => e.into_response(),
    }
}

/// What a region answers to a deployment's step: ready (a prepare), or what it put in place.
#[derive(Debug, serde::Serialize)]
#[serde(untagged)]
enum StepDone {
    /// The prepare passed: the region can take it.
    Ready {
        /// Always true.
        ready: bool,
    },
    /// The road is in place (`PUT /api/road`'s answer).
    Road {
        /// Its version and the goals it cleared.
        #[serde(flatten)]
        replaced: RoadReplaced,
        /// When the loop put it in place (ms since the Unix epoch, this server's clock).
        switched_at_ms: u64,
    },
    /// The scenario is loaded (`POST /api/scenario`'s answer).
    Scenario {
        /// Its name, UAVs and tick.
        #[serde(flatten)]
        loaded: ScenarioLoaded,
        /// When the loop put it in place.
        switched_at_ms: u64,
    },
}

async fn run_step(app: &AppState, own: &str, step: Step) -> Result<StepDone, ApiError> {
    let (current, min_passage_m) = {
        let view = app.engine.road.borrow();
        (view.layout.clone(), view.min_passage_m)
    };
    let (kind, body) = (step.kind, step.body.clone());
    let own_name = own.to_string();
    let rules = app.link_rules.clone();
    // Validated on the blocking pool, one large input at a time, as over REST.
    let (road, scenario) = app
        .validate(move || {
            let (layout, passage_m) = layout_of(kind, &body, min_passage_m)?;
            let road = super::road::airspace_of(layout, passage_m)?;
            // Built before with the passages it had to have then: only its regions are read here.
            let old = current.build(0.0).map_err(|e| ApiError::invalid("road", e.message))?;
            check_same_regions(&old, &road)?;
            let scenario =
                (kind == Kind::Scenario).then(|| scenario_for(&rules, &body, &own_name)).transpose()?;
            Ok((road, scenario))
        })
        .await?;
    if let Some(s) = &scenario
        && s.uavs.len() > app.max_uavs
    {
        return Err(
            engine::command::ChangeError::FleetFull { wanted: s.uavs.len(), max: app.max_uavs }.into()
        );
    }
    if !step.commit {
        if kind == Kind::Road {
            app.apply(Command::CheckRoad(Box::new(road))).await?;
        }
        return Ok(StepDone::Ready { ready: true });
    }
    // Queued half a tick before the boundary: the loop takes it in the gap at the boundary.
    let half_tick = (app.engine.metrics.borrow().dt * 500.0) as u64;
    let wait =
        step.at_ms.saturating_sub(half_tick).saturating_sub(now_ms()).min(COMMIT_TIMEOUT.as_millis() as u64);
    tokio::time::sleep(Duration::from_millis(wait)).await;
    let done = match scenario {
        None => {
            let new = NewRoad { road, checked_passage_m: min_passage_m };
            let cleared_goals = match app.apply(Command::SetRoad(Box::new(new))).await? {
                Outcome::RoadReplaced { cleared_goals } => cleared_goals,
                _ => Vec::new(),
            };
            let replaced = RoadReplaced { version: app.engine.road.borrow().version, cleared_goals };
            StepDone::Road { replaced, switched_at_ms: app.engine.road.borrow().since_ms }
        }
        Some(valid) => {
            let (name, uavs) = (valid.name.clone(), valid.uavs.len());
            let loaded_after_tick = match app.apply(Command::LoadScenario(Box::new(valid))).await? {
                Outcome::ScenarioLoaded { tick } => tick,
                _ => app.engine.snapshots.borrow().tick,
            };
            let loaded = ScenarioLoaded { name, uavs, loaded_after_tick };
            // When the loop put the new road in place (the gap at the boundary, on this server's clock).
            StepDone::Scenario { loaded, switched_at_ms: app.engine.road.borrow().since_ms }
        }
    };
    Ok(done)
}

/// Runs `step` in every region of `regions` (this one directly, the others over Zenoh).
async fn everywhere(
    app: &AppState,
    federation: &Federation,
    regions: &[String],
    step: &Step,
    timeout: Duration,
    authorization: &Option<String>,
) -> Vec<(String, Answer)> {
    let query: ApiQuery<ApiRequest> = ApiQuery {
        request: None,
        uav: None,
        deploy: Some(step.clone()),
        authorization: authorization.clone(),
        client: None,
    };
    let asks = regions.iter().map(|region| {
        let query = &query;
        async move {
            if *region == federation.own {
                let response = answer(app, region, step.clone()).await;
                (region.clone(), Answer::Replied(super::federate::reply_of(response).await))
            } else {
                (region.clone(), federation.ask_within(region, query, timeout).await)
            }
        }
    });
    futures_util::future::join_all(asks).await
}

/// A region's refusal or silence as the answer: its status and body, the error naming the region.
fn refused(region: &str, answer: Answer) -> Response {
    let Answer::Replied(ApiReply { status, body }) = answer else {
        return super::federate::unanswered(region);
    };
    let mut doc: Value = serde_json::from_str(&body).unwrap_or_else(|_| json!({"error": {}}));
    if let Some(error) = doc.get_mut("error").and_then(Value::as_object_mut) {
        error.insert("region".into(), json!(region));
    }
    let status = StatusCode::from_u16(status).unwrap_or(StatusCode::BAD_GATEWAY);
    (status, Json(doc)).into_response()
}

/// The answer of a deployment every region applied: this region's own answer with each region's.
#[derive(Debug, serde::Serialize)]
struct Deployed {
    /// This region's answer (`StepDone`), at the top level.
    #[serde(flatten)]
    own: Map<String, Value>,
    /// Each region's answer, by name.
    regions: BTreeMap<String, RegionAnswer>,
    /// The tick boundary every region switched at (ms since the Unix epoch).
    switch_at_ms: u64,
}

/// Deploys `body` (a `kind`) to every region of the served road, as the coordinator.
/// `authorization`: the operator's, for each region to check itself.
pub async fn coordinate(
    app: &AppState,
    federation: &Federation,
    kind: Kind,
    body: String,
    authorization: Option<String>,
) -> Response {
    let old_layout = app.engine.road.borrow().layout.clone();
    let regions: Vec<String> = old_layout.region_names().into_iter().map(String::from).collect();
    let prepare = Step { commit: false, kind, body: body.clone(), at_ms: 0 };
    for (region, answer) in
        everywhere(app, federation, &regions, &prepare, regions::federation::ASK_TIMEOUT, &authorization)
            .await
    {
        let ok = matches!(&answer, Answer::Replied(r) if (200..300).contains(&r.status));
        if !ok {
            return refused(&region, answer);
        }
    }
    // The first tick boundary (a multiple of dt on the wall clock) after the delay.
    let dt_ms = ((app.engine.metrics.borrow().dt * 1e3).round() as u64).max(1);
    let at_ms = (now_ms() + SWITCH_DELAY.as_millis() as u64).div_ceil(dt_ms) * dt_ms;
    let commit = Step { commit: true, kind, body, at_ms };
    let answers = everywhere(app, federation, &regions, &commit, COMMIT_TIMEOUT, &authorization).await;
    let mut report = BTreeMap::new();
    let (mut failed, mut switched) = (Vec::new(), Vec::new());
    let mut own_body = Map::new();
    for (region, answer) in answers {
        let entry = RegionAnswer::of(&answer);
        match (&answer, &entry) {
            (Answer::Replied(reply), RegionAnswer::Replied { body, .. })
                if (200..300).contains(&reply.status) =>
            {
                if region == federation.own {
                    own_body = body.as_object().cloned().unwrap_or_default();
                }
                switched.push(region.clone());
            }
            _ => failed.push(region.clone()),
        }
        report.insert(region, entry);
    }
    if failed.is_empty() {
        return Json(Deployed { own: own_body, regions: report, switch_at_ms: at_ms }).into_response();
    }
    let mut message = format!("not applied in {}", failed.join(", "));
    if kind == Kind::Road && !switched.is_empty() {
        let old = serde_json::to_string(&old_layout).unwrap_or_default();
        let back = Step { commit: true, kind, body: old, at_ms: now_ms() };
        let undone = everywhere(app, federation, &switched, &back, COMMIT_TIMEOUT, &authorization).await;
        let ok: Vec<String> = undone
            .into_iter()
            .filter(|(_, a)| matches!(a, Answer::Replied(r) if (200..300).contains(&r.status)))
            .map(|(r, _)| r)
            .collect();
        message = format!(
            "{message}; the old road was put back in {}",
            if ok.is_empty() { "none".into() } else { ok.join(", ") }
        );
    } else if !switched.is_empty() {
        message = format!("{message}; loaded in {}", switched.join(", "));
    }
    let mut error = ApiError::new(StatusCode::BAD_GATEWAY, "deployment_failed", message);
    let report = serde_json::to_value(report).unwrap_or_default();
    error.extra = Some(Map::from_iter([("regions".to_string(), report)]));
    error.into_response()
}

#[cfg(test)]
#[path = "deploy_tests.rs"]
mod tests;
