//! How `federate` puts the regions' answers together: `GET /api/state` and `GET /api/uavs` over
//! the whole deployment (each UAV tagged with its `region`), and a fleet-wide command's outcome in
//! every region. A region that did not answer is named, never silently left out.

use super::error::ApiError;
use super::state::AppState;
use axum::Json;
use axum::http::{StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use engine::snapshot::Snapshot;
use regions::federation::Answer;
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// The header of a merged `GET /api/uavs` naming the regions that did not answer (comma-separated).
pub const UNANSWERED_HEADER: &str = "x-airroads-unanswered-regions";

/// Every UAV of one region's answer, tagged with the region.
fn tagged(mut uavs: Value, region: &str) -> Vec<Value> {
    let Some(list) = uavs.as_array_mut() else { return Vec::new() };
    for u in list.iter_mut() {
        if let Some(object) = u.as_object_mut() {
            object.insert("region".into(), json!(region));
        }
    }
    std::mem::take(list)
}

/// A region's answer as JSON when it answered 200.
fn answered_json(answer: &Answer) -> Option<Value> {
    match answer {
        Answer::Replied(reply) if reply.status == 200 => serde_json::from_str(&reply.body).ok(),
        _ => None,
    }
}

/// How a region answered a merged read (`regions` of a merged `GET /api/state`).
#[derive(Debug, serde::Serialize)]
struct ReadReport {
    /// The region.
    name: String,
    /// It answered 200.
    answered: bool,
    /// The tick of its snapshot.
    #[serde(skip_serializing_if = "Option::is_none")]
    tick: Option<u64>,
    /// Its UAVs.
    #[serde(skip_serializing_if = "Option::is_none")]
    uavs: Option<usize>,
    /// Its status when it answered otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    status: Option<u16>,
}

/// The report of a region that answered `doc`.
fn answered_report(name: &str, doc: &Value) -> ReadReport {
    let uavs = Some(doc["uavs"].as_array().map_or(0, Vec::len));
    ReadReport { name: name.into(), answered: true, tick: doc["tick"].as_u64(), uavs, status: None }
}

/// The report of a region with no usable answer (`answer` says why).
fn unanswered_report(name: &str, answer: &Answer) -> ReadReport {
    let status = match answer {
        Answer::Replied(reply) => Some(reply.status),
        Answer::Silent => None,
    };
    ReadReport { name: name.into(), answered: false, tick: None, uavs: None, status }
}

/// One region's answer to a command or a deployment step sent to every region (`regions` of the
/// answer, by name).
#[derive(Debug, serde::Serialize)]
#[serde(untagged)]
pub enum RegionAnswer {
    /// Its status and body, as it gave them.
    Replied {
        /// HTTP status.
        status: u16,
        /// Its answer.
        body: Value,
    },
    /// This region's own: its status (its body is the answer's).
    Here {
        /// HTTP status.
        status: u16,
    },
    /// It did not answer.
    Silent {
        /// Always false.
        answered: bool,
    },
}

impl RegionAnswer {
    /// The entry of `answer`.
    pub fn of(answer: &Answer) -> Self {
        match answer {
            Answer::Replied(reply) => {
                let body = serde_json::from_str(&reply.body).unwrap_or(Value::Null);
                Self::Replied { status: reply.status, body }
            }
            Answer::Silent => Self::Silent { answered: false },
        }
    }
}

/// The smaller of two optional margins.
fn min_margin(a: &Value, b: &Value) -> Value {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) => json!(x.min(y)),
        (Some(x), None) | (None, Some(x)) => json!(x),
        (None, None) => Value::Null,
    }
}

/// `GET /api/state` over every region: this region's snapshot with the others' UAVs and
/// reservations added, the smallest margins of all, and `regions` (per region of the road:
/// `name`, `answered`, `tick`, `uavs`).
pub fn state(
    app: &AppState,
    own: &str,
    regions: &[String],
    answers: Vec<(String, Answer)>,
) -> Result<Response, ApiError> {
    let snapshot: std::sync::Arc<Snapshot> = app.engine.snapshots.borrow().clone();
    let mut doc = serde_json::to_value(&*snapshot)
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", e.to_string()))?;
    // A standby asked its own region's owner: its own empty fleet is not the region's.
    let standby = answers.iter().any(|(name, _)| name == own);
    let mut reports = Vec::new();
    if !standby {
        let uavs = Some(snapshot.uavs.len());
        let report =
            ReadReport { name: own.into(), answered: true, tick: Some(snapshot.tick), uavs, status: None };
        reports.push((own.to_string(), report));
    }
    let mut uavs = tagged(doc["uavs"].take(), own);
    for (name, answer) in answers {
        let Some(mut other) = answered_json(&answer) else {
            reports.push((name.clone(), unanswered_report(&name, &answer)));
            continue;
        };
        reports.push((name.clone(), answered_report(&name, &other)));
        uavs.extend(tagged(other["uavs"].take(), &name));
        if let (Some(mine), Some(theirs)) =
            (doc["reservations"].as_array_mut(), other["reservations"].as_array_mut())
        {
            mine.append(theirs);
        }
        for key in ["min_collision_margin_m", "min_road_margin_m"] {
            doc[key] = min_margin(&doc[key], &other[key]);
        }
    }
    doc["uavs"] = Value::Array(uavs);
    reports.sort_by_key(|(name, _)| regions.iter().position(|r| r == name).unwrap_or(usize::MAX));
    let reports: Vec<ReadReport> = reports.into_iter().map(|(_, r)| r).collect();
    doc["regions"] = serde_json::to_value(reports).unwrap_or_default();
    Ok(Json(doc).into_response())
}

/// `GET /api/uavs` over every region: the regions' UAVs in the road's region order, each tagged
/// with its `region`, then `bbox`, `after` and `limit` as for one region; the regions that did not
/// answer are named in [`UNANSWERED_HEADER`].
pub fn list(
    uri: &Uri,
    snapshot: std::sync::Arc<Snapshot>,
    own: &str,
    regions: &[String],
    answers: Vec<(String, Answer)>,
) -> Result<Response, ApiError> {
    let q = axum::extract::Query::<super::handlers::ListQuery>::try_from_uri(uri)
        .map_err(|e| ApiError::invalid("limit", e.body_text()))?
        .0;
    let own_uavs = serde_json::to_value(&snapshot.uavs).unwrap_or(Value::Null);
    let standby = answers.iter().any(|(name, _)| name == own);
    let mut by_region = Vec::new();
    if !standby {
        by_region.push((own.to_string(), tagged(own_uavs, own)));
    }
    let mut unanswered = Vec::new();
    for (name, answer) in answers {
        match answered_json(&answer) {
            Some(list) => by_region.push((name.clone(), tagged(list, &name))),
            None => unanswered.push(name),
        }
    }
    by_region.sort_by_key(|(name, _)| regions.iter().position(|r| r == name).unwrap_or(usize::MAX));
    let all: Vec<Value> = by_region.into_iter().flat_map(|(_, list)| list).collect();
    let page: Vec<Value> = match q.page()? {
        None => all,
        Some(page) => {
            let start = match &q.after {
                None => 0,
                Some(id) => {
                    all.iter()
                        .position(|u| u["id"] == *id)
                        .ok_or_else(|| super::handlers::no_uav_after(id))?
                        + 1
                }
            };
            let at =
                |u: &Value| [u["p"][0].as_f64().unwrap_or(f64::NAN), u["p"][1].as_f64().unwrap_or(f64::NAN)];
            all[start..].iter().filter(|u| page.shows(at(u))).take(page.limit).cloned().collect()
        }
    };
    let mut response = Json(page).into_response();
    if let Ok(value) = header::HeaderValue::from_str(&unanswered.join(",")) {
        response.headers_mut().insert(UNANSWERED_HEADER, value);
    }
    Ok(response)
}

/// A fleet-wide command applied here (`local`, a success) and sent to the other regions: the local
/// body with `regions` (per region: `status`, or `answered: false`); 502 `regions_failed` when
/// any other region refused it or did not answer (it was applied here and in those that said so).
pub async fn fleet_command(local: Response, own: &str, answers: Vec<(String, Answer)>) -> Response {
    let status = local.status();
    let body = axum::body::to_bytes(local.into_body(), 1 << 20).await.unwrap_or_default();
    let mut doc: Value = serde_json::from_slice(&body).unwrap_or_else(|_| json!({}));
    let mut report = BTreeMap::new();
    report.insert(own.to_string(), RegionAnswer::Here { status: status.as_u16() });
    let mut failed = Vec::new();
    for (name, answer) in answers {
        let confirmed = matches!(&answer, Answer::Replied(reply) if (200..300).contains(&reply.status));
        if !confirmed {
            failed.push(name.clone());
        }
        report.insert(name, RegionAnswer::of(&answer));
    }
    let report = serde_json::to_value(report).unwrap_or_default();
    if failed.is_empty() {
        doc["regions"] = report;
        return (status, Json(doc)).into_response();
    }
    let message = format!("applied in region `{own}`, not confirmed by {}", failed.join(", "));
    let mut error = ApiError::new(StatusCode::BAD_GATEWAY, "regions_failed", message);
    error.extra = Some(serde_json::Map::from_iter([("regions".to_string(), report)]));
    error.into_response()
}
