//! The accept loop's table of open connections: what each one is doing (idle or sending its head,
//! serving a request, receiving a request body and since when) and which one to close when room is
//! needed.

use hyper::body::{Body, Bytes, Frame, Incoming, SizeHint};
use std::collections::BTreeMap;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::sync::Notify;

/// What the accept loop knows about one open connection.
#[derive(Debug, Default)]
pub struct Conn {
    /// Requests in flight (0: idle, or still sending its request head).
    busy: AtomicUsize,
    /// When the request in flight began waiting for its body (ms since the table's start, plus 1);
    /// 0 while no body is awaited.
    body_since: AtomicU64,
    /// Notified when the connection is to be closed to make room.
    pub evict: Notify,
}

/// Why a connection was closed to make room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Evicted {
    /// It was idle or still sending its request head.
    Idle,
    /// Its request had been receiving its body for longer than the slow-body bound.
    SlowBody,
}

/// Open connections by age (the key is an increasing id).
#[derive(Debug)]
pub struct Table {
    start: Instant,
    slow_body: Duration,
    conns: Mutex<BTreeMap<u64, Arc<Conn>>>,
}

impl Table {
    /// An empty table whose requests count as slow once their body took longer than `slow_body`.
    pub fn new(slow_body: Duration) -> Self {
        Self { start: Instant::now(), slow_body, conns: Mutex::default() }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<Conn>>> {
        self.conns.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn now_ms(&self) -> u64 {
        u64::try_from(self.start.elapsed().as_millis()).unwrap_or(u64::MAX - 1) + 1
    }

    /// Adds connection `id`.
    pub fn insert(&self, id: u64, conn: Arc<Conn>) {
        self.lock().insert(id, conn);
    }

    /// Takes connection `id` out; false when it was not there (already evicted).
    pub fn remove(&self, id: u64) -> bool {
        self.lock().remove(&id).is_some()
    }

    /// Open connections.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Closes the oldest connection that is idle or sending its head, else the oldest one whose
    /// request has been receiving its body for longer than the bound (it leaves the table at once);
    /// None when every connection is serving a request that is not slow.
    pub fn evict_one(&self) -> Option<Evicted> {
        let now = self.now_ms();
        let slow = u64::try_from(self.slow_body.as_millis()).unwrap_or(u64::MAX);
        let mut conns = self.lock();
        let idle = conns.iter().find(|(_, c)| c.busy.load(Relaxed) == 0).map(|(id, _)| (*id, Evicted::Idle));
        let victim = idle.or_else(|| {
            conns
                .iter()
                .find(|(_, c)| {
                    let since = c.body_since.load(Relaxed);
                    since != 0 && now.saturating_sub(since) > slow
                })
                .map(|(id, _)| (*id, Evicted::SlowBody))
        });
        let (id, why) = victim?;
        let conn = conns.remove(&id)?;
        conn.evict.notify_one();
        Some(why)
    }

    /// Marks a request in flight on `conn` (until the returned guard drops) and wraps its body so
    /// the table knows while it is still arriving.
    pub fn begin(&self, conn: &Arc<Conn>, body: Incoming) -> (Busy, Watched) {
        conn.busy.fetch_add(1, Relaxed);
        let receiving = !body.is_end_stream();
        if receiving {
            conn.body_since.store(self.now_ms(), Relaxed);
        }
        (Busy(conn.clone()), Watched { inner: body, conn: conn.clone(), receiving })
    }
}

/// Counts a request in flight on its connection while alive.
pub struct Busy(Arc<Conn>);

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.busy.fetch_sub(1, Relaxed);
    }
}

/// A request body that tells its connection when it has arrived (or was given up).
pub struct Watched {
    inner: Incoming,
    conn: Arc<Conn>,
    receiving: bool,
}

impl Watched {
    fn done(&mut self) {
        if self.receiving {
            self.receiving = false;
            self.conn.body_since.store(0, Relaxed);
        }
    }
}

impl Drop for Watched {
    fn drop(&mut self) {
        self.done();
    }
}

impl Body for Watched {
    type Data = Bytes;
    type Error = hyper::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, hyper::Error>>> {
        let this = &mut *self;
        let polled = Pin::new(&mut this.inner).poll_frame(cx);
        let ended = match &polled {
            Poll::Pending => false,
            Poll::Ready(Some(Ok(_))) => this.inner.is_end_stream(),
            Poll::Ready(None | Some(Err(_))) => true,
        };
        if ended {
            this.done();
        }
        polled
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idle_connections_go_first_then_slow_bodies_oldest_first() {
        let table = Table::new(Duration::from_millis(50));
        let conns: Vec<Arc<Conn>> = (0..3).map(|_| Arc::new(Conn::default())).collect();
        for (id, conn) in conns.iter().enumerate() {
            table.insert(id as u64, conn.clone());
            conn.busy.store(1, Relaxed);
        }
        // All serving, none receiving a body: nothing to evict.
        assert_eq!(table.evict_one(), None);
        // Connections 1 and 2 wait for their bodies; 2 is idle once its request ends.
        conns[1].body_since.store(table.now_ms(), Relaxed);
        conns[2].body_since.store(table.now_ms(), Relaxed);
        assert_eq!(table.evict_one(), None, "not slow yet");
        std::thread::sleep(Duration::from_millis(80));
        conns[2].busy.store(0, Relaxed);
        assert_eq!(table.evict_one(), Some(Evicted::Idle));
        assert_eq!(table.evict_one(), Some(Evicted::SlowBody));
        assert_eq!(table.len(), 1);
        assert!(table.remove(0) && !table.remove(1));
    }
}
