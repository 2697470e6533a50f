//! The state writer: a dedicated OS thread that owns the [`Store`] and commits with group commit.
//! The fleet loop applies a gap's changes, ticks, publishes, then hands the batch to the writer
//! (never waiting); the writer drains everything queued (batches of several gaps, positions, audit
//! entries from the HTTP side) into one transaction, fsyncs once and only then answers each change's
//! client. A failed commit goes back to the loop, which takes those changes back (newest first) and
//! answers 503: a 2xx always means applied and on disk; an error means nothing changed.

use super::command::{Outcome, Reply};
use super::store::{AuditEntry, AuditRecord, Store, Write};
use serde::Serialize;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;
use tokio::sync::{mpsc, oneshot};

/// Messages queued for the writer (at most this many; the loop and the HTTP side never wait).
pub const QUEUE: usize = 65_536;

/// Audit entries kept for a retry while the disk refuses them; older ones are dropped and counted.
const AUDIT_BACKLOG: usize = 10_000;

/// The changes of one gap between ticks, with their clients' answers.
pub struct Batch {
    /// Increasing number of the batch.
    pub seq: u64,
    /// What to write (the changes and their audit entries).
    pub writes: Vec<Write>,
    /// Answered with their outcome once the batch is on disk.
    pub replies: Vec<(Reply, Outcome)>,
}

/// A query of the audit log (answered after the pending writes are committed).
pub struct AuditQuery {
    /// Entries newer than this, oldest first.
    pub after: Option<i64>,
    /// Entries older than this, newest first (when `after` is None).
    pub before: Option<i64>,
    /// At most this many.
    pub limit: usize,
    /// Where the entries go.
    pub reply: oneshot::Sender<Result<Vec<AuditEntry>, String>>,
}

/// What the writer is asked to do.
pub enum ToWriter {
    /// Commit a gap's changes.
    Batch(Batch),
    /// The UAVs' positions (newest wins).
    Positions(Vec<(String, [f64; 2])>),
    /// An audit entry of a request that changed nothing (refused, or land/stop).
    Audit(AuditRecord),
    /// The loop took back every batch after a failure: commit new ones again.
    Resume,
    /// Read the audit log.
    Query(AuditQuery),
    /// Answer once everything queued before is committed (or failed).
    Flush(oneshot::Sender<()>),
}

/// What the writer tells the loop.
pub enum FromWriter {
    /// Batch `seq` is on disk and its clients were answered.
    Committed(u64),
    /// Batch `seq` is not on disk: the loop takes it back and answers its clients.
    Failed {
        /// The batch.
        seq: u64,
        /// Its clients.
        replies: Vec<(Reply, Outcome)>,
        /// Why.
        reason: String,
    },
}

/// The storage's health, shared by the writer, the loop and `/healthz`/`/api/metrics`.
#[derive(Debug, Default)]
pub struct StorageStatus {
    /// The database file (None: `--ephemeral`, in memory).
    pub path: Option<String>,
    /// Committed transactions.
    pub commits: AtomicU64,
    /// Transactions the disk refused.
    pub failed_commits: AtomicU64,
    /// Changes cannot be made durable now: they are refused with 503.
    pub degraded: AtomicBool,
    /// Why, while degraded (and the last failure otherwise).
    pub error: Mutex<Option<String>>,
    /// Duration of the last commit (µs).
    pub last_commit_us: AtomicU64,
    /// Audit entries dropped (queue full, or the disk refused them for too long).
    pub audit_dropped: AtomicU64,
}

/// `storage` in `GET /api/metrics`.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct StorageReport {
    /// Changes are fsynced to a database file.
    pub durable: bool,
    /// The database file.
    pub path: Option<String>,
    /// True while changes are refused because they cannot be saved.
    pub degraded: bool,
    /// The last storage error.
    pub error: Option<String>,
    /// Committed transactions.
    pub commits: u64,
    /// Failed transactions.
    pub failed_commits: u64,
    /// Duration of the last commit (µs).
    pub last_commit_us: u64,
    /// Audit entries dropped.
    pub audit_dropped: u64,
}

impl StorageStatus {
    /// Marks the storage degraded for `reason`.
    pub fn degrade(&self, reason: String) {
        *self.error.lock().unwrap_or_else(PoisonError::into_inner) = Some(reason);
        self.degraded.store(true, Relaxed);
    }

    /// The reason changes are refused now, if they are.
    pub fn refusal(&self) -> Option<String> {
        if !self.degraded.load(Relaxed) {
            return None;
        }
        let error = self.error.lock().unwrap_or_else(PoisonError::into_inner).clone();
        Some(error.unwrap_or_else(|| "the storage failed".into()))
    }

    /// The report for `/api/metrics`.
    pub fn report(&self) -> StorageReport {
        StorageReport {
            durable: self.path.is_some(),
            path: self.path.clone(),
            degraded: self.degraded.load(Relaxed),
            error: self.error.lock().unwrap_or_else(PoisonError::into_inner).clone(),
            commits: self.commits.load(Relaxed),
            failed_commits: self.failed_commits.load(Relaxed),
            last_commit_us: self.last_commit_us.load(Relaxed),
            audit_dropped: self.audit_dropped.load(Relaxed),
        }
    }
}

/// The writer's ends: its queue, the loop's answers, and the status.
pub struct Writer {
    /// Where work goes (try_send only).
    pub queue: mpsc::Sender<ToWriter>,
    /// What the loop reads between ticks.
    pub answers: std::sync::mpsc::Receiver<FromWriter>,
    /// Shared health.
    pub status: Arc<StorageStatus>,
    /// The thread (ends when every queue sender is gone, after committing what was queued).
    pub thread: std::thread::JoinHandle<()>,
}

impl Writer {
    /// Starts the writer thread on `store`.
    pub fn spawn(store: Store) -> std::io::Result<Self> {
        let status = Arc::new(StorageStatus {
            path: store.path.as_ref().map(|p| p.display().to_string()),
            ..Default::default()
        });
        let (queue, rx) = mpsc::channel(QUEUE);
        let (tx, answers) = std::sync::mpsc::channel();
        let shared = status.clone();
        let thread = std::thread::Builder::new().name("state-writer".into()).spawn(move || {
            WriterThread { store, back: tx, status: shared, failed: false, audit: Vec::new() }.run(rx)
        })?;
        Ok(Self { queue, answers, status, thread })
    }
}

struct WriterThread {
    store: Store,
    back: std::sync::mpsc::Sender<FromWriter>,
    status: Arc<StorageStatus>,
    /// A batch failed and the loop has not yet confirmed it took the later ones back.
    failed: bool,
    /// Audit entries not yet on disk.
    audit: Vec<Write>,
}

impl WriterThread {
    fn run(mut self, mut rx: mpsc::Receiver<ToWriter>) {
        while let Some(first) = rx.blocking_recv() {
            let (mut batches, mut positions, mut queries, mut flushes) =
                (Vec::new(), None, Vec::new(), Vec::new());
            let mut next = Some(first);
            let mut drained = 0;
            while let Some(message) = next.take() {
                match message {
                    ToWriter::Batch(batch) if self.failed => {
                        self.fail(batch, "an earlier change could not be saved")
                    }
                    ToWriter::Batch(batch) => batches.push(batch),
                    ToWriter::Positions(p) => positions = Some(Write::Positions(p)),
                    ToWriter::Audit(record) => self.audit.push(Write::Audit(record)),
                    ToWriter::Resume => self.failed = false,
                    ToWriter::Query(query) => queries.push(query),
                    ToWriter::Flush(done) => flushes.push(done),
                }
                drained += 1;
                if drained < QUEUE {
                    next = rx.try_recv().ok();
                }
            }
            if !batches.is_empty() || positions.is_some() || !self.audit.is_empty() {
                self.commit(batches, positions);
            }
            for q in queries {
                let _ = q.reply.send(self.store.audit(q.after, q.before, q.limit).map_err(|e| e.to_string()));
            }
            for done in flushes {
                let _ = done.send(());
            }
        }
    }

    fn commit(&mut self, batches: Vec<Batch>, positions: Option<Write>) {
        let started = Instant::now();
        let writes =
            batches.iter().flat_map(|b| b.writes.iter()).chain(positions.iter()).chain(self.audit.iter());
        match self.store.commit(writes) {
            Ok(()) => {
                self.status.commits.fetch_add(1, Relaxed);
                let us = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
                self.status.last_commit_us.store(us, Relaxed);
                self.status.degraded.store(false, Relaxed);
                self.audit.clear();
                for batch in batches {
                    for (reply, outcome) in batch.replies {
                        let _ = reply.send(Ok(outcome));
                    }
                    let _ = self.back.send(FromWriter::Committed(batch.seq));
                }
            }
            Err(e) => {
                let reason = e.to_string();
                tracing::error!("the state could not be saved: {reason}");
                self.status.failed_commits.fetch_add(1, Relaxed);
                self.status.degrade(reason.clone());
                self.failed |= !batches.is_empty();
                self.store.compact_log();
                for batch in batches {
                    self.fail(batch, &reason);
                }
                if self.audit.len() > AUDIT_BACKLOG {
                    let excess = self.audit.len() - AUDIT_BACKLOG;
                    self.audit.drain(..excess);
                    self.status.audit_dropped.fetch_add(excess as u64, Relaxed);
                }
            }
        }
    }

    fn fail(&self, batch: Batch, reason: &str) {
        let failed =
            FromWriter::Failed { seq: batch.seq, replies: batch.replies, reason: reason.to_string() };
        let _ = self.back.send(failed);
    }
}
