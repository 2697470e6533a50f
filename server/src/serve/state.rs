//! What every request handler shares: the command queue into the fleet loop and the latest
//! published snapshot, road and metrics.

use super::command::{Command, Outcome, Request};
use super::engine::RoadView;
use super::error::ApiError;
use super::snapshot::Snapshot;
use super::stats::LoopMetrics;
use axum::extract::ws::Utf8Bytes;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize};
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};

/// How long a handler waits for the loop to apply its command before answering 503.
pub const COMMAND_TIMEOUT: Duration = Duration::from_secs(2);

/// A snapshot serialised once for every reader.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// Its tick.
    pub tick: u64,
    /// The `GET /api/state` document.
    pub text: Utf8Bytes,
}

/// Counters of the WebSocket stream.
#[derive(Debug, Default)]
pub struct StreamCounters {
    /// Connected clients.
    pub clients: AtomicUsize,
    /// Frames sent.
    pub frames_sent: AtomicU64,
    /// Frames a client without `rate` skipped because it was slower than the loop (a rate-limited
    /// client's skips are by request and not counted).
    pub frames_skipped: AtomicU64,
    /// Clients dropped because a send stalled.
    pub clients_dropped: AtomicU64,
}

/// Shared handler state (cheap to clone).
#[derive(Clone)]
pub struct AppState {
    /// Commands into the fleet loop.
    pub commands: mpsc::Sender<Request>,
    /// Land and stop requests, which the loop applies before any other command.
    pub urgent: mpsc::UnboundedSender<Request>,
    /// The latest snapshot.
    pub snapshots: watch::Receiver<Arc<Snapshot>>,
    /// The latest snapshot as JSON text (serialised once, sent to every client).
    pub frames: watch::Receiver<Frame>,
    /// The current road.
    pub road: watch::Receiver<Arc<RoadView>>,
    /// The latest loop statistics.
    pub metrics: watch::Receiver<Arc<LoopMetrics>>,
    /// The bearer token mutating requests need, if one is configured.
    pub token: Option<Arc<str>>,
    /// Names of the loaded policies.
    pub policies: Arc<[String]>,
    /// The policy of UAVs added without one.
    pub default_policy: Arc<str>,
    /// WebSocket counters.
    pub stream: Arc<StreamCounters>,
}

impl AppState {
    /// Sends a land or stop `command` ahead of every queued change and waits for its outcome.
    pub async fn apply_urgent(&self, command: Command) -> Result<Outcome, ApiError> {
        let (reply, answer) = oneshot::channel();
        self.urgent.send(Request { command, reply }).map_err(|_| ApiError::loop_unavailable())?;
        match tokio::time::timeout(COMMAND_TIMEOUT, answer).await {
            Ok(Ok(outcome)) => outcome.map_err(ApiError::from),
            _ => Err(ApiError::loop_unavailable()),
        }
    }

    /// Sends `command` to the fleet loop and waits (off the loop) for its outcome.
    pub async fn apply(&self, command: Command) -> Result<Outcome, ApiError> {
        let (reply, answer) = oneshot::channel();
        let sent = tokio::time::timeout(COMMAND_TIMEOUT, self.commands.send(Request { command, reply }));
        match sent.await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return Err(ApiError::loop_unavailable()),
            Err(_) => {
                return Err(ApiError::new(
                    axum::http::StatusCode::SERVICE_UNAVAILABLE,
                    "busy",
                    "too many changes queued; try again",
                ));
            }
        }
        match tokio::time::timeout(COMMAND_TIMEOUT, answer).await {
            Ok(Ok(outcome)) => outcome.map_err(ApiError::from),
            _ => Err(ApiError::loop_unavailable()),
        }
    }
}
