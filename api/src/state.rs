//! What every request handler shares: the command queue into the fleet loop, the latest published
//! snapshot, road and metrics, the state writer's queue, and the counters of bounded resources.

use super::auth::AuthFailures;
use super::error::ApiError;
use super::guard::{AccessRules, BODY_BUDGET_BYTES};
use super::listener::ConnectionCounters;
use axum::extract::ws::Utf8Bytes;
use engine::EngineHandle;
use engine::command::{Command, Outcome};
use engine::snapshot::Snapshot;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use tokio::sync::{Semaphore, watch};

/// A snapshot serialised once for every reader: in the binary format always, as JSON once a reader
/// asks for it (at 10,000 UAVs the JSON is 5.6 MB and costs the serialiser far more than the binary
/// frame; binary clients alone never pay for it).
#[derive(Debug, Clone)]
pub struct Frame {
    /// The snapshot itself.
    pub snapshot: Arc<Snapshot>,
    /// Its JSON text, made by the first reader that needs it and shared by every clone.
    json: Arc<OnceLock<Utf8Bytes>>,
    /// The same snapshot in the binary stream's format (`/ws?format=bin`).
    pub binary: super::binary::BinaryFrame,
}

impl Frame {
    /// The frame of `snapshot`, its binary encoding given and its JSON not made yet.
    pub fn new(snapshot: Arc<Snapshot>, binary: super::binary::BinaryFrame) -> Self {
        Frame { snapshot, json: Arc::default(), binary }
    }

    /// Its tick.
    pub fn tick(&self) -> u64 {
        self.snapshot.tick
    }

    /// The `GET /api/state` document (and the `/ws` JSON message), serialised on first use.
    pub fn json(&self) -> Utf8Bytes {
        self.json.get_or_init(|| json_of(&self.snapshot)).clone()
    }
}

/// The JSON text of `snapshot` (`GET /api/state`).
pub fn json_of(snapshot: &Snapshot) -> Utf8Bytes {
    match serde_json::to_string(snapshot) {
        Ok(text) => Utf8Bytes::from(text),
        Err(e) => {
            tracing::error!("snapshot not serialised: {e}");
            Utf8Bytes::from_static("{\"error\":\"snapshot not serialised\"}")
        }
    }
}

/// Counters of the WebSocket stream.
#[derive(Debug, Default)]
pub struct StreamCounters {
    /// Connected clients.
    pub clients: AtomicUsize,
    /// Connected clients of the JSON stream (while there are any, the serialiser makes each
    /// frame's JSON before publishing it, once for all of them).
    pub json_clients: AtomicUsize,
    /// Frames sent.
    pub frames_sent: AtomicU64,
    /// Frames a client without `rate` skipped because it was slower than the loop (a rate-limited
    /// client's skips are by request and not counted).
    pub frames_skipped: AtomicU64,
    /// Clients dropped because a send stalled.
    pub clients_dropped: AtomicU64,
    /// Clients refused because [`AppState::max_stream_clients`] were connected.
    pub clients_refused: AtomicU64,
}

/// Shared handler state (cheap to clone).
#[derive(Clone)]
pub struct AppState {
    /// The fleet loop: changes in; snapshots, road and metrics out; the state writer's queue.
    pub engine: EngineHandle,
    /// The latest snapshot serialised (binary always, JSON once asked), sent to every client.
    pub frames: watch::Receiver<Frame>,
    /// The bearer token mutating requests need, if one is configured.
    pub token: Option<Arc<str>>,
    /// Failed authentication attempts per client.
    pub auth_failures: Arc<AuthFailures>,
    /// Requests waiting on other regions at once (`--region`; `federate::MAX_FORWARDED`).
    pub forwarding: Arc<tokio::sync::Semaphore>,
    /// Accepted `Host` and `Origin` values (set when the server starts listening).
    pub access: Arc<OnceLock<AccessRules>>,
    /// Names of the loaded policies.
    pub policies: Arc<[String]>,
    /// The policy of UAVs added without one.
    pub default_policy: Arc<str>,
    /// Most UAVs the fleet may have.
    pub max_uavs: usize,
    /// Which Crazyflie links may be given (remote UDP hosts: `--allow-link-host`).
    pub link_rules: Arc<links::LinkRules>,
    /// Most WebSocket clients at once.
    pub max_stream_clients: usize,
    /// WebSocket counters.
    pub stream: Arc<StreamCounters>,
    /// HTTP connection counters.
    pub connections: Arc<ConnectionCounters>,
    /// Request bodies in flight (permits of 1 KiB).
    pub body_budget: Arc<Semaphore>,
    /// Validations of large inputs (roads, scenarios) run one at a time, off the async workers.
    pub validation: Arc<Semaphore>,
    /// The region this server flies and its neighbours' UAVs (`--region`; None without).
    pub region: Option<regions::RegionShared>,
    /// Motion-capture counters (all zero without `--mocap`).
    pub mocap: Arc<engine::mocap::MocapCounters>,
    /// What the Rerun sink has done.
    pub rerun: Arc<rerun_sink::RerunCounters>,
    /// The UAVs that keep their own Rerun entities in a batched fleet (`/api/rerun/selection`).
    pub rerun_selection: Arc<watch::Sender<Arc<[String]>>>,
}

/// Permits of the body budget.
pub fn body_budget() -> Arc<Semaphore> {
    Arc::new(Semaphore::new(BODY_BUDGET_BYTES / 1024))
}

impl AppState {
    /// What a Rerun sink reads from this server (`rerun_sink::start`).
    pub fn rerun_inputs(&self) -> rerun_sink::Inputs {
        rerun_sink::Inputs {
            snapshots: self.engine.snapshots.clone(),
            road: self.engine.road.clone(),
            metrics: self.engine.metrics.clone(),
            selection: self.rerun_selection.subscribe(),
            counters: self.rerun.clone(),
        }
    }

    /// Sends a land or stop `command` ahead of every queued change, wakes the loop, and waits for
    /// its outcome (land and stop are never persisted, so they never wait on the disk).
    pub async fn apply_urgent(&self, command: Command) -> Result<Outcome, ApiError> {
        Ok(self.engine.apply_urgent(command).await?)
    }

    /// Sends `command` to the fleet loop with the request's audit entry and waits (off the loop)
    /// until it is applied and on disk ([`EngineHandle::apply`]); an applied change marks the
    /// request's audit entry as committed with it.
    pub async fn apply(&self, command: Command) -> Result<Outcome, ApiError> {
        let context = super::audit::current();
        let audit = context.as_ref().map(|c| c.record.clone());
        let outcome = self.engine.apply(command, audit).await?;
        if let Some(context) = context {
            context.committed.store(true, Relaxed);
        }
        Ok(outcome)
    }

    /// Runs `work` (a validation of a large input) on the blocking pool, one at a time: waits at
    /// most 5 s for its turn (then 503), so no request holds an async worker or starves the loop.
    pub async fn validate<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        let permit = tokio::time::timeout(Duration::from_secs(5), self.validation.clone().acquire_owned())
            .await
            .map_err(|_| ApiError::busy("another large input is being validated; try again"))?
            .map_err(|_| ApiError::loop_unavailable())?;
        let result = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            work()
        })
        .await;
        result.unwrap_or_else(|_| {
            Err(ApiError::new(
                axum::http::StatusCode::INTERNAL_SERVER_ERROR,
                "internal_error",
                "validation failed",
            ))
        })
    }
}
