//! `GET /ws[?rate=HZ]`: every snapshot as JSON text (the `GET /api/state` document), at most `rate`
//! frames per second. Each client reads the latest frame from a `watch` channel at its own pace: a
//! slow client skips frames, a stalled one is dropped after [`SEND_TIMEOUT`]; neither touches the
//! fleet loop or other clients.

use super::error::ApiError;
use super::state::AppState;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::response::Response;
use serde::Deserialize;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

/// A client whose socket does not take a frame within this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(2);

/// Most simultaneous WebSocket clients.
pub const MAX_CLIENTS: usize = 4096;

/// Query of `GET /ws`.
#[derive(Debug, Deserialize)]
pub struct StreamQuery {
    /// Frames per second, 0 < rate ≤ 1000 (default: every snapshot).
    pub rate: Option<f64>,
}

/// Upgrades to a WebSocket that streams snapshots.
pub async fn handler(
    State(app): State<AppState>,
    query: Result<Query<StreamQuery>, axum::extract::rejection::QueryRejection>,
    upgrade: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    let Query(query) = query.map_err(|e| ApiError::invalid("rate", e.body_text()))?;
    let min_interval = match query.rate {
        None => Duration::ZERO,
        Some(r) if r.is_finite() && r > 0.0 && r <= 1000.0 => Duration::from_secs_f64(1.0 / r),
        Some(_) => {
            return Err(ApiError::invalid("rate", "must be a number of frames per second in (0, 1000]"));
        }
    };
    if app.stream.clients.load(Relaxed) >= MAX_CLIENTS {
        return Err(ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "too_many_clients",
            format!("at most {MAX_CLIENTS} stream clients"),
        ));
    }
    Ok(upgrade.on_upgrade(move |socket| stream(app, socket, min_interval)))
}

async fn stream(app: AppState, mut socket: WebSocket, min_interval: Duration) {
    let counters = app.stream.clone();
    counters.clients.fetch_add(1, Relaxed);
    let mut frames = app.frames.clone();
    frames.mark_changed();
    let mut last_sent: Option<Instant> = None;
    let mut last_tick = 0u64;
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                if last_sent.is_some_and(|t| t.elapsed() < min_interval) {
                    continue;
                }
                let frame = frames.borrow_and_update().clone();
                if frame.text.as_str().is_empty() {
                    continue;
                }
                if last_tick > 0 && frame.tick > last_tick + 1 && min_interval.is_zero() {
                    counters.frames_skipped.fetch_add(frame.tick - last_tick - 1, Relaxed);
                }
                last_tick = frame.tick;
                match tokio::time::timeout(SEND_TIMEOUT, socket.send(Message::Text(frame.text))).await {
                    Ok(Ok(())) => {
                        counters.frames_sent.fetch_add(1, Relaxed);
                        last_sent = Some(Instant::now());
                    }
                    Ok(Err(_)) => break,
                    Err(_) => {
                        counters.clients_dropped.fetch_add(1, Relaxed);
                        break;
                    }
                }
            }
            incoming = socket.recv() => match incoming {
                // Clients have nothing to say; pings are answered by the library.
                Some(Ok(Message::Close(_))) | Some(Err(_)) | None => break,
                Some(Ok(_)) => {}
            },
        }
    }
    counters.clients.fetch_sub(1, Relaxed);
}
