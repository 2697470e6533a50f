//! `GET /ws[?rate=HZ][&format=json|bin][&bbox=x0,y0,x1,y1]`: every snapshot as JSON text (the
//! `GET /api/state` document) or, with `format=bin`, in the binary format of [`super::binary`] (a
//! roster frame first and whenever it changes, then tick frames, only the UAVs inside `bbox` if
//! given), at most `rate` frames per second. Each client reads the latest frame from a `watch`
//! channel at its own pace: a slow client skips frames, a stalled one is dropped after
//! [`SEND_TIMEOUT`]; neither touches the fleet loop or other clients.

use super::binary::{Bbox, BinaryFrame, filter_bbox, parse_bbox};
use super::error::ApiError;
use super::state::{AppState, StreamCounters};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// A client whose socket does not take a frame within this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(2);

/// Most simultaneous WebSocket clients by default (fitted under the open-file limit at start).
pub const MAX_CLIENTS: usize = 1024;

/// Largest message or frame a client may send (the stream is one-way; clients send only control
/// frames).
pub const MAX_CLIENT_MESSAGE_BYTES: usize = 4 << 10;

/// The client cap under an open-file limit (half of what is left after the runtime's own files).
pub fn fitted_max_clients(open_files: Option<u64>) -> usize {
    open_files.map_or(MAX_CLIENTS, |files| {
        MAX_CLIENTS.min(usize::try_from(files.saturating_sub(64) / 2).unwrap_or(usize::MAX)).max(4)
    })
}

/// The pause between two frames for a rate of `rate` frames per second: 0 < rate ≤ 1000, any finite
/// positive value (a vanishing rate gets the longest pause a `Duration` holds, never a panic).
pub fn frame_interval(rate: Option<f64>) -> Result<Duration, ApiError> {
    match rate {
        None => Ok(Duration::ZERO),
        Some(r) if r.is_finite() && r > 0.0 && r <= 1000.0 => {
            Ok(Duration::try_from_secs_f64(1.0 / r).unwrap_or(Duration::MAX))
        }
        Some(_) => Err(ApiError::invalid("rate", "must be a number of frames per second in (0, 1000]")),
    }
}

/// Query of `GET /ws`.
#[derive(Debug, Deserialize)]
pub struct StreamQuery {
    /// Frames per second, 0 < rate ≤ 1000 (default: every snapshot).
    pub rate: Option<f64>,
    /// `json` (default) or `bin`.
    pub format: Option<String>,
    /// Viewport `x0,y0,x1,y1` (m) of a `bin` stream: only the UAVs inside it are sent.
    pub bbox: Option<String>,
}

/// What a client receives.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Json,
    Binary(Option<Bbox>),
}

fn format_of(query: &StreamQuery) -> Result<Format, ApiError> {
    let bbox = query.bbox.as_deref().map(parse_bbox).transpose().map_err(|e| ApiError::invalid("bbox", e))?;
    match (query.format.as_deref(), bbox) {
        (None | Some("json"), None) => Ok(Format::Json),
        (None | Some("json"), Some(_)) => Err(ApiError::invalid("bbox", "needs format=bin")),
        (Some("bin"), bbox) => Ok(Format::Binary(bbox)),
        (Some(_), _) => Err(ApiError::invalid("format", "must be json or bin")),
    }
}

/// Upgrades to a WebSocket that streams snapshots.
pub async fn handler(
    State(app): State<AppState>,
    query: Result<Query<StreamQuery>, axum::extract::rejection::QueryRejection>,
    upgrade: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    let Query(query) = query.map_err(|e| ApiError::invalid("rate", e.body_text()))?;
    let min_interval = frame_interval(query.rate)?;
    let format = format_of(&query)?;
    let Some(place) = Held::place(&app.stream, app.max_stream_clients) else {
        app.stream.clients_refused.fetch_add(1, Relaxed);
        return Err(ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "too_many_clients",
            format!("at most {} stream clients", app.max_stream_clients),
        ));
    };
    let upgrade = upgrade.max_message_size(MAX_CLIENT_MESSAGE_BYTES).max_frame_size(MAX_CLIENT_MESSAGE_BYTES);
    Ok(upgrade.on_upgrade(move |socket| async move {
        let sending = stream(app, socket, min_interval, format, place);
        match streams() {
            Some(runtime) => drop(runtime.spawn(sending)),
            None => sending.await,
        }
    }))
}

/// Sends `message`, giving up after [`SEND_TIMEOUT`]: Err(true) when the client stalled.
async fn send(socket: &mut WebSocket, message: Message) -> Result<(), bool> {
    match tokio::time::timeout(SEND_TIMEOUT, socket.send(message)).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(_)) => Err(false),
        Err(_) => Err(true),
    }
}

/// Sends the roster and reservations frames of `b` whose versions the client has not `seen`, then
/// its tick frame (only the records inside `bbox`, if given), then (with `--region`) the other
/// regions' newest state messages it has not seen (`region::elsewhere`; never cut by `bbox`).
async fn send_binary(
    socket: &mut WebSocket,
    b: BinaryFrame,
    bbox: Option<Bbox>,
    seen: &mut Seen,
    elsewhere: Option<&regions::elsewhere::Elsewhere>,
) -> Result<(), bool> {
    if b.roster_version != seen.0 {
        send(socket, Message::Binary(b.roster)).await?;
        seen.0 = b.roster_version;
    }
    if b.reservations_version != seen.1 {
        send(socket, Message::Binary(b.reservations)).await?;
        seen.1 = b.reservations_version;
    }
    let body = match bbox {
        None => b.body,
        Some(bbox) => filter_bbox(&b.body, bbox).into(),
    };
    send(socket, Message::Binary(body)).await?;
    let others = elsewhere.map(|e| e.unseen(&mut seen.2, Instant::now())).unwrap_or_default();
    for payload in others {
        send(socket, Message::Binary(payload)).await?;
    }
    Ok(())
}

/// What a binary client has: the roster and reservations versions, and each other region's
/// message number.
type Seen = (u32, u32, std::collections::HashMap<String, u64>);

/// One count held in [`StreamCounters`] while a client streams, given back when dropped (when the
/// stream ends, panics, or the upgrade never completes).
struct Held {
    counters: Arc<StreamCounters>,
    count: fn(&StreamCounters) -> &AtomicUsize,
}

impl Held {
    /// A client's place among [`AppState::max_stream_clients`], taken at the handshake: checked and
    /// counted in one step, so concurrent handshakes cannot exceed the cap.
    fn place(counters: &Arc<StreamCounters>, max: usize) -> Option<Held> {
        let counted = counters.clients.fetch_update(Relaxed, Relaxed, |n| (n < max).then_some(n + 1));
        counted.ok().map(|_| Held { counters: counters.clone(), count: |c| &c.clients })
    }

    /// A JSON client, counted while it streams (the serialiser makes each frame's JSON meanwhile).
    fn json_reader(counters: &Arc<StreamCounters>) -> Held {
        counters.json_clients.fetch_add(1, Relaxed);
        Held { counters: counters.clone(), count: |c| &c.json_clients }
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        (self.count)(&self.counters).fetch_sub(1, Relaxed);
    }
}

/// Nice value of the stream runtime's threads.
pub const STREAM_NICE: i32 = 5;

/// The runtime that sends the stream (one per process, built at the first client, never dropped):
/// its threads run at nice [`STREAM_NICE`], so that a request waits for no stream send (50 clients
/// take 400 MB/s at 10,000 UAVs) and the fleet loop is not slowed by them either. The sockets stay
/// registered with the server's runtime, which wakes these tasks. `None` if it could not be built
/// (no threads left): then the server's runtime sends the stream.
fn streams() -> Option<&'static tokio::runtime::Handle> {
    static STREAMS: std::sync::OnceLock<Option<tokio::runtime::Runtime>> = std::sync::OnceLock::new();
    STREAMS
        .get_or_init(|| {
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .thread_name("stream")
                .on_thread_start(|| {
                    let this = rustix::thread::gettid();
                    if let Err(e) = rustix::process::setpriority_process(Some(this), STREAM_NICE) {
                        tracing::debug!("the stream thread keeps its priority: {e}");
                    }
                })
                .enable_all()
                .build();
            runtime.inspect_err(|e| tracing::warn!("the stream runs on the server's runtime: {e}")).ok()
        })
        .as_ref()
        .map(|runtime| runtime.handle())
}

async fn stream(app: AppState, mut socket: WebSocket, min_interval: Duration, format: Format, place: Held) {
    let counters = app.stream.clone();
    let json_reader = matches!(format, Format::Json).then(|| Held::json_reader(&counters));
    let mut frames = app.frames.clone();
    frames.mark_changed();
    let mut last_sent: Option<Instant> = None;
    let mut last_tick = 0u64;
    // The roster and reservations versions this client has, and the other regions' messages.
    let mut seen: Seen = (0, 0, Default::default());
    let elsewhere = app.region.as_ref().map(|r| r.elsewhere.clone());
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
                if last_tick > 0 && frame.tick() > last_tick + 1 && min_interval.is_zero() {
                    counters.frames_skipped.fetch_add(frame.tick() - last_tick - 1, Relaxed);
                }
                last_tick = frame.tick();
                let sent = match format {
                    Format::Json => send(&mut socket, Message::Text(frame.json())).await,
                    Format::Binary(bbox) => {
                        send_binary(&mut socket, frame.binary, bbox, &mut seen, elsewhere.as_deref()).await
                    },
                };
                match sent {
                    Ok(()) => {
                        counters.frames_sent.fetch_add(1, Relaxed);
                        last_sent = Some(Instant::now());
                    }
                    Err(false) => break,
                    Err(true) => {
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
    drop((json_reader, place));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_rate_in_range_gives_an_interval_and_others_an_error() {
        assert_eq!(frame_interval(None).unwrap(), Duration::ZERO);
        assert_eq!(frame_interval(Some(10.0)).unwrap(), Duration::from_millis(100));
        assert_eq!(frame_interval(Some(1e-300)).unwrap(), Duration::MAX);
        assert!(frame_interval(Some(f64::MIN_POSITIVE)).is_ok());
        for bad in [0.0, -1.0, 1000.5, f64::NAN, f64::INFINITY, -0.0] {
            assert!(frame_interval(Some(bad)).is_err(), "{bad}");
        }
    }
}
