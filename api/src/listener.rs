//! The HTTP side's own accept loop (in place of `axum::serve`), so every resource a client can hold
//! is bounded: a request head (and the idle time of a kept-alive connection) must arrive within
//! [`Limits::header_timeout`]; request heads are capped in size; at most
//! [`Limits::max_connections`] HTTP connections are open. Upgraded WebSocket connections leave this
//! table and are counted and capped by [`super::ws`].
//!
//! When every connection is taken, a new one makes room, so the operator's emergency stop always
//! gets in, even past clients that hold the token and send their bodies slowly:
//! 1. it closes the oldest connection that is idle or still sending its head (a slowloris socket);
//! 2. else the oldest one whose request has been receiving its body for more than [`SLOW_BODY`]
//!    (the body is wrapped to know when it ended: `table::Watched`); such an upload is cut only
//!    when the table is full, and its client sees the connection close;
//! 3. else (every connection serves a request that is not slow, e.g. slow bodies younger than
//!    [`SLOW_BODY`]) it goes to a reserve of [`RESERVE_CONNECTIONS`] beyond the cap, which serves
//!    one request each, only on the stop and land routes (others get `503 busy`, see
//!    [`super::guard`]), with a head timeout of [`RESERVE_HEAD_TIMEOUT`]; a full reserve makes room
//!    the same way (1, 2) among its own, else the new connection is closed.

mod table;

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::time::Duration;
use table::{Conn, Evicted, Table};
use tokio::net::TcpListener;
use tokio::sync::watch;
use tower::ServiceExt as _;

/// A request receiving its body for longer than this may have its connection closed when every
/// connection is taken.
pub const SLOW_BODY: Duration = Duration::from_secs(1);
/// Connections beyond the cap that serve only the emergency stop and land routes (one request
/// each) when every ordinary one is busy.
pub const RESERVE_CONNECTIONS: usize = 8;
/// A reserve connection's request head must arrive within this.
pub const RESERVE_HEAD_TIMEOUT: Duration = Duration::from_secs(1);

/// Marks a request that came on a reserve connection: only the stop and land routes serve it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reserved;

/// Bounds on what clients can hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Open HTTP connections (WebSocket clients are capped apart).
    pub max_connections: usize,
    /// A request head, and the idle time between two requests of a connection, must arrive within this.
    pub header_timeout: Duration,
    /// Largest request head the HTTP library reads (bytes); the API answers 414/431 well below it.
    pub max_head_bytes: usize,
    /// Most header lines the HTTP library parses; the API answers 431 well below it.
    pub max_header_lines: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_connections: 256,
            header_timeout: Duration::from_secs(10),
            max_head_bytes: 256 << 10,
            max_header_lines: 512,
        }
    }
}

impl Limits {
    /// The defaults, with the connection caps fitted under the process's open-file limit.
    pub fn fitted(open_files: Option<u64>) -> Self {
        let mut limits = Self::default();
        if let Some(files) = open_files {
            // Room for the runtime, the database, links and simulators; a quarter for HTTP.
            let usable = usize::try_from(files.saturating_sub(64)).unwrap_or(usize::MAX);
            limits.max_connections = limits.max_connections.min(usable / 4).max(8);
        }
        limits
    }
}

/// Counters of the connection table (`connections` in `/api/metrics`).
#[derive(Debug, Default)]
pub struct ConnectionCounters {
    /// Open HTTP connections.
    pub open: AtomicUsize,
    /// Connections accepted since the start.
    pub accepted: AtomicU64,
    /// Idle or slow connections closed to make room for a new one.
    pub evicted: AtomicU64,
    /// Connections refused because every open one was busy.
    pub refused: AtomicU64,
    /// `accept` failures (e.g. out of file descriptors).
    pub accept_errors: AtomicU64,
    /// The cap on open connections.
    pub limit: AtomicUsize,
    /// Of the evicted, those closed while their request had been receiving its body for longer
    /// than [`SLOW_BODY`].
    pub evicted_slow_bodies: AtomicU64,
    /// Open reserve connections (beyond `limit`, for the stop and land routes only).
    pub reserve_open: AtomicUsize,
    /// Connections admitted to the reserve since the start.
    pub reserve_accepted: AtomicU64,
}

/// `connections` of `GET /api/metrics`: [`ConnectionCounters`] read once.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, schemars::JsonSchema)]
pub struct ConnectionsReport {
    /// Open connections (the reserve's included).
    pub open: usize,
    /// Most connections at once (beyond: the reserve, for the stop and land routes).
    pub limit: usize,
    /// Connections accepted since the start.
    pub accepted: u64,
    /// Idle or slow connections closed to make room.
    pub evicted: u64,
    /// Connections refused (no room, no idle one to close).
    pub refused: u64,
    /// Errors of `accept` (e.g. out of file descriptors).
    pub accept_errors: u64,
    /// Of the evicted, those closed while receiving a body for too long.
    pub evicted_slow_bodies: u64,
    /// Open reserve connections.
    pub reserve_open: usize,
    /// Most reserve connections.
    pub reserve_limit: usize,
    /// Connections admitted to the reserve since the start.
    pub reserve_accepted: u64,
}

impl ConnectionCounters {
    /// The `connections` object of `/api/metrics`.
    pub fn report(&self) -> ConnectionsReport {
        ConnectionsReport {
            open: self.open.load(Relaxed),
            limit: self.limit.load(Relaxed),
            accepted: self.accepted.load(Relaxed),
            evicted: self.evicted.load(Relaxed),
            refused: self.refused.load(Relaxed),
            accept_errors: self.accept_errors.load(Relaxed),
            evicted_slow_bodies: self.evicted_slow_bodies.load(Relaxed),
            reserve_open: self.reserve_open.load(Relaxed),
            reserve_limit: RESERVE_CONNECTIONS,
            reserve_accepted: self.reserve_accepted.load(Relaxed),
        }
    }

    /// Counts a connection closed to make room (`reserve`: one of the reserve's).
    fn count_eviction(&self, why: Evicted, reserve: bool) {
        self.evicted.fetch_add(1, Relaxed);
        if why == Evicted::SlowBody {
            self.evicted_slow_bodies.fetch_add(1, Relaxed);
        }
        // Counted closed now (it left the table), not when its task gets round to it: `open`
        // never exceeds the cap.
        if reserve {
            self.reserve_open.fetch_sub(1, Relaxed);
        } else {
            self.open.fetch_sub(1, Relaxed);
        }
    }
}

/// Which table a new connection goes to.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Place {
    Main,
    Reserve,
}

/// Where a new connection goes (making room as the module documentation says); None: closed.
fn make_room(main: &Table, reserve: &Table, limit: usize, counters: &ConnectionCounters) -> Option<Place> {
    if main.len() < limit {
        return Some(Place::Main);
    }
    if let Some(why) = main.evict_one() {
        counters.count_eviction(why, false);
        return Some(Place::Main);
    }
    if reserve.len() < RESERVE_CONNECTIONS {
        return Some(Place::Reserve);
    }
    if let Some(why) = reserve.evict_one() {
        counters.count_eviction(why, true);
        return Some(Place::Reserve);
    }
    None
}

/// Serves `router` on `listener` until `shutdown` turns true, then lets open requests finish (at
/// most `drain` long) and returns.
pub async fn run(
    listener: TcpListener,
    router: Router,
    limits: Limits,
    counters: Arc<ConnectionCounters>,
    mut shutdown: watch::Receiver<bool>,
    drain: Duration,
) {
    counters.limit.store(limits.max_connections, Relaxed);
    let main = Arc::new(Table::new(SLOW_BODY));
    let reserve = Arc::new(Table::new(SLOW_BODY));
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .max_buf_size(limits.max_head_bytes.max(8192))
        .max_header_size(limits.max_head_bytes)
        .max_headers(limits.max_header_lines);
    // The reserve: a short head timeout and one request per connection.
    let mut reserved = builder.clone();
    reserved.header_read_timeout(limits.header_timeout.min(RESERVE_HEAD_TIMEOUT)).keep_alive(false);
    let (builder, reserved) = (Arc::new(builder), Arc::new(reserved));
    let mut next_id = 0u64;
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            () = closing(&mut shutdown) => break,
        };
        let (stream, remote) = match accepted {
            Ok(pair) => pair,
            Err(e) => {
                // Out of file descriptors: make room by closing an idle connection, then retry.
                counters.accept_errors.fetch_add(1, Relaxed);
                tracing::warn!("accept failed: {e}");
                if let Some(why) = main.evict_one() {
                    counters.count_eviction(why, false);
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        let Some(place) = make_room(&main, &reserve, limits.max_connections, &counters) else {
            counters.refused.fetch_add(1, Relaxed);
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        next_id += 1;
        let id = next_id;
        let conn = Arc::new(Conn::default());
        let (table, builder) = match place {
            Place::Main => {
                counters.open.fetch_add(1, Relaxed);
                (main.clone(), builder.clone())
            }
            Place::Reserve => {
                counters.reserve_open.fetch_add(1, Relaxed);
                counters.reserve_accepted.fetch_add(1, Relaxed);
                (reserve.clone(), reserved.clone())
            }
        };
        table.insert(id, conn.clone());
        counters.accepted.fetch_add(1, Relaxed);
        let service = hyper::service::service_fn({
            let (router, table, conn) = (router.clone(), table.clone(), conn.clone());
            move |request: hyper::Request<Incoming>| {
                let (parts, body) = request.into_parts();
                let (busy, body) = table.begin(&conn, body);
                let mut request = hyper::Request::from_parts(parts, axum::body::Body::new(body));
                request.extensions_mut().insert(ConnectInfo(remote));
                if place == Place::Reserve {
                    request.extensions_mut().insert(Reserved);
                }
                let call = router.clone().oneshot(request);
                async move {
                    let response = call.await;
                    drop(busy);
                    response
                }
            }
        });
        let connection = builder.serve_connection(TokioIo::new(stream), service).with_upgrades();
        let (counters, mut shutdown) = (counters.clone(), shutdown.clone());
        tokio::spawn(async move {
            tokio::pin!(connection);
            tokio::select! {
                _ = connection.as_mut() => {}
                () = conn.evict.notified() => {}
                () = closing(&mut shutdown) => {
                    connection.as_mut().graceful_shutdown();
                    let _ = tokio::time::timeout(drain, connection).await;
                }
            }
            // An evicted connection was already taken out of the table and the count.
            if table.remove(id) {
                match place {
                    Place::Main => counters.open.fetch_sub(1, Relaxed),
                    Place::Reserve => counters.reserve_open.fetch_sub(1, Relaxed),
                };
            }
        });
    }
    let deadline = tokio::time::Instant::now() + drain;
    while main.len() + reserve.len() > 0 && tokio::time::Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Completes when the shutdown flag turns true (or its sender is gone).
async fn closing(shutdown: &mut watch::Receiver<bool>) {
    let _ = shutdown.wait_for(|stop| *stop).await;
}

/// The soft limit on open files of this process (Linux), after raising it to the hard limit.
pub fn raise_open_files_limit() -> Option<u64> {
    use rustix::process::{Resource, getrlimit, setrlimit};
    let mut limit = getrlimit(Resource::Nofile);
    if let (Some(current), Some(hard)) = (limit.current, limit.maximum)
        && current < hard
    {
        limit.current = Some(hard.min(1 << 20));
        if setrlimit(Resource::Nofile, limit).is_err() {
            limit.current = Some(current);
        }
    }
    limit.current
}

/// The remote address a request came from (inserted by [`run`]), if any.
pub fn remote(request: &axum::extract::Request) -> Option<SocketAddr> {
    request.extensions().get::<ConnectInfo<SocketAddr>>().map(|c| c.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connection_caps_fit_under_the_open_file_limit() {
        assert_eq!(Limits::fitted(None).max_connections, 256);
        assert_eq!(Limits::fitted(Some(1 << 20)).max_connections, 256);
        assert_eq!(Limits::fitted(Some(256)).max_connections, 48);
        assert_eq!(Limits::fitted(Some(16)).max_connections, 8);
    }
}
