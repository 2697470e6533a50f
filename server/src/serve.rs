//! `airroads serve`: the engine (the fleet loop on its own thread and the state writer), the regions,
//! and the HTTP side (`api`: the REST API and the WebSocket stream on tokio/axum). [`Server::start`] wires them; [`serve`] runs the HTTP side on an
//! already-bound listener until a shutdown future completes (tests bind 127.0.0.1:0).

use api::{audit, auth, binary, error, federate, guard, listener, routes, state, web, ws};

use anyhow::Context as _;
use axum::Router;
use engine::linking::MocapRoutes;
use engine::snapshot::Snapshot;
use engine::{EngineConfig, RunningEngine};
use fleet::{FleetConfig, ValidScenario};
use policies::PolicyRegistry;
use state::{AppState, Frame, StreamCounters};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::watch;

pub use engine::handle::open_store;

/// Most UAVs by default: what the fleet loop ticks within dt on the development machine with the
/// default policy in a dense crowd, with either navigation (BENCHMARKS.md, "Admission").
pub const DEFAULT_MAX_UAVS: usize = 120;

pub use engine::{DEMO_SCENARIO, demo_scenario};

/// Everything the server needs to start.
pub struct ServeConfig {
    /// Road rule, navigation and filter settings (parameters come from the scenario or saved state).
    pub fleet: FleetConfig,
    /// The loaded policies.
    pub policies: PolicyRegistry,
    /// The policy of UAVs added without one.
    pub default_policy: String,
    /// Mutating requests need this bearer token, if set.
    pub token: Option<String>,
    /// Where the state is saved and resumed from; None: nothing is saved.
    pub data_dir: Option<PathBuf>,
    /// What to fly when the data directory has no saved state.
    pub initial: ValidScenario,
    /// How Crazyflie links fly (altitude, take-off and landing times, log period).
    pub relay: crazyflie::RelayConfig,
    /// Resume the saved state of `data_dir` when there is one (false: start from `initial`).
    pub resume: bool,
    /// Most UAVs the fleet may have (changes beyond are refused with 422).
    pub max_uavs: usize,
    /// Extra `Host` values accepted (`--allow-host`).
    pub allow_hosts: Vec<String>,
    /// Extra origins allowed to make changes and open `/ws` (`--allow-origin`).
    pub allow_origins: Vec<String>,
    /// Connection and request-head limits of the HTTP side.
    pub limits: listener::Limits,
    /// Most WebSocket clients at once.
    pub max_stream_clients: usize,
    /// Which Crazyflie links may be given (remote UDP hosts: `--allow-link-host`).
    pub link_rules: links::LinkRules,
    /// The region this server flies (`--region`) and what its loop shares with Zenoh; None: the
    /// whole road, no Zenoh.
    pub region: Option<regions::RegionShared>,
}

impl ServeConfig {
    /// A configuration with the defaults for everything but the fleet, its policies and start.
    pub fn new(
        fleet: FleetConfig,
        policies: PolicyRegistry,
        default_policy: String,
        initial: ValidScenario,
    ) -> Self {
        Self {
            fleet,
            policies,
            default_policy,
            token: None,
            data_dir: None,
            initial,
            relay: crazyflie::RelayConfig::default(),
            resume: true,
            max_uavs: DEFAULT_MAX_UAVS,
            allow_hosts: Vec::new(),
            allow_origins: Vec::new(),
            limits: listener::Limits::default(),
            max_stream_clients: ws::MAX_CLIENTS,
            link_rules: links::LinkRules::default(),
            region: None,
        }
    }
}

/// A running server: the engine's threads and the shared handler state.
pub struct Server {
    app: AppState,
    engine: RunningEngine,
    allow_hosts: Vec<String>,
    allow_origins: Vec<String>,
    limits: listener::Limits,
}

impl Server {
    /// Starts the engine (the fleet loop and the state writer), the snapshot serialiser and the
    /// HTTP side's state (inside a tokio runtime).
    pub fn start(config: ServeConfig) -> anyhow::Result<Self> {
        let token = config.token.clone().map(Arc::from);
        let default_policy: Arc<str> = Arc::from(config.default_policy.as_str());
        let policies: Arc<[String]> = config.policies.names().map(str::to_string).collect();
        anyhow::ensure!(
            policies.iter().any(|p| **p == *default_policy),
            "default policy `{default_policy}` is not loaded (available: {})",
            policies.join(", ")
        );
        let (max_uavs, max_stream_clients, limits) =
            (config.max_uavs, config.max_stream_clients, config.limits);
        let (allow_hosts, allow_origins) = (config.allow_hosts.clone(), config.allow_origins.clone());
        let link_rules = Arc::new(config.link_rules.clone());
        let region = config.region.clone();
        let hook = match &region {
            Some(region) => Some(Box::new(
                regions::RegionLoop::new(region.clone(), link_rules.clone())
                    .context("the region's loop side was taken already")?,
            ) as Box<dyn engine::hook::LoopHook>),
            None => None,
        };
        let running = engine::start(EngineConfig {
            fleet: config.fleet,
            policies: config.policies,
            default_policy: config.default_policy,
            data_dir: config.data_dir,
            initial: config.initial,
            relay: config.relay,
            resume: config.resume,
            max_uavs,
            link_rules: link_rules.clone(),
            hook,
        })?;
        let snapshots = running.handle.snapshots.clone();
        let mut encoder = binary::Encoder::default();
        let first = snapshots.borrow().clone();
        let binary = encoder.encode(&first);
        let (frames_tx, frames) = watch::channel(Frame::new(first, binary));
        let stream = Arc::new(StreamCounters::default());
        tokio::spawn(serialise(snapshots, frames_tx, encoder, stream.clone()));
        let app = AppState {
            engine: running.handle.clone(),
            frames,
            token,
            auth_failures: Arc::default(),
            forwarding: Arc::new(tokio::sync::Semaphore::new(federate::MAX_FORWARDED)),
            access: Arc::default(),
            policies,
            default_policy,
            max_uavs,
            link_rules,
            max_stream_clients,
            stream,
            connections: Arc::default(),
            body_budget: state::body_budget(),
            validation: Arc::new(tokio::sync::Semaphore::new(1)),
            mocap: Arc::default(),
            rerun: Arc::default(),
            rerun_selection: Arc::new(watch::channel(Arc::from(Vec::new())).0),
            region,
        };
        Ok(Self { app, engine: running, allow_hosts, allow_origins, limits })
    }

    /// The shared handler state (for tests and other sinks such as Rerun).
    pub fn state(&self) -> &AppState {
        &self.app
    }

    /// Where the first fleet came from (`saved state` or the scenario's name), for the banner.
    pub fn resumed_from(&self) -> &str {
        &self.engine.resumed_from
    }

    /// Where motion-capture poses of each Crazyflie go.
    pub fn mocap(&self) -> &MocapRoutes {
        &self.engine.mocap
    }

    /// The HTTP application: REST API, `/ws`, the dashboard at `/`, behind the request guard, the
    /// token check and the audit log (see [`guard`]). Requests are refused until
    /// [`Server::listening_on`] set the address.
    pub fn router(&self) -> Router {
        let app = self.app.clone();
        routes::router()
            .merge(web::router())
            .route("/ws", axum::routing::get(ws::handler))
            .fallback(not_found)
            .layer(axum::middleware::from_fn_with_state(app.clone(), federate::forward))
            .layer(axum::middleware::from_fn_with_state(app.clone(), auth::require_token))
            .layer(axum::middleware::from_fn_with_state(app.clone(), guard::check))
            .layer(axum::middleware::from_fn_with_state(app.clone(), audit::record))
            .layer(axum::middleware::from_fn(guard::finish))
            .layer(axum::extract::DefaultBodyLimit::max(error::MAX_BODY_BYTES))
            .with_state(app)
    }

    /// Sets the address the server listens on (which `Host` and `Origin` values are its own).
    pub fn listening_on(&self, listen: std::net::SocketAddr) {
        let rules = guard::AccessRules::new(listen, &self.allow_hosts, &self.allow_origins);
        if self.app.access.set(rules).is_err() {
            tracing::warn!("the listening address was set twice; keeping the first");
        }
    }

    /// Stops the fleet loop after its current tick and waits until the state writer committed
    /// everything queued (the last positions included).
    pub async fn shutdown(self) {
        self.engine.shutdown().await;
    }
}

/// How long shutdown waits for the Crazyflies to land.
pub const LANDING_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(8);

/// Lands every UAV flown over a radio or UDP link and waits (up to [`LANDING_TIMEOUT`]) until none
/// is airborne. In-process UAVs keep their place: they resume from the saved state.
pub async fn land_crazyflies(state: &AppState) {
    let airborne = |s: &Snapshot| -> Vec<String> {
        s.uavs
            .iter()
            .filter(|u| *u.link != *links::SIM_LINK && u.phase.airborne())
            .map(|u| u.id.to_string())
            .collect()
    };
    let ids = airborne(&state.engine.snapshots.borrow());
    if ids.is_empty() {
        return;
    }
    tracing::info!("landing {} Crazyflies before exiting", ids.len());
    for id in ids {
        if let Err(e) = state.apply_urgent(engine::command::Command::Land(Some(id.clone()))).await {
            tracing::warn!("{id} not landed: {}", e.message);
        }
    }
    let mut snapshots = state.engine.snapshots.clone();
    let landed = async {
        while !airborne(&snapshots.borrow_and_update()).is_empty() {
            if snapshots.changed().await.is_err() {
                return;
            }
        }
    };
    if tokio::time::timeout(LANDING_TIMEOUT, landed).await.is_err() {
        tracing::warn!("not every Crazyflie reported landed within {LANDING_TIMEOUT:?}");
    }
}

async fn not_found() -> error::ApiError {
    error::ApiError::new(axum::http::StatusCode::NOT_FOUND, "not_found", "no such route")
}

/// Serialises every new snapshot once in the binary format, and as JSON while JSON stream clients
/// are connected, for all readers of `/api/state` and `/ws` (`GET /api/state` makes the JSON of a
/// frame nobody streams on demand, once).
async fn serialise(
    mut snapshots: watch::Receiver<Arc<Snapshot>>,
    frames: watch::Sender<Frame>,
    mut encoder: binary::Encoder,
    stream: Arc<StreamCounters>,
) {
    while snapshots.changed().await.is_ok() {
        let snapshot = snapshots.borrow_and_update().clone();
        let binary = encoder.encode(&snapshot);
        let frame = Frame::new(snapshot, binary);
        if stream.json_clients.load(Ordering::Relaxed) > 0 {
            frame.json();
        }
        frames.send_replace(frame);
    }
}

/// How long open requests may finish after the shutdown began.
pub const DRAIN: Duration = Duration::from_secs(5);

/// Serves `server` on `listener` until `shutdown` completes, then lands the Crazyflies, stops the
/// loop, lets open requests finish and saves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    server: Server,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    server.listening_on(listener.local_addr().context("the listener's address")?);
    let app = server.router();
    // Crazyflies land before the loop stops (it keeps flying the others meanwhile); then stopping
    // the loop ends every WebSocket stream, and the accept loop stops and drains.
    let stopper = server.engine.stopper();
    let state = server.app.clone();
    let (closing, closed) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        land_crazyflies(&state).await;
        stopper.stop();
        closing.send_replace(true);
    });
    listener::run(listener, app, server.limits, server.app.connections.clone(), closed, DRAIN).await;
    server.shutdown().await;
    Ok(())
}
