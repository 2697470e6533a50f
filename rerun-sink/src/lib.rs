//! Rerun logging of the live fleet (`airroads serve --rerun …`).
//!
//! A dedicated thread reads the snapshot, road and metrics watch channels at its own pace: when it
//! falls behind it takes the latest snapshot and counts the ones it skipped, so the fleet loop never
//! waits for it. Everything is logged on the `tick` sequence timeline (and `time`, in seconds):
//! - `world/road/walls`, `world/road/centerline`: line strips, logged again when the road changes
//!   (a network has no centre line; its cells are the closed outlines of `world/road/cells`);
//! - `world/road/reservations`: the single-file sections, coloured by the end they admit from and
//!   labelled with who is in and who waits, every tick while the road has any;
//! - `world/uavs/{id}`: the position (labelled with the id, coloured by status, radius D_c/2), with
//!   `trail`, `velocity`, `target` and `goal` below it; cleared when the UAV is removed;
//! - scalar series `barrier/{id}` (smallest barrier value), `slack/{id}`, `margins/collision`,
//!   `margins/road` (fleet minima, m) and `tick_us/p50`, `tick_us/p99` (fleet loop timing).
//!
//! Above `--rerun-batch-above` UAVs (default [`BATCH_ABOVE_UAVS`]) the fleet is `world/fleet` (all
//! positions, labelled with the ids) and `world/fleet/velocity`, one batch each per tick, and only
//! the UAVs selected with `PUT /api/rerun/selection` (the dashboard sends its selection) get the
//! per-UAV entities and series above. What the sink logged and skipped is `rerun` in `/api/metrics`.

mod fleet_log;
mod logger;
mod viewer;

use anyhow::Context as _;
use engine::fleet_loop::RoadView;
use engine::snapshot::Snapshot;
use engine::stats::LoopMetrics;
use logger::Logger;
use rerun::external::re_uri::RedapUri;
use rerun::log::ChunkBatcherConfig;
use rerun::sink::{FileSink, FileSinkOptions, LogSink};
use rerun::{RecordingStream, RecordingStreamBuilder};
use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::Duration;
use tokio::sync::{oneshot, watch};
use viewer::Viewer;

/// The Rerun application id of the recordings.
pub const APPLICATION_ID: &str = "airroads";
/// The sequence timeline of fleet-loop ticks.
pub const TICK_TIMELINE: &str = "tick";
/// The duration timeline of simulated time (s).
pub const TIME_TIMELINE: &str = "time";
/// Points kept in each UAV's trail.
pub const TRAIL_POINTS: usize = 50;
/// Ticks between two trail points (the trail covers TRAIL_POINTS × this many ticks: 10 s at 20 Hz).
pub const TRAIL_EVERY_TICKS: u64 = 4;
/// Memory the `serve` mode's gRPC server keeps for late viewers before dropping the oldest data.
pub const SERVE_MEMORY_BYTES: u64 = 512 * 1024 * 1024;
/// Fleets larger than this are logged as one batch (`--rerun-batch-above`).
pub const BATCH_ABOVE_UAVS: usize = 100;
/// Most UAVs `PUT /api/rerun/selection` takes.
pub const MAX_SELECTED: usize = 64;

/// What the sink has done (`rerun` in `GET /api/metrics`), updated after every snapshot.
#[derive(Debug, Default)]
pub struct RerunCounters {
    /// A sink is running (`--rerun` is not `off` and it started).
    pub active: AtomicBool,
    /// The last snapshot was logged as one batch.
    pub batched: AtomicBool,
    /// Snapshots logged.
    pub logged: AtomicU64,
    /// Snapshots skipped: the sink was behind the loop, or no viewer was connected.
    pub skipped: AtomicU64,
    /// Log calls that failed.
    pub errors: AtomicU64,
}

impl RerunCounters {
    fn store(&self, stats: SinkStats, batched: bool) {
        self.batched.store(batched, Relaxed);
        self.logged.store(stats.logged, Relaxed);
        self.skipped.store(stats.skipped, Relaxed);
        self.errors.store(stats.errors, Relaxed);
    }

    /// The counters as `GET /api/metrics` shows them.
    pub fn report(&self) -> RerunReport {
        RerunReport {
            active: self.active.load(Relaxed),
            batched: self.batched.load(Relaxed),
            logged: self.logged.load(Relaxed),
            skipped: self.skipped.load(Relaxed),
            errors: self.errors.load(Relaxed),
        }
    }
}

/// `rerun` of `GET /api/metrics`: [`RerunCounters`] read once.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, schemars::JsonSchema)]
pub struct RerunReport {
    /// A sink is running.
    pub active: bool,
    /// The last snapshot was logged as one batch.
    pub batched: bool,
    /// Snapshots logged.
    pub logged: u64,
    /// Snapshots skipped.
    pub skipped: u64,
    /// Log calls that failed.
    pub errors: u64,
}

/// How long [`RerunSink::finish`] waits for the sink to flush before leaving it behind.
pub const FINISH_TIMEOUT: Duration = Duration::from_secs(5);

/// Where `--rerun` sends the log.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum RerunMode {
    /// No logging.
    #[default]
    Off,
    /// Stream to a running viewer at this `rerun+http://…/proxy` URL (None: the default local viewer).
    Connect(Option<String>),
    /// Write an `.rrd` file.
    Save(PathBuf),
    /// Host a gRPC server on 127.0.0.1:9876 that viewers connect to.
    Serve,
}

/// Why a `--rerun` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RerunModeError {
    /// Not one of the forms.
    #[error("`{0}`: expected off, connect, connect=ADDR, save=FILE.rrd or serve")]
    Unknown(String),
    /// `connect=` with an address that is not `host:port` or a `rerun+http://host:port/proxy` URL.
    #[error("`{0}`: expected host:port or rerun+http://host:port/proxy after connect=")]
    BadAddress(String),
    /// `save=` without a file name ending in `.rrd`.
    #[error("`{0}`: expected a file name ending in .rrd after save=")]
    NotRrd(String),
}

impl std::str::FromStr for RerunMode {
    type Err = RerunModeError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "off" => return Ok(Self::Off),
            "connect" => return Ok(Self::Connect(None)),
            "serve" => return Ok(Self::Serve),
            _ => {}
        }
        if let Some(addr) = s.strip_prefix("connect=") {
            return connect_url(addr).map(|url| Self::Connect(Some(url)));
        }
        if let Some(file) = s.strip_prefix("save=") {
            let path = PathBuf::from(file);
            let rrd = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("rrd"));
            let named = path.file_stem().is_some_and(|stem| !stem.is_empty());
            return if rrd && named { Ok(Self::Save(path)) } else { Err(RerunModeError::NotRrd(s.into())) };
        }
        Err(RerunModeError::Unknown(s.into()))
    }
}

impl std::fmt::Display for RerunMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Off => write!(f, "off"),
            Self::Connect(url) => {
                write!(f, "connect={}", url.as_deref().unwrap_or(rerun::DEFAULT_CONNECT_URL))
            }
            Self::Save(path) => write!(f, "save={}", path.display()),
            Self::Serve => write!(f, "serve (rerun+http://127.0.0.1:{}/proxy)", rerun::DEFAULT_SERVER_PORT),
        }
    }
}

/// `host:port` or a full proxy URL, as the proxy URL; refused unless Rerun parses it as one.
fn connect_url(addr: &str) -> Result<String, RerunModeError> {
    let url = if addr.contains("://") { addr.to_string() } else { format!("rerun+http://{addr}/proxy") };
    match url.parse::<RedapUri>() {
        Ok(RedapUri::Proxy(_)) if !addr.trim().is_empty() => Ok(url),
        _ => Err(RerunModeError::BadAddress(format!("connect={addr}"))),
    }
}

/// What the sink did, returned by [`RerunSink::finish`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SinkStats {
    /// Snapshots logged.
    pub logged: u64,
    /// Snapshots skipped because the sink was behind the loop or no viewer was connected.
    pub skipped: u64,
    /// Log calls that failed (the first one is printed).
    pub errors: u64,
}

/// The running sink thread.
pub struct RerunSink {
    stop: Option<oneshot::Sender<()>>,
    done: std::sync::mpsc::Receiver<SinkStats>,
}

impl RerunSink {
    /// Stops logging, flushes (an `.rrd` file is complete afterwards) and returns the counts; None if
    /// the sink did not finish within [`FINISH_TIMEOUT`] (it is left behind, never blocking shutdown).
    /// Blocking: call it from a plain thread or `spawn_blocking`.
    pub fn finish(mut self) -> Option<SinkStats> {
        if let Some(stop) = self.stop.take() {
            // The thread may already have ended with the fleet loop; then there is nothing to stop.
            let _ = stop.send(());
        }
        self.done.recv_timeout(FINISH_TIMEOUT).ok()
    }
}

/// Starts logging `state`'s channels as `mode` says (None for `off`), batching fleets of more
/// than `batch_above` UAVs. Errors (a file that cannot be created, a port in use) are returned; a
/// missing viewer for `connect` is not an error: the sink warns, keeps retrying and skips
/// snapshots until one listens.
pub fn start(mode: &RerunMode, inputs: Inputs, batch_above: usize) -> anyhow::Result<Option<RerunSink>> {
    let output = match mode {
        RerunMode::Off => return Ok(None),
        RerunMode::Connect(url) => {
            let url = url.clone().unwrap_or_else(|| rerun::DEFAULT_CONNECT_URL.to_string());
            Output::Viewer(Viewer::open(url)?)
        }
        RerunMode::Save(path) => {
            // The footer (an index of every chunk, which `rerun rrd verify` checks) is kept in memory
            // until the file is closed: it grows with the chunk count, about one per entity per
            // second here, which batching keeps independent of the fleet's size.
            let sink = FileSink::with_options(path, FileSinkOptions { write_footer: true })
                .with_context(|| format!("creating {}", path.display()))?;
            // Rows of one entity are gathered into a chunk for a second, not 200 ms: every chunk carries its
            // own schema, and the demo fleet's file was 3× larger with the default.
            let batching =
                ChunkBatcherConfig { flush_tick: Duration::from_secs(1), ..ChunkBatcherConfig::DEFAULT };
            let builder = builder().batcher_config(batching);
            Output::Stream(builder.set_sinks(vec![Box::new(sink) as Box<dyn LogSink>])?)
        }
        RerunMode::Serve => {
            let port = rerun::DEFAULT_SERVER_PORT;
            // The gRPC server binds on its own thread and only logs a failure: check the port first.
            drop(std::net::TcpListener::bind(("127.0.0.1", port)).with_context(|| format!("port {port}"))?);
            let options = rerun::ServerOptions {
                memory_limit: rerun::MemoryLimit::from_bytes(SERVE_MEMORY_BYTES),
                ..Default::default()
            };
            Output::Stream(builder().serve_grpc_opts("127.0.0.1", port, options)?)
        }
    };
    let channels = inputs;
    let (stop, stopped) = oneshot::channel();
    let (done_tx, done) = std::sync::mpsc::channel();
    channels.counters.active.store(true, Relaxed);
    std::thread::Builder::new().name("rerun-sink".into()).spawn(move || {
        let counters = channels.counters.clone();
        let stats = run(output, channels, Logger::new(batch_above), stopped);
        counters.active.store(false, Relaxed);
        // `finish` may have given up waiting; the counts are then of no use to anyone.
        let _ = done_tx.send(stats);
    })?;
    Ok(Some(RerunSink { stop: Some(stop), done }))
}

/// The recording's builder: application id and name.
pub(crate) fn builder() -> RecordingStreamBuilder {
    RecordingStreamBuilder::new(APPLICATION_ID).recording_name("airroads serve")
}

/// What the sink thread reads, and where it reports.
/// What the sink reads (the engine's channels and the selection) and where it counts.
pub struct Inputs {
    /// The snapshot after each tick.
    pub snapshots: watch::Receiver<Arc<Snapshot>>,
    /// The road, after each change.
    pub road: watch::Receiver<Arc<RoadView>>,
    /// The loop's statistics.
    pub metrics: watch::Receiver<Arc<LoopMetrics>>,
    /// The UAVs that keep their own entities in a batched fleet (`PUT /api/rerun/selection`).
    pub selection: watch::Receiver<Arc<[String]>>,
    /// What the sink did, for `GET /api/metrics`.
    pub counters: Arc<RerunCounters>,
}

/// The sink thread: logs every snapshot it gets to until `stopped` fires or the fleet loop ends.
fn run(
    mut output: Output,
    channels: Inputs,
    mut logger: Logger,
    mut stopped: oneshot::Receiver<()>,
) -> SinkStats {
    let Inputs { mut snapshots, road, metrics, mut selection, counters } = channels;
    let mut selected: HashSet<String> = selection.borrow_and_update().iter().cloned().collect();
    let runtime = match tokio::runtime::Builder::new_current_thread().build() {
        Ok(r) => r,
        Err(e) => {
            tracing::warn!("rerun: no runtime for the sink thread ({e}); nothing is logged");
            return logger.stats;
        }
    };
    loop {
        let snapshot = snapshots.borrow_and_update().clone();
        if selection.has_changed().unwrap_or(false) {
            selected = selection.borrow_and_update().iter().cloned().collect();
        }
        match output.stream() {
            Some(rec) => {
                let (road, metrics) = (road.borrow().clone(), metrics.borrow().clone());
                logger.log(rec, &snapshot, &road, &metrics, &selected);
            }
            None => {
                logger.stats.skipped += 1;
                logger.forget_road();
            }
        }
        counters.store(logger.stats, logger.batched(&snapshot));
        let next = runtime.block_on(async {
            tokio::select! {
                biased;
                _ = &mut stopped => false,
                changed = snapshots.changed() => changed.is_ok(),
            }
        });
        if !next {
            break;
        }
    }
    if let Some(rec) = output.stream()
        && let Err(e) = rec.flush_with_timeout(FINISH_TIMEOUT)
    {
        tracing::warn!("rerun: final flush: {e}");
    }
    if let Output::Viewer(viewer) = output
        && !viewer.connected
    {
        viewer.abandon();
    }
    logger.stats
}

/// Where the recording goes.
enum Output {
    /// A file or the gRPC server: always ready.
    Stream(RecordingStream),
    /// A viewer that may not be listening (yet, or any more).
    Viewer(Viewer),
}

impl Output {
    /// The stream to log to now, None while no viewer is connected.
    fn stream(&mut self) -> Option<&RecordingStream> {
        match self {
            Self::Stream(rec) => Some(rec),
            Self::Viewer(viewer) => viewer.ready(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form() {
        assert_eq!("off".parse(), Ok(RerunMode::Off));
        assert_eq!("serve".parse(), Ok(RerunMode::Serve));
        assert_eq!("connect".parse(), Ok(RerunMode::Connect(None)));
        let url = "rerun+http://10.0.0.2:9000/proxy".to_string();
        assert_eq!("connect=10.0.0.2:9000".parse(), Ok(RerunMode::Connect(Some(url.clone()))));
        assert_eq!(format!("connect={url}").parse(), Ok(RerunMode::Connect(Some(url))));
        assert_eq!("save=out/run.rrd".parse(), Ok(RerunMode::Save("out/run.rrd".into())));
    }

    #[test]
    fn refuses_anything_else() {
        for bad in [
            "",
            "on",
            "Off",
            "connect=",
            "connect=http://x:1/",
            "save=",
            "save=run.json",
            "save=.rrd",
            "serve=1",
        ] {
            let err = bad.parse::<RerunMode>().expect_err(bad).to_string();
            assert!(err.starts_with(&format!("`{bad}`")), "{bad}: {err}");
        }
        assert!(matches!("save=x.txt".parse::<RerunMode>(), Err(RerunModeError::NotRrd(_))));
        assert!(matches!("connect=a b".parse::<RerunMode>(), Err(RerunModeError::BadAddress(_))));
    }
}
