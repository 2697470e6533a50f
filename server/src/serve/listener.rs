//! The HTTP side's own accept loop (in place of `axum::serve`), so every resource a client can hold
//! is bounded: a request head (and the idle time of a kept-alive connection) must arrive within
//! [`Limits::header_timeout`]; request heads are capped in size; at most
//! [`Limits::max_connections`] HTTP connections are open, and when they are all taken a new one
//! closes the oldest connection that is idle or still sending its head (a slowloris socket), so an
//! operator's emergency stop always gets in. Upgraded WebSocket connections leave this table and are
//! counted and capped by [`super::ws`].

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::{Notify, watch};
use tower::ServiceExt as _;

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
}

struct Entry {
    busy: Arc<AtomicUsize>,
    evict: Arc<Notify>,
}

/// Open connections by age (the key is an increasing id).
#[derive(Default)]
struct Table(Mutex<BTreeMap<u64, Entry>>);

impl Table {
    /// Closes the oldest connection not serving a request (it leaves the table at once); false when
    /// all are busy.
    fn evict_one(&self) -> bool {
        let mut table = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        let oldest_idle = table.iter().find(|(_, e)| e.busy.load(Relaxed) == 0).map(|(id, _)| *id);
        match oldest_idle.and_then(|id| table.remove(&id)) {
            Some(entry) => {
                entry.evict.notify_one();
                true
            }
            None => false,
        }
    }

    fn len(&self) -> usize {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).len()
    }
}

/// Counts a request in flight on its connection while alive.
struct Busy(Arc<AtomicUsize>);

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Relaxed);
    }
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
    let table = Arc::new(Table::default());
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .max_buf_size(limits.max_head_bytes.max(8192))
        .max_header_size(limits.max_head_bytes)
        .max_headers(limits.max_header_lines);
    let builder = Arc::new(builder);
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
                if table.evict_one() {
                    counters.evicted.fetch_add(1, Relaxed);
                    counters.open.fetch_sub(1, Relaxed);
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        if table.len() >= limits.max_connections {
            if table.evict_one() {
                // Counted closed now (it left the table), not when its task gets round to it: `open`
                // never exceeds the cap.
                counters.evicted.fetch_add(1, Relaxed);
                counters.open.fetch_sub(1, Relaxed);
            } else {
                counters.refused.fetch_add(1, Relaxed);
                drop(stream);
                continue;
            }
        }
        let _ = stream.set_nodelay(true);
        next_id += 1;
        let id = next_id;
        let entry = Entry { busy: Arc::default(), evict: Arc::new(Notify::new()) };
        let (busy, evict) = (entry.busy.clone(), entry.evict.clone());
        table.0.lock().unwrap_or_else(PoisonError::into_inner).insert(id, entry);
        counters.accepted.fetch_add(1, Relaxed);
        counters.open.fetch_add(1, Relaxed);
        let service = hyper::service::service_fn({
            let router = router.clone();
            move |mut request: hyper::Request<Incoming>| {
                request.extensions_mut().insert(ConnectInfo(remote));
                busy.fetch_add(1, Relaxed);
                let guard = Busy(busy.clone());
                let call = router.clone().oneshot(request.map(axum::body::Body::new));
                async move {
                    let response = call.await;
                    drop(guard);
                    response
                }
            }
        });
        let connection = builder.serve_connection(TokioIo::new(stream), service).with_upgrades();
        let (table, counters, mut shutdown) = (table.clone(), counters.clone(), shutdown.clone());
        tokio::spawn(async move {
            tokio::pin!(connection);
            tokio::select! {
                _ = connection.as_mut() => {}
                () = evict.notified() => {}
                () = closing(&mut shutdown) => {
                    connection.as_mut().graceful_shutdown();
                    let _ = tokio::time::timeout(drain, connection).await;
                }
            }
            // An evicted connection was already taken out of the table and the count.
            if table.0.lock().unwrap_or_else(PoisonError::into_inner).remove(&id).is_some() {
                counters.open.fetch_sub(1, Relaxed);
            }
        });
    }
    let deadline = tokio::time::Instant::now() + drain;
    while table.len() > 0 && tokio::time::Instant::now() < deadline {
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
