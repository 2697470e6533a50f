//! `airroads serve`: the fleet loop on its own thread, the REST API and the WebSocket stream on
//! tokio/axum, and the state writer. [`Server::start`] wires them; [`serve`] runs the HTTP side on an
//! already-bound listener until a shutdown future completes (tests bind 127.0.0.1:0).

mod api;
mod auth;
pub mod client;
pub mod command;
pub mod engine;
pub mod error;
pub mod linking;
pub mod mocap;
pub mod openapi;
pub mod persist;
mod rerun_log;
pub mod rerun_sink;
pub mod snapshot;
pub mod state;
pub mod stats;
mod web;
mod ws;

use anyhow::Context as _;
use axum::Router;
use axum::extract::ws::Utf8Bytes;
use engine::{Engine, LoopChannels, RoadView};
use fleet::{Fleet, FleetConfig, ValidScenario};
use linking::{LinkFactory, MocapRoutes};
use persist::SavedState;
use policies::PolicyRegistry;
use snapshot::Snapshot;
use state::{AppState, Frame, StreamCounters};
use stats::LoopMetrics;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use tokio::sync::{mpsc, watch};
use uav::{UavState, Vec2};

/// The scenario `airroads serve` flies when it has no saved state and no `--scenario`.
pub const DEMO_SCENARIO: &str = include_str!("../../../scenarios/demo.json");

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
}

/// A running server: the fleet loop thread and the shared handler state.
pub struct Server {
    app: AppState,
    stop: Arc<AtomicBool>,
    fleet_loop: Option<std::thread::JoinHandle<()>>,
    writer: Option<tokio::task::JoinHandle<()>>,
    /// Where the initial fleet came from (`saved state` or the scenario's name), for the banner.
    pub resumed_from: String,
    /// Where motion-capture poses of each Crazyflie go.
    pub mocap: MocapRoutes,
}

/// The scenario embedded as the default demo (always valid: a test checks it).
pub fn demo_scenario() -> anyhow::Result<ValidScenario> {
    let scenario = fleet::Scenario::from_json(DEMO_SCENARIO).context("embedded demo scenario")?;
    scenario.validate().context("embedded demo scenario")
}

/// Builds the fleet: the saved state of `data_dir` if there is one, else `initial`.
fn initial_fleet(config: ServeConfig, factory: &LinkFactory) -> anyhow::Result<(Fleet, String)> {
    let saved = match &config.data_dir {
        Some(dir) if config.resume => persist::load(dir)?,
        _ => None,
    };
    let mut fleet_config = config.fleet;
    let Some(saved) = saved else {
        fleet_config.params = config.initial.params;
        let mut fleet = Fleet::new(fleet_config, config.initial.road.clone(), config.policies);
        engine::load_scenario(&mut fleet, &config.initial, &config.default_policy, factory)?;
        return Ok((fleet, format!("scenario `{}`", config.initial.name)));
    };
    saved.params.validate()?;
    fleet_config.params = saved.params;
    let mut fleet = Fleet::new(fleet_config, saved.road()?, config.policies);
    for u in &saved.uavs {
        let policy =
            if fleet.policy_names().any(|n| n == u.policy) { &u.policy } else { &config.default_policy };
        let state = UavState::at_rest(Vec2::new(u.position[0], u.position[1]));
        let goal = u.goal.map(|g| Vec2::new(g[0], g[1]));
        if let Some(Err(e)) = u.link.as_deref().map(links::check_link) {
            eprintln!("airroads: saved UAV `{}` not resumed: link: {e}", u.id);
            continue;
        }
        if let Err(e) = fleet.check_new(&u.id, policy, &state, goal) {
            eprintln!("airroads: saved UAV `{}` not resumed: {e}", u.id);
            continue;
        }
        let link = factory.make(&u.id, u.link.as_deref(), state, saved.params.dt);
        if let Err(e) = fleet.try_add(u.id.clone(), policy.clone(), link, state, goal) {
            eprintln!("airroads: saved UAV `{}` not resumed: {e}", u.id);
        }
    }
    fleet.set_hold(saved.paused);
    Ok((fleet, "saved state".to_string()))
}

impl Server {
    /// Starts the fleet loop, the snapshot serialiser and the state writer (inside a tokio runtime).
    pub fn start(config: ServeConfig) -> anyhow::Result<Self> {
        let token = config.token.clone().map(Arc::from);
        let default_policy: Arc<str> = Arc::from(config.default_policy.as_str());
        let data_dir = config.data_dir.clone();
        let policies: Arc<[String]> = config.policies.names().map(str::to_string).collect();
        anyhow::ensure!(
            policies.iter().any(|p| **p == *default_policy),
            "default policy `{default_policy}` is not loaded (available: {})",
            policies.join(", ")
        );
        let factory = LinkFactory::new(tokio::runtime::Handle::current(), config.relay);
        let (fleet, resumed_from) = initial_fleet(config, &factory)?;
        let (commands, requests) = mpsc::channel(1024);
        let (urgent, urgent_requests) = mpsc::unbounded_channel();
        let first = Snapshot::of(&fleet, 0, 0.0, 0);
        let first_frame = Frame { tick: 0, text: Utf8Bytes::from(serde_json::to_string(&first)?) };
        let (snapshots_tx, snapshots) = watch::channel(Arc::new(first));
        let (metrics_tx, metrics) = watch::channel(Arc::new(LoopMetrics::default()));
        let (saved_tx, saved) = watch::channel(Arc::new(SavedState::of(&fleet)));
        let (road_tx, road) = watch::channel(Arc::new(RoadView::of(fleet.road(), 0)));
        let (frames_tx, frames) = watch::channel(first_frame);
        let channels = LoopChannels {
            requests,
            urgent: urgent_requests,
            snapshots: snapshots_tx,
            metrics: metrics_tx,
            saved: saved_tx,
            road: road_tx,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let mocap = factory.mocap.clone();
        let fleet_loop =
            Engine::new(fleet, default_policy.to_string(), factory, channels).spawn(stop.clone())?;
        tokio::spawn(serialise(snapshots.clone(), frames_tx));
        let writer = data_dir.map(|dir| tokio::spawn(persist::writer(dir, saved)));
        let app = AppState {
            commands,
            urgent,
            snapshots,
            frames,
            road,
            metrics,
            token,
            policies,
            default_policy,
            stream: Arc::new(StreamCounters::default()),
        };
        Ok(Self { app, stop, fleet_loop: Some(fleet_loop), writer, resumed_from, mocap })
    }

    /// The shared handler state (for tests and other sinks such as Rerun).
    pub fn state(&self) -> &AppState {
        &self.app
    }

    /// The HTTP application: REST API, `/ws`, the dashboard at `/`, with the token check on changes.
    pub fn router(&self) -> Router {
        api::router()
            .merge(web::router())
            .route("/ws", axum::routing::get(ws::handler))
            .fallback(not_found)
            .layer(axum::middleware::from_fn_with_state(self.app.clone(), auth::require_token))
            .layer(axum::extract::DefaultBodyLimit::max(error::MAX_BODY_BYTES))
            .with_state(self.app.clone())
    }

    /// Stops the fleet loop after its current tick and writes the final state.
    pub async fn shutdown(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.fleet_loop.take() {
            // Joining a thread blocks: do it on the blocking pool.
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
        // The loop's channel ends are gone with its thread; the writer flushes the last state and ends.
        if let Some(writer) = self.writer.take() {
            let _ = writer.await;
        }
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
            .filter(|u| {
                u.link != links::SIM_LINK
                    && matches!(u.phase, "taking_off" | "flying" | "landing" | "stopping")
            })
            .map(|u| u.id.clone())
            .collect()
    };
    let ids = airborne(&state.snapshots.borrow());
    if ids.is_empty() {
        return;
    }
    eprintln!("airroads: landing {} Crazyflies before exiting", ids.len());
    for id in ids {
        if let Err(e) = state.apply_urgent(command::Command::Land(Some(id.clone()))).await {
            eprintln!("airroads: {id} not landed: {}", e.message);
        }
    }
    let mut snapshots = state.snapshots.clone();
    let landed = async {
        while !airborne(&snapshots.borrow_and_update()).is_empty() {
            if snapshots.changed().await.is_err() {
                return;
            }
        }
    };
    if tokio::time::timeout(LANDING_TIMEOUT, landed).await.is_err() {
        eprintln!("airroads: not every Crazyflie reported landed within {LANDING_TIMEOUT:?}");
    }
}

async fn not_found() -> error::ApiError {
    error::ApiError::new(axum::http::StatusCode::NOT_FOUND, "not_found", "no such route")
}

/// Serialises every new snapshot once, for all readers of `/api/state` and `/ws`.
async fn serialise(mut snapshots: watch::Receiver<Arc<Snapshot>>, frames: watch::Sender<Frame>) {
    while snapshots.changed().await.is_ok() {
        let snapshot = snapshots.borrow_and_update().clone();
        match serde_json::to_string(&*snapshot) {
            Ok(text) => {
                frames.send_replace(Frame { tick: snapshot.tick, text: Utf8Bytes::from(text) });
            }
            Err(e) => eprintln!("airroads: snapshot not serialised: {e}"),
        }
    }
}

/// Serves `server` on `listener` until `shutdown` completes, then stops the loop and saves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    server: Server,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let app = server.router();
    // Crazyflies land before the loop stops (it keeps flying the others meanwhile); then stopping
    // the loop ends every WebSocket stream, so the graceful shutdown does not wait on them.
    let stop = server.stop.clone();
    let state = server.app.clone();
    let shutdown = async move {
        shutdown.await;
        land_crazyflies(&state).await;
        stop.store(true, Ordering::Relaxed);
    };
    axum::serve(listener, app).with_graceful_shutdown(shutdown).await.context("HTTP server")?;
    server.shutdown().await;
    Ok(())
}
