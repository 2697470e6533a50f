//! The audit log: every request that may change something is recorded with its time, method, route,
//! client address and outcome. A change the fleet applied is written in the same transaction as the
//! change itself (so an acknowledged change is always in the log); everything else (refusals of any
//! kind, land and stop) is queued for the state writer's next commit. `GET /api/audit` reads it.

use super::error::{ApiError, ErrorInfo};
use super::guard::is_change;
use super::state::AppState;
use axum::Json;
use axum::extract::{Query, Request, State};
use axum::http::StatusCode;
use axum::middleware::Next;
use axum::response::Response;
use engine::durable::{AuditQuery, ToWriter};
use engine::store::{AuditRecord, now_ms};
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};

/// A request another region forwarded (its owner applies and audits it here).
#[derive(Debug, Clone)]
pub struct Forwarded {
    /// The region the operator sent it to.
    pub region: String,
    /// The operator's address there.
    pub client: Option<String>,
}

/// The audit context of the request being handled.
#[derive(Debug)]
pub struct RequestAudit {
    /// Time, method, route and client; status and outcome are filled in when known.
    pub record: AuditRecord,
    /// The entry was committed with the change (the middleware writes none).
    pub committed: AtomicBool,
}

tokio::task_local! {
    static AUDIT: Arc<RequestAudit>;
}

/// The audit context of the current request, when it is a change.
pub fn current() -> Option<Arc<RequestAudit>> {
    AUDIT.try_with(Arc::clone).ok()
}

/// Records every change request (see the module documentation).
pub async fn record(State(app): State<AppState>, request: Request, next: Next) -> Response {
    if !is_change(request.method()) {
        return next.run(request).await;
    }
    let remote = match request.extensions().get::<Forwarded>() {
        Some(f) => f.remote(),
        None => super::listener::remote(&request).map_or_else(|| "unknown".to_string(), |a| a.to_string()),
    };
    let method = request.method().clone();
    let route = request.uri().path_and_query().map_or_else(String::new, |p| p.as_str().to_string());
    audited(&app, &method, route, remote, next.run(request)).await
}

impl Forwarded {
    /// The client as the audit log names it: the operator's address and the region it went through.
    pub fn remote(&self) -> String {
        format!("{} via region {}", self.client.as_deref().unwrap_or("unknown"), self.region)
    }
}

/// Handles a change `method route` from `remote` (`handled`) and records it (see the module
/// documentation); any other method is handled without a record.
pub async fn audited(
    app: &AppState,
    method: &axum::http::Method,
    route: String,
    remote: String,
    handled: impl Future<Output = Response>,
) -> Response {
    if !is_change(method) {
        return handled.await;
    }
    let context = Arc::new(RequestAudit {
        record: AuditRecord {
            time_ms: now_ms(),
            method: method.to_string(),
            route,
            remote,
            status: 0,
            outcome: String::new(),
            detail: String::new(),
        },
        committed: AtomicBool::new(false),
    });
    let response = AUDIT.scope(context.clone(), handled).await;
    if !context.committed.load(Relaxed) {
        let (outcome, detail) = match response.extensions().get::<ErrorInfo>() {
            Some(e) => (e.code.to_string(), e.message.clone()),
            None if response.status().is_success() => ("applied".to_string(), String::new()),
            None => ("http_error".to_string(), String::new()),
        };
        let mut record = context.record.clone();
        record.status = response.status().as_u16();
        record.outcome = outcome;
        if record.detail.is_empty() {
            record.detail = detail;
        }
        if app.engine.writer.try_send(ToWriter::Audit(record)).is_err() {
            app.engine.storage.audit_dropped.fetch_add(1, Relaxed);
        }
    }
    response
}

/// Query of `GET /api/audit`.
#[derive(Debug, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AuditParams {
    /// Entries newer than this sequence number, oldest first (with `before`: only those older than
    /// it too).
    #[schemars(range(min = i64::MIN, max = i64::MAX))]
    pub after: Option<i64>,
    /// Entries older than this sequence number, newest first (with `after`: the end of the window,
    /// oldest first).
    #[schemars(range(min = i64::MIN, max = i64::MAX))]
    pub before: Option<i64>,
    /// At most this many (default 100).
    #[schemars(range(min = 1, max = MAX_AUDIT_PAGE))]
    pub limit: Option<usize>,
}

/// Most entries one `GET /api/audit` answers.
pub const MAX_AUDIT_PAGE: usize = 1000;

/// `GET /api/audit[?after=SEQ][&before=SEQ][&limit=N]`: newest first unless `after` is given (both:
/// the entries between them, oldest first).
pub async fn list(
    State(app): State<AppState>,
    query: Result<Query<AuditParams>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<super::answers::AuditLog>, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::invalid("query", e.body_text()))?;
    let limit = q.limit.unwrap_or(100);
    if !(1..=MAX_AUDIT_PAGE).contains(&limit) {
        return Err(ApiError::invalid("limit", format!("must be between 1 and {MAX_AUDIT_PAGE}")));
    }
    let (reply, answer) = tokio::sync::oneshot::channel();
    let query = AuditQuery { after: q.after, before: q.before, limit, reply };
    app.engine
        .writer
        .try_send(ToWriter::Query(query))
        .map_err(|_| ApiError::busy("the audit log is busy; try again"))?;
    let unavailable = |why: &str| {
        let message = format!("the audit log cannot be read: {why}");
        ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "storage_unavailable", message)
    };
    let entries = match tokio::time::timeout(std::time::Duration::from_secs(10), answer).await {
        Ok(Ok(Ok(entries))) => entries,
        Ok(Ok(Err(e))) => return Err(unavailable(&e)),
        Ok(Err(_)) => return Err(unavailable("the state writer stopped")),
        Err(_) => return Err(unavailable("no answer within 10 s")),
    };
    Ok(Json(super::answers::AuditLog { entries }))
}
