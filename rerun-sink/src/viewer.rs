//! The `connect` mode's connection to a Rerun viewer (`--rerun connect[=ADDR]`): reopened when the
//! viewer goes away, and nothing is logged while it is not connected, so the gRPC client's queue
//! never fills and the sink thread never blocks on it.

use super::builder;
use anyhow::Context as _;
use rerun::RecordingStream;
use rerun::external::re_uri::RedapUri;
use rerun::log::ChunkBatcherConfig;
use rerun::sink::{GrpcSink, GrpcSinkConnectionState, LogSink, SinkFlushError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A connection to a viewer, reopened when the viewer goes away. Nothing is logged while it is not
/// connected, so the gRPC client's queue never fills and the sink thread never blocks on it.
pub(super) struct Viewer {
    url: String,
    rec: RecordingStream,
    sink: Arc<GrpcSink>,
    opened: Instant,
    pub(super) connected: bool,
    warned: bool,
    recording_id: String,
}

/// The gRPC sink behind an `Arc`, so its connection state stays readable.
struct SharedGrpcSink(Arc<GrpcSink>);

impl LogSink for SharedGrpcSink {
    fn send(&self, msg: rerun::log::LogMsg) {
        self.0.send(msg);
    }
    fn flush_blocking(&self, timeout: Duration) -> Result<(), SinkFlushError> {
        self.0.flush_blocking(timeout)
    }
    fn default_batcher_config(&self) -> ChunkBatcherConfig {
        self.0.default_batcher_config()
    }
}

impl Viewer {
    /// Opens a connection to the viewer at `url` (a proxy URL); it connects in the background.
    pub(super) fn open(url: String) -> anyhow::Result<Self> {
        let since_epoch =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let recording_id = format!("airroads-{}-{}", std::process::id(), since_epoch.as_millis());
        let (rec, sink) = Self::connect(&url, &recording_id)?;
        Ok(Self { url, rec, sink, opened: Instant::now(), connected: false, warned: false, recording_id })
    }

    fn connect(url: &str, recording_id: &str) -> anyhow::Result<(RecordingStream, Arc<GrpcSink>)> {
        let RedapUri::Proxy(uri) = url.parse::<RedapUri>().with_context(|| format!("rerun URL {url}"))?
        else {
            anyhow::bail!("rerun URL {url}: not a proxy URL (rerun+http://host:port/proxy)");
        };
        let sink = Arc::new(GrpcSink::new(uri));
        let rec = builder()
            .recording_id(recording_id)
            .set_sinks(vec![Box::new(SharedGrpcSink(sink.clone())) as Box<dyn LogSink>])?;
        Ok((rec, sink))
    }

    /// The stream to log to while a viewer is connected; reconnects when it went away.
    pub(super) fn ready(&mut self) -> Option<&RecordingStream> {
        match self.sink.status() {
            GrpcSinkConnectionState::Connected => {
                if !self.connected && self.warned {
                    tracing::info!("rerun: connected to the viewer at {}", self.url);
                }
                (self.connected, self.warned) = (true, false);
                return Some(&self.rec);
            }
            GrpcSinkConnectionState::Connecting { started } => {
                if !self.warned && started.elapsed() > Duration::from_secs(2) {
                    tracing::warn!(
                        "rerun: no viewer at {} (start one with `rerun`); the server keeps running \
                         and logging starts when a viewer listens",
                        self.url
                    );
                    self.warned = true;
                }
            }
            GrpcSinkConnectionState::Disconnected(_) if self.opened.elapsed() > Duration::from_secs(1) => {
                if self.connected {
                    tracing::warn!("rerun: the viewer at {} went away; reconnecting", self.url);
                }
                // The client makes no new attempts once disconnected: open a new one (same recording).
                match Self::connect(&self.url, &self.recording_id) {
                    Ok((rec, sink)) => {
                        let old =
                            (std::mem::replace(&mut self.rec, rec), std::mem::replace(&mut self.sink, sink));
                        drop_in_background(old);
                    }
                    Err(e) => tracing::warn!("rerun: {e:#}"),
                }
                (self.opened, self.connected) = (Instant::now(), false);
            }
            GrpcSinkConnectionState::Disconnected(_) => {}
        }
        None
    }
}

impl Viewer {
    /// Lets go of a connection that never reached a viewer without waiting for it.
    pub(super) fn abandon(self) {
        drop_in_background((self.rec, self.sink));
    }
}

/// Drops a stream on a thread of its own: the gRPC client's flush on drop waits up to 5 s for a
/// viewer that is not there.
fn drop_in_background(stream: (RecordingStream, Arc<GrpcSink>)) {
    // If no thread can be spawned, the closure (and the stream) is dropped right here: slower, still correct.
    let _ = std::thread::Builder::new().name("rerun-drop".into()).spawn(move || drop(stream));
}
