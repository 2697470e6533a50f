//! One fleet to the operator (`--region`; docs/regions.md, One fleet): any region's REST
//! API answers for every UAV of the deployment. A middleware, after the token check, looks at each
//! request: a request about a UAV this region does not fly goes to the region that does (its owner
//! answers; the status and body come back unchanged); `POST /api/uavs` goes to the region of the
//! new UAV's position; `GET /api/state` and `GET /api/uavs` merge every region's answer; the
//! fleet-wide commands (`/api/fleet/pause|resume|land|stop`) are applied here first, then in every
//! other region. `?scope=region` keeps a read to this region alone.
//!
//! A forwarded request travels typed (`request::ApiRequest`: its route and data, parsed once
//! here; a body its route refuses is refused here). The other side: requests from other regions
//! arrive on this region's queryable and run through the same API handlers directly (not through
//! the router nor this middleware, so nothing is routed or forwarded twice); only the region's
//! owner answers. The owner checks the operator's token itself (carried with the
//! request) and audits the change in its own log, with the asking region and the operator's
//! address; only servers with a certificate of the deployment can ask (`region::secure`).

use super::error::{ApiError, MAX_BODY_BYTES};
use super::handlers;
use super::request::ApiRequest;
use super::routes::Reach;
use super::state::AppState;
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use regions::federation::{Answer, ApiQuery, ApiReply, Federation, MAX_CARRIED_BYTES};
use serde_json::json;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Semaphore;

/// Requests from other regions run at once at most (more are answered 503 `busy`).
pub const MAX_CONCURRENT_QUERIES: usize = 16;
/// Requests of this server's clients waiting on other regions at once at most (more are answered
/// 503 `busy` at once); a quarter of the default connection cap.
pub const MAX_FORWARDED: usize = 64;
/// A request about a UAV nobody answered for is asked again once after this long (it may have
/// been between two regions, released and not yet adopted).
const RETRY_AFTER: Duration = Duration::from_millis(150);

/// What the middleware does with a request.
#[derive(Debug, PartialEq)]
enum Route {
    /// About UAV `id`: here if flown here, else at its owner.
    Uav(String),
    /// `GET /api/state`: merged.
    State,
    /// `GET /api/uavs`: merged.
    List,
    /// `POST /api/uavs`: at the region of the position.
    Add,
    /// `POST /api/fleet/...`: here, then everywhere.
    Fleet,
    /// `PUT /api/road` or `POST /api/scenario`: every region at once, or none (`deploy`).
    Deploy(regions::federation::Kind),
    /// Here only.
    Local,
}

/// Where a request to `found` is answered (the route table's [`Reach`], with the UAV's id).
fn route(found: Option<(&'static super::routes::Route, Option<&str>)>) -> Route {
    let Some((route, id)) = found else { return Route::Local };
    match (route.reach, id) {
        (Reach::Uav, Some(id)) => Route::Uav(id.to_string()),
        (Reach::State, _) => Route::State,
        (Reach::List, _) => Route::List,
        (Reach::Add, _) => Route::Add,
        (Reach::Fleet, _) => Route::Fleet,
        (Reach::Deploy(kind), _) => Route::Deploy(kind),
        (Reach::Here | Reach::Uav, _) => Route::Local,
    }
}

/// The query parameter of a read every region answers (`GET /api/state`, `GET /api/uavs`), as the
/// document states it; [`scope_is_region`] reads it.
#[derive(schemars::JsonSchema)]
pub struct ScopeQuery {
    /// With `serve --region`: `fleet` (the default) answers for every region of the deployment,
    /// `region` for this server's region alone; without `--region` both are this server's fleet.
    pub scope: Option<Scope>,
}

/// Which fleet a read answers for.
#[derive(schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Scope {
    /// Every region's.
    Fleet,
    /// This server's region's.
    Region,
}

/// `scope` of the query string: `fleet` (the default) or `region`.
fn scope_is_region(query: Option<&str>) -> Result<bool, ApiError> {
    let value = query.unwrap_or_default().split('&').find_map(|kv| kv.strip_prefix("scope="));
    match value {
        None | Some("fleet") => Ok(false),
        Some("region") => Ok(true),
        Some(other) => Err(ApiError::invalid("scope", format!("`{other}`: expected `fleet` or `region`"))),
    }
}

/// The middleware (a pass-through without `--region` or before the Zenoh side started).
pub async fn forward(State(app): State<AppState>, request: Request, next: Next) -> Response {
    // Checked with or without regions: a script gets the same answer from every server.
    let local = match scope_is_region(request.uri().query()) {
        Ok(local) => local,
        Err(e) => return e.into_response(),
    };
    let Some(federation) = app.region.as_ref().and_then(|r| r.federation.get()).cloned() else {
        return next.run(request).await;
    };
    let found = super::routes::find(request.method(), request.uri().path());
    let found = found.map(|(route, id)| (route, id.map(str::to_string)));
    let route = route(found.as_ref().map(|(r, id)| (*r, id.as_deref())));
    // A standby flies nothing and refuses changes (409 `standby`); its reads ask every region,
    // its own included (whose owner answers).
    let owner = app.region.as_ref().is_some_and(|r| r.failover.is_owner());
    let read = request.method() == Method::GET;
    let flown = matches!(&route, Route::Uav(id) if flown_here(&app, id));
    // Only reads and changes travel; any other method is answered here (405 from the router).
    let travels = read || super::guard::is_change(request.method());
    if local || flown || route == Route::Local || !travels || !(owner || read) {
        return next.run(request).await;
    }
    let (parts, body) = request.into_parts();
    let Ok(bytes) = axum::body::to_bytes(body, MAX_BODY_BYTES).await else {
        return ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", "the body is too large")
            .into_response();
    };
    let authorization =
        parts.headers.get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()).map(str::to_string);
    let client =
        parts.extensions.get::<axum::extract::ConnectInfo<std::net::SocketAddr>>().map(|c| c.0.to_string());
    let held = Held { parts, next, bytes };
    let bytes = &held.bytes;
    if let Route::Deploy(kind) = route {
        let body = String::from_utf8_lossy(bytes).into_owned();
        return super::deploy::coordinate(&app, &federation, kind, body, authorization).await;
    }
    // The request parsed once, here; a body its route refuses is refused here, as it would be there.
    let typed = found.and_then(|(r, id)| ApiRequest::of(r, id.as_deref(), bytes));
    let Some(Ok(typed)) = typed else { return held.here().await };
    let query = ApiQuery { request: Some(typed), uav: None, deploy: None, authorization, client };
    // Requests waiting on other regions are bounded, so they never take every connection; the
    // fleet-wide commands (the emergency stop among them) are never refused here.
    let _permit = match route {
        Route::Fleet => None,
        _ => match app.forwarding.clone().try_acquire_owned() {
            Ok(permit) => Some(permit),
            Err(_) => {
                return ApiError::busy("too many requests waiting on other regions; try again")
                    .into_response();
            }
        },
    };
    send(&app, &federation, route, query, held).await
}

/// A request held by the middleware: answered here when it comes to that.
struct Held {
    parts: axum::http::request::Parts,
    next: Next,
    bytes: Bytes,
}

impl Held {
    /// Answers it here (the router and its handler).
    async fn here(self) -> Response {
        self.next.run(Request::from_parts(self.parts, Body::from(self.bytes))).await
    }
}

/// Sends `query` where its `route` is answered (see the module documentation).
async fn send(
    app: &AppState,
    federation: &Federation,
    route: Route,
    query: ApiQuery<ApiRequest>,
    held: Held,
) -> Response {
    let owner = app.region.as_ref().is_some_and(|r| r.failover.is_owner());
    let position = match &query.request {
        Some(ApiRequest::AddUav { body }) => Some(body.position),
        _ => None,
    };
    let uri = held.parts.uri.clone();
    let all = region_names(app);
    let mut regions = all.clone();
    if owner {
        regions.retain(|r| *r != federation.own);
    }
    match route {
        Route::Uav(id) => ask_owner(app, federation, &regions, &id, query, held).await,
        Route::Add => match position.and_then(|p| region_of_position(app, federation, p)) {
            Some(region) if region != federation.own => match federation.ask(&region, &query).await {
                Answer::Replied(reply) => replied(reply),
                Answer::Silent => unanswered(&region),
            },
            _ => held.here().await,
        },
        Route::Fleet => {
            let response = held.here().await;
            if !response.status().is_success() {
                return response;
            }
            let answers = federation.ask_all(&regions, &query).await;
            super::federate_merge::fleet_command(response, &federation.own, answers).await
        }
        Route::State | Route::List => {
            // Each region gives all its UAVs; pages and boxes apply to the merged list.
            let answers = federation.ask_all(&regions, &query).await;
            let merged = if route == Route::State {
                super::federate_merge::state(app, &federation.own, &all, answers)
            } else {
                let snapshot = app.engine.snapshots.borrow().clone();
                super::federate_merge::list(&uri, snapshot, &federation.own, &all, answers)
            };
            merged.unwrap_or_else(IntoResponse::into_response)
        }
        Route::Deploy(_) | Route::Local => held.here().await,
    }
}

/// A request about UAV `id`, not flown here: its owner's answer (every region is asked, twice if
/// none flies it: it may have been between two regions), here if it was adopted meanwhile.
async fn ask_owner(
    app: &AppState,
    federation: &Federation,
    regions: &[String],
    id: &str,
    query: ApiQuery<ApiRequest>,
    held: Held,
) -> Response {
    let mut silent = Vec::new();
    let asked = ApiQuery { uav: Some(id.to_string()), ..query };
    for attempt in 0..2 {
        // Adopted here meanwhile (it was between two regions at the first ask).
        if attempt > 0 && flown_here(app, id) {
            return held.here().await;
        }
        silent.clear();
        for (region, answer) in federation.ask_all(regions, &asked).await {
            match answer {
                // Every owner answers: 404 `unknown_uav` when it does not fly the UAV.
                Answer::Replied(reply) if reply.status != 404 => return replied(reply),
                Answer::Replied(_) => {}
                Answer::Silent => silent.push(region),
            }
        }
        if attempt == 0 {
            // Between two regions (released, not yet adopted), or a region restarting.
            tokio::time::sleep(RETRY_AFTER).await;
        }
    }
    match silent.first() {
        Some(region) => unanswered(region),
        None => held.here().await,
    }
}

/// The road's regions, in its order.
fn region_names(app: &AppState) -> Vec<String> {
    let road = app.engine.road.borrow();
    road.layout.region_names().into_iter().map(String::from).collect()
}

/// This region flies UAV `id` now (by the latest snapshot).
fn flown_here(app: &AppState, id: &str) -> bool {
    let snapshot = app.engine.snapshots.borrow().clone();
    handlers::position_of(app, &snapshot, id).is_some()
}

/// The region of a new UAV's `position` (None: on no region).
fn region_of_position(app: &AppState, federation: &Federation, position: [f64; 2]) -> Option<String> {
    let view = app.engine.road.borrow().clone();
    let road = federation.road(&view)?;
    road.region_at(&uav::Vec2::new(position[0], position[1])).map(String::from)
}

/// Another region's answer, as it gave it.
fn replied(reply: ApiReply) -> Response {
    let status = StatusCode::from_u16(reply.status).unwrap_or(StatusCode::BAD_GATEWAY);
    (status, [(header::CONTENT_TYPE, "application/json")], reply.body).into_response()
}

/// 503 `region_unavailable`: a region that may fly the UAV, or must apply the change, did not
/// answer (no owner, or unreachable); nothing was changed there.
pub fn unanswered(region: &str) -> Response {
    let message = format!("region `{region}` did not answer; nothing was changed there");
    let mut error = ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "region_unavailable", message);
    error.extra = Some(serde_json::Map::from_iter([("region".to_string(), json!(region))]));
    error.into_response()
}

/// Answers other regions' requests on this region's queryable until the session closes; returns
/// the queryable (undeclared when dropped).
pub async fn answer_queries(
    federation: &Federation,
    session: &zenoh::Session,
    app: AppState,
) -> anyhow::Result<zenoh::query::Queryable<()>> {
    let key = federation.own_key();
    let runtime = tokio::runtime::Handle::current();
    let permits = Arc::new(Semaphore::new(MAX_CONCURRENT_QUERIES));
    session
        .declare_queryable(key.as_str())
        .callback(move |query| {
            let (app, permits) = (app.clone(), permits.clone());
            runtime.spawn(async move {
                let Ok(_permit) = permits.try_acquire() else {
                    let body = ApiError::busy("too many requests from other regions").into_response();
                    reply(&query, body).await;
                    return;
                };
                if let Some(response) = run_query(&app, &query).await {
                    reply(&query, response).await;
                }
            });
        })
        .await
        .map_err(|e| anyhow::anyhow!("declaring the queryable {key}: {e}"))
}

/// Runs one request from another region through the API handlers; None: this server does not
/// answer it (a standby). A request about a UAV not flown here is answered 404 `unknown_uav`.
async fn run_query(app: &AppState, query: &zenoh::query::Query) -> Option<Response> {
    let owner = app.region.as_ref().is_some_and(|r| r.failover.is_owner());
    if !owner {
        return None;
    }
    // Asked on `.../api/ASKER` by a server of this deployment's region ASKER (another region, or
    // this region's standby; the access control lets only ASKER's certificates ask there);
    // anything else is not answered.
    let region = app.region.as_ref()?;
    let asker = region.federation.get()?.asker(query.key_expr().as_str())?;
    let known = app.engine.road.borrow().layout.region_names().contains(&asker);
    if !known {
        return None;
    }
    let payload = query.payload()?;
    if payload.len() > MAX_CARRIED_BYTES {
        return Some(
            ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", "too large").into_response(),
        );
    }
    let asked: ApiQuery<ApiRequest> = match serde_json::from_slice(&payload.to_bytes()) {
        Ok(q) => q,
        Err(e) => return Some(ApiError::invalid("query", e.to_string()).into_response()),
    };
    let given = asked.authorization.as_deref().and_then(|a| axum::http::HeaderValue::from_str(a).ok());
    if let Some(step) = asked.deploy {
        // A deployment step is no API route: its token is checked here (every other request
        // passes the API's own token check below).
        if let Some(token) = &app.token
            && !super::auth::authorised(given.as_ref(), token)
        {
            let message = "this server needs `Authorization: Bearer <token>` for changes";
            return Some(ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", message).into_response());
        }
        let own = app.region.as_ref().map(|r| r.name.clone()).unwrap_or_default();
        return Some(super::deploy::answer(app, &own, step).await);
    }
    if let Some(id) = asked.uav.as_deref().filter(|id| !flown_here(app, id)) {
        return Some(ApiError::unknown_uav(id).into_response());
    }
    let Some(request) = asked.request else {
        return Some(ApiError::invalid("query", "neither a request nor a deployment step").into_response());
    };
    // The operator's authority is checked here, by the API's own token check and rate limit (the
    // operator's address stands for the client's: wrong tokens count against its network), and
    // the change audited here, where it is applied (in its own transaction), naming the region
    // and the operator's address.
    let (route, _) = request.route();
    let (method, path) = (route.verb.method(), request.path());
    let ip = asked.client.as_deref().and_then(|c| c.parse::<std::net::SocketAddr>().ok()).map(|c| c.ip());
    let remote = super::audit::Forwarded { region: asker.to_string(), client: asked.client }.remote();
    let handled = async {
        match super::auth::refusal(app, ip, &method, &path, given.as_ref()) {
            None => request.run(app.clone()).await,
            Some(refused) => refused,
        }
    };
    Some(super::audit::audited(app, &method, path.clone(), remote, handled).await)
}

/// A response as an [`ApiReply`] (its status and body).
pub async fn reply_of(response: Response) -> ApiReply {
    let status = response.status().as_u16();
    let body = axum::body::to_bytes(response.into_body(), MAX_CARRIED_BYTES).await.unwrap_or_default();
    ApiReply { status, body: String::from_utf8_lossy(&body).into_owned() }
}

/// Sends `response` back as an [`ApiReply`].
async fn reply(query: &zenoh::query::Query, response: Response) {
    let answer = reply_of(response).await;
    let Ok(payload) = serde_json::to_vec(&answer) else { return };
    // A plain key (not the query's wire form, which may name a resource the asker declared): the
    // asker's access control resolves a reply's key before letting it in.
    let key = query.key_expr().as_str().to_string();
    if let Err(e) = query.reply(key, payload).await {
        tracing::warn!("answering another region: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn route(method: &Method, path: &str) -> Route {
        super::route(crate::routes::find(method, path))
    }

    #[test]
    fn requests_are_routed_by_method_and_path() {
        assert_eq!(route(&Method::PUT, "/api/uavs/u1/goal"), Route::Uav("u1".into()));
        assert_eq!(route(&Method::GET, "/api/uavs/u1"), Route::Uav("u1".into()));
        assert_eq!(route(&Method::DELETE, "/api/uavs/u1"), Route::Uav("u1".into()));
        assert_eq!(route(&Method::GET, "/api/uavs"), Route::List);
        assert_eq!(route(&Method::POST, "/api/uavs"), Route::Add);
        assert_eq!(route(&Method::GET, "/api/state"), Route::State);
        assert_eq!(route(&Method::POST, "/api/fleet/stop"), Route::Fleet);
        assert_eq!(route(&Method::GET, "/api/metrics"), Route::Local);
        assert_eq!(route(&Method::PUT, "/api/road"), Route::Deploy(regions::federation::Kind::Road));
        assert_eq!(route(&Method::GET, "/api/road"), Route::Local);
    }

    #[test]
    fn scope_is_fleet_by_default_and_anything_else_is_refused() {
        assert_eq!(scope_is_region(None), Ok(false));
        assert_eq!(scope_is_region(Some("limit=5&scope=region")), Ok(true));
        assert_eq!(scope_is_region(Some("scope=fleet")), Ok(false));
        assert_eq!(scope_is_region(Some("scope=all")).unwrap_err().field.as_deref(), Some("scope"));
    }
}
