//! The engine seen from outside. [`start`] opens the store, builds the first fleet, and spawns the
//! state writer and the fleet loop; what it returns holds the threads ([`RunningEngine`]) and the
//! [`EngineHandle`], which is all a client of the loop needs: apply a change, apply an urgent one,
//! and watch the snapshots, the road and the metrics.

use crate::command::{ChangeError, Claim, Command, Outcome, Request};
use crate::durable::{StorageStatus, ToWriter, Writer};
use crate::fleet_loop::{Engine, LoopChannels, LoopClock, RoadView, now_ms};
use crate::hook::LoopHook;
use crate::linking::{LinkFactory, MocapRoutes, StopRoutes};
use crate::persist::SavedState;
use crate::snapshot::Snapshot;
use crate::stats::LoopMetrics;
use crate::store::{AuditRecord, Store, StoreError, Write};
use anyhow::Context as _;
use fleet::{Edit, Fleet, FleetConfig, ValidScenario};
use policies::PolicyRegistry;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};
use uav::{UavState, Vec2};

/// How long a change may wait for the fleet loop to take it; then it is withdrawn (nothing changed).
pub const COMMAND_TIMEOUT: Duration = Duration::from_secs(2);

/// How long a change the loop took may wait for the disk before the client is told it is unknown.
pub const DURABLE_TIMEOUT: Duration = Duration::from_secs(30);

/// Changes queued for the loop at most (a full queue is [`ApplyError::Busy`]).
pub const COMMAND_QUEUE: usize = 1024;

/// What the engine needs to start.
pub struct EngineConfig {
    /// Road rule, navigation and filter settings (parameters come from the scenario or saved state).
    pub fleet: FleetConfig,
    /// The loaded policies.
    pub policies: PolicyRegistry,
    /// The policy of UAVs added without one.
    pub default_policy: String,
    /// Where the state is saved and resumed from; None: nothing is saved.
    pub data_dir: Option<PathBuf>,
    /// What to fly when there is no saved state to resume.
    pub initial: ValidScenario,
    /// How Crazyflie links fly.
    pub relay: crazyflie::RelayConfig,
    /// Resume the saved state of `data_dir` when there is one (never with a hook: see [`start`]).
    pub resume: bool,
    /// Most UAVs the fleet may have.
    pub max_uavs: usize,
    /// Which Crazyflie links may be opened (remote UDP hosts).
    pub link_rules: Arc<links::LinkRules>,
    /// What a region adds to the loop (None: a single server).
    pub hook: Option<Box<dyn LoopHook>>,
}

/// Why a change was not applied (in every case but [`ApplyError::StorageTimeout`], nothing changed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    /// The fleet loop is not running.
    #[error("the fleet loop is not running")]
    Unavailable,
    /// The loop's queue is full.
    #[error("too many changes queued; nothing changed; try again")]
    Busy,
    /// The loop refused it.
    #[error(transparent)]
    Refused(#[from] ChangeError),
    /// Applied, but the disk has not confirmed it within [`DURABLE_TIMEOUT`].
    #[error("the change was applied but the disk has not confirmed it; check GET /healthz")]
    StorageTimeout,
}

/// A client's side of the fleet loop (cheap to clone).
#[derive(Clone)]
pub struct EngineHandle {
    commands: mpsc::Sender<Request>,
    urgent: mpsc::UnboundedSender<Request>,
    loop_thread: std::thread::Thread,
    /// Every Crazyflie's emergency stop, reachable without the fleet loop.
    pub stops: StopRoutes,
    /// The latest snapshot.
    pub snapshots: watch::Receiver<Arc<Snapshot>>,
    /// The current road.
    pub road: watch::Receiver<Arc<RoadView>>,
    /// The latest loop statistics.
    pub metrics: watch::Receiver<Arc<LoopMetrics>>,
    /// When the loop last finished a tick.
    pub clock: Arc<LoopClock>,
    /// The state writer's queue (audit entries and queries).
    pub writer: mpsc::Sender<ToWriter>,
    /// The storage's health.
    pub storage: Arc<StorageStatus>,
}

impl EngineHandle {
    /// The loop has ended (every change would be refused).
    pub fn stopped(&self) -> bool {
        self.commands.is_closed()
    }

    /// Sends a land or stop `command` ahead of every queued change, wakes the loop, and waits for
    /// its outcome (land and stop are never persisted, so they never wait on the disk).
    pub async fn apply_urgent(&self, command: Command) -> Result<Outcome, ApplyError> {
        let (reply, answer) = oneshot::channel();
        self.urgent.send(Request::new(command, reply)).map_err(|_| ApplyError::Unavailable)?;
        self.loop_thread.unpark();
        match tokio::time::timeout(COMMAND_TIMEOUT, answer).await {
            Ok(Ok(outcome)) => Ok(outcome?),
            _ => Err(ApplyError::Unavailable),
        }
    }

    /// Sends `command` (with the audit entry committed with it) to the fleet loop and waits, off
    /// the loop, until it is applied and on disk. A change the loop did not take within
    /// [`COMMAND_TIMEOUT`] is withdrawn (nothing changed); one it took is answered with its real
    /// outcome, never with an error for an applied change.
    pub async fn apply(&self, command: Command, audit: Option<AuditRecord>) -> Result<Outcome, ApplyError> {
        let (reply, mut answer) = oneshot::channel();
        let claim = Arc::new(Claim::default());
        let request = Request { command, reply, audit, claim: claim.clone() };
        match tokio::time::timeout(COMMAND_TIMEOUT, self.commands.send(request)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return Err(ApplyError::Unavailable),
            Err(_) => return Err(ApplyError::Busy),
        }
        let outcome = match tokio::time::timeout(COMMAND_TIMEOUT, &mut answer).await {
            Ok(answer) => answer,
            Err(_) if claim.withdraw() => return Err(ChangeError::Withdrawn.into()),
            // Taken: the outcome comes once it is on disk (or taken back).
            Err(_) => match tokio::time::timeout(DURABLE_TIMEOUT, answer).await {
                Ok(answer) => answer,
                Err(_) => return Err(ApplyError::StorageTimeout),
            },
        };
        Ok(outcome.map_err(|_| ApplyError::Unavailable)??)
    }

    /// Wakes the loop (a land or stop is waiting, or it is stopping).
    pub fn wake(&self) {
        self.loop_thread.unpark();
    }
}

/// The engine's threads, stopped by [`RunningEngine::shutdown`].
pub struct RunningEngine {
    /// The clients' side.
    pub handle: EngineHandle,
    /// Where the first fleet came from (`saved state` or the scenario's name).
    pub resumed_from: String,
    /// Where motion-capture poses of each Crazyflie go.
    pub mocap: MocapRoutes,
    stop: Arc<AtomicBool>,
    fleet_loop: Option<std::thread::JoinHandle<()>>,
    writer: Option<std::thread::JoinHandle<()>>,
}

/// Stops the fleet loop from another task (its threads are joined by [`RunningEngine::shutdown`]).
#[derive(Clone)]
pub struct Stopper {
    stop: Arc<AtomicBool>,
    loop_thread: std::thread::Thread,
}

impl Stopper {
    /// The loop ends after its current tick (it is woken if asleep).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
        self.loop_thread.unpark();
    }
}

impl RunningEngine {
    /// What stops the loop without waiting for it.
    pub fn stopper(&self) -> Stopper {
        Stopper { stop: self.stop.clone(), loop_thread: self.handle.loop_thread.clone() }
    }

    /// Stops the fleet loop after its current tick and waits until the state writer committed
    /// everything queued (the last positions included).
    pub async fn shutdown(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.fleet_loop.take() {
            thread.thread().unpark();
            // Joining a thread blocks: do it on the blocking pool.
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
        let (done, flushed) = oneshot::channel();
        if self.handle.writer.send(ToWriter::Flush(done)).await.is_ok() {
            let _ = tokio::time::timeout(Duration::from_secs(10), flushed).await;
        }
        // The writer thread ends once the last queue sender (in handle clones) is gone.
        drop(self.writer.take());
    }
}

/// Opens the data directory's database (an in-memory one without a directory); the error names why
/// it cannot be written.
pub fn open_store(data_dir: Option<&Path>) -> Result<Store, StoreError> {
    match data_dir {
        Some(dir) => Store::open(dir),
        None => Store::in_memory(),
    }
}

/// Starts the engine (inside a tokio runtime: the links' tasks run on it): the store, the first
/// fleet (the saved state when `resume` and there is one, else `initial`), the state writer and the
/// fleet loop. A loop with a hook (a region server) never resumes: UAVs come and go by handover
/// without being saved (the region's owner and its mirror are the record), so a saved fleet may
/// hold UAVs another server flies now.
pub fn start(mut config: EngineConfig) -> anyhow::Result<RunningEngine> {
    let mut store = open_store(config.data_dir.as_deref())
        .with_context(|| format!("data directory {}", display_dir(config.data_dir.as_deref())))?;
    let factory = LinkFactory::new(tokio::runtime::Handle::current(), config.relay);
    let hook = config.hook.take();
    let (max_uavs, default_policy, link_rules) =
        (config.max_uavs, config.default_policy.clone(), config.link_rules.clone());
    let resume = config.resume && hook.is_none();
    let (fleet, resumed_from) = first_fleet(config, resume, &store, &factory)?;
    anyhow::ensure!(
        fleet.uavs().len() <= max_uavs,
        "the fleet has {} UAVs, more than the maximum of {max_uavs} (--max-uavs)",
        fleet.uavs().len()
    );
    // The database holds exactly what flies from the first tick on.
    store.commit([&Write::Replace(SavedState::of(&fleet))]).context("saving the initial state")?;
    let writer = Writer::spawn(store)?;
    let (commands, requests) = mpsc::channel(COMMAND_QUEUE);
    let (urgent, urgent_requests) = mpsc::unbounded_channel();
    let (snapshots_tx, snapshots) = watch::channel(Arc::new(Snapshot::of(&fleet, 0, 0.0, 0)));
    let (metrics_tx, metrics) = watch::channel(Arc::new(LoopMetrics::default()));
    let (road_tx, road) =
        watch::channel(Arc::new(RoadView::of(fleet.airspace(), &fleet.config.params, 0, now_ms())));
    let clock = Arc::new(LoopClock::default());
    let channels = LoopChannels {
        requests,
        urgent: urgent_requests,
        snapshots: snapshots_tx,
        metrics: metrics_tx,
        road: road_tx,
        writer: writer.queue.clone(),
        written: writer.answers,
        storage: writer.status.clone(),
        clock: clock.clone(),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (mocap, stops) = (factory.mocap.clone(), factory.stops.clone());
    let mut engine = Engine::new(fleet, default_policy, factory, channels, max_uavs);
    engine.set_link_rules(link_rules);
    if let Some(hook) = hook {
        engine.set_hook(hook);
    }
    let fleet_loop = engine.spawn(stop.clone())?;
    let handle = EngineHandle {
        commands,
        urgent,
        loop_thread: fleet_loop.thread().clone(),
        stops,
        snapshots,
        road,
        metrics,
        clock,
        writer: writer.queue,
        storage: writer.status,
    };
    Ok(RunningEngine {
        handle,
        resumed_from,
        mocap,
        stop,
        fleet_loop: Some(fleet_loop),
        writer: Some(writer.thread),
    })
}

fn display_dir(dir: Option<&Path>) -> String {
    dir.map_or_else(|| "(in memory)".to_string(), |d| d.display().to_string())
}

/// The first fleet: the saved state of `store` if `resume` and there is one, else the initial scenario.
fn first_fleet(
    config: EngineConfig,
    resume: bool,
    store: &Store,
    factory: &LinkFactory,
) -> anyhow::Result<(Fleet, String)> {
    let saved = if resume { store.load()? } else { None };
    let mut fleet_config = config.fleet;
    // The snapshot shows each UAV's collision margin: the rows stage measures it with the rows.
    fleet_config.uav_collision_margins = true;
    let Some(saved) = saved else {
        fleet_config.params = config.initial.params;
        let mut fleet = Fleet::new(fleet_config, config.initial.road.clone(), config.policies);
        crate::changes::load_scenario(&mut fleet, &config.initial, &config.default_policy, factory)?;
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
        if let Some(Err(e)) = u.link.as_deref().map(|l| links::check_link_with(l, &config.link_rules)) {
            tracing::warn!("saved UAV `{}` not resumed: link: {e}", u.id);
            continue;
        }
        if let Err(e) = fleet.check_new(&u.id, policy, &state, goal) {
            tracing::warn!("saved UAV `{}` not resumed: {e}", u.id);
            continue;
        }
        let link = factory.make(&u.id, u.link.as_deref(), state, saved.params.dt);
        let add = Edit::Add { id: u.id.clone(), policy: policy.clone(), link, state, goal };
        if let Err(e) = fleet.apply(add) {
            tracing::warn!("saved UAV `{}` not resumed: {e}", u.id);
        }
    }
    // The first fleet is the start: nothing to take back.
    drop(fleet.apply(Edit::Pause(saved.paused)));
    Ok((fleet, "saved state".to_string()))
}
