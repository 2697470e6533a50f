//! The fleet loop: a dedicated OS thread that ticks the fleet every dt (ARCHITECTURE.md, "One
//! tick"). Commands from REST handlers are applied between ticks, never during one; land and
//! stop requests the moment they arrive (the loop sleeps in `park_timeout` and the handler unparks
//! it). After each tick an immutable snapshot and the metrics are published on `watch` channels, then
//! the gap's changes go to the state writer ([`super::durable`]). The thread never waits on a
//! client, a disk or a radio: it only `try_recv`s and `try_send`s; late ticks are counted and
//! skipped, never bunched.

use super::command::Command;
use super::command::{ChangeError, Outcome, Reply, Request};
use super::durable::{FromWriter, StorageStatus, ToWriter};
use super::hook::{Arrival, LoopEdits, LoopHook, NoHook, Ownership};
use super::linking::LinkFactory;
pub use super::road_view::RoadView;
use super::snapshot::Snapshot;
use super::stats::{LoopMetrics, TickStages, TickStats};
use fleet::{Fleet, Undo};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};

/// Most commands applied between two ticks (the rest wait for the next gap).
pub const MAX_COMMANDS_PER_TICK: usize = 64;

/// Ticks between two writes of the UAVs' positions.
const POSITIONS_EVERY_TICKS: u64 = 20;

/// A change not on disk after this long marks the storage degraded (new changes are refused).
pub const STORAGE_STALL: Duration = Duration::from_secs(5);

/// The wall clock now (s since the Unix epoch; 0 on a clock set before 1970).
pub fn wall_now() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs_f64()).unwrap_or(0.0)
}

/// The wall clock now (ms since the Unix epoch).
pub fn now_ms() -> u64 {
    (wall_now() * 1e3) as u64
}

/// The next instant at which the wall clock is a whole multiple of `period` (since the Unix epoch).
pub fn next_wall_boundary(period: Duration) -> Instant {
    let now = Instant::now();
    let wall = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    let period_ns = period.as_nanos().max(1);
    let to_go = period_ns - wall.as_nanos() % period_ns;
    now + Duration::from_nanos(u64::try_from(to_go).unwrap_or(u64::MAX))
}

/// When the loop last finished a tick, for `/healthz` (a stalled loop publishes nothing else).
#[derive(Debug)]
pub struct LoopClock {
    start: Instant,
    last_tick_us: AtomicU64,
}

impl Default for LoopClock {
    fn default() -> Self {
        Self { start: Instant::now(), last_tick_us: AtomicU64::new(0) }
    }
}

impl LoopClock {
    /// Records a tick finished now.
    pub fn ticked(&self) {
        let us = u64::try_from(self.start.elapsed().as_micros()).unwrap_or(u64::MAX);
        self.last_tick_us.store(us, Ordering::Relaxed);
    }

    /// Time since the last finished tick (since the start before the first one).
    pub fn tick_age(&self) -> Duration {
        let last = Duration::from_micros(self.last_tick_us.load(Ordering::Relaxed));
        self.start.elapsed().saturating_sub(last)
    }
}

/// The ends of the loop's channels.
pub struct LoopChannels {
    /// Commands from the REST handlers.
    pub requests: mpsc::Receiver<Request>,
    /// Land and stop requests, applied as soon as they arrive.
    pub urgent: mpsc::UnboundedReceiver<Request>,
    /// The snapshot after each tick.
    pub snapshots: watch::Sender<Arc<Snapshot>>,
    /// Loop statistics after each tick.
    pub metrics: watch::Sender<Arc<LoopMetrics>>,
    /// The road, after each change.
    pub road: watch::Sender<Arc<RoadView>>,
    /// Work for the state writer.
    pub writer: mpsc::Sender<ToWriter>,
    /// The writer's answers.
    pub written: std::sync::mpsc::Receiver<FromWriter>,
    /// The storage's health.
    pub storage: Arc<StorageStatus>,
    /// When the last tick finished.
    pub clock: Arc<LoopClock>,
}

/// A gap's changes on their way to the disk, with what takes them back.
pub(crate) struct PendingBatch {
    pub(crate) seq: u64,
    pub(crate) undo: Vec<Undo>,
    pub(crate) sent: Instant,
}

/// The fleet loop's own state.
pub struct Engine {
    pub(crate) fleet: Fleet,
    pub(crate) default_policy: String,
    pub(crate) links: LinkFactory,
    pub(crate) channels: LoopChannels,
    pub(crate) stats: TickStats,
    pub(crate) road_version: u64,
    pub(crate) ticks: u64,
    time: f64,
    /// Most UAVs the fleet may have (`--max-uavs`).
    pub(crate) max_uavs: usize,
    /// Batches sent to the writer and not yet confirmed, oldest first.
    pub(crate) pending: VecDeque<PendingBatch>,
    pub(crate) next_seq: u64,
    /// The current gap's applied changes: undo records, writes, clients.
    pub(crate) gap: super::changes::Gap,
    /// Answers held until the next snapshot shows what they say.
    pub(crate) after_publish: Vec<(Reply, Result<Outcome, ChangeError>)>,
    /// What a region adds to the loop (a single server: [`NoHook`]).
    pub(crate) hook: Box<dyn LoopHook>,
    /// Which Crazyflie links this server may open (`--allow-link-host`), for UAVs that come from
    /// another server (a handover or a takeover).
    pub(crate) link_rules: Arc<links::LinkRules>,
    /// The tick boundary of the current gap on the wall clock (ms; 0 before the first).
    boundary_ms: u64,
}

impl Engine {
    /// A loop over `fleet` (at most `max_uavs` UAVs); UAVs added without a policy fly
    /// `default_policy`, links come from `links`.
    pub fn new(
        fleet: Fleet,
        default_policy: String,
        links: LinkFactory,
        channels: LoopChannels,
        max_uavs: usize,
    ) -> Self {
        let stats = TickStats::new(fleet.config.params.dt);
        Self {
            fleet,
            default_policy,
            links,
            channels,
            stats,
            road_version: 0,
            ticks: 0,
            time: 0.0,
            max_uavs,
            pending: VecDeque::new(),
            next_seq: 0,
            gap: Default::default(),
            after_publish: Vec::new(),
            hook: Box::new(NoHook),
            link_rules: Arc::default(),
            boundary_ms: 0,
        }
    }

    /// Which Crazyflie links this server may open for UAVs that come from another server.
    pub fn set_link_rules(&mut self, rules: Arc<links::LinkRules>) {
        self.link_rules = rules;
    }

    /// Plugs in what a region adds to the loop; every UAV flown now is recorded as there from the start.
    pub fn set_hook(&mut self, hook: Box<dyn LoopHook>) {
        self.hook = hook;
        for u in self.fleet.uavs() {
            self.hook.ownership(Ownership::Opened { id: &u.id, how: "start" });
        }
    }

    /// The hook's step between two ticks (it borrows the loop, so it is taken out meanwhile).
    fn between_ticks(&mut self) {
        let mut hook = std::mem::replace(&mut self.hook, Box::new(NoHook));
        hook.between_ticks(self);
        self.hook = hook;
    }

    /// Runs the loop on a new thread until `stop` is set or every command sender is gone.
    pub fn spawn(mut self, stop: Arc<AtomicBool>) -> std::io::Result<std::thread::JoinHandle<()>> {
        std::thread::Builder::new().name("fleet-loop".into()).spawn(move || self.run(&stop))
    }

    fn run(&mut self, stop: &AtomicBool) {
        self.publish_road();
        let mut next = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            // Sleep until the tick instant; land and stop requests unpark the thread and are
            // applied at once (this is between two ticks).
            loop {
                self.apply_urgent();
                let now = Instant::now();
                if now >= next || stop.load(Ordering::Relaxed) {
                    break;
                }
                std::thread::park_timeout(next - now);
            }
            let period = Duration::from_secs_f64(self.fleet.config.params.dt);
            let started = Instant::now();
            let late = started.saturating_duration_since(next);
            if late >= period {
                // Skip the instants we missed instead of running them back to back.
                let missed = (late.as_secs_f64() / period.as_secs_f64()).floor() as u32;
                self.stats.missed(u64::from(missed));
                next += period * missed;
            }
            // The boundary this gap belongs to, on the wall clock (the loop may wake a little late).
            let late_ms = started.saturating_duration_since(next).as_millis() as u64;
            self.boundary_ms = now_ms().saturating_sub(late_ms);
            self.read_writer();
            if !self.apply_commands() {
                break;
            }
            self.between_ticks();
            self.tick(started);
            self.send_gap();
            next += period;
            let aligned = self.hook.next_tick(next, period);
            if aligned != next {
                let missed = aligned.saturating_duration_since(next).as_secs_f64() / period.as_secs_f64();
                self.stats.missed(missed.round() as u64);
                next = aligned;
            }
        }
        // Answer what is still held; the writer commits what it has (and the last positions).
        self.read_writer();
        self.send_positions();
        self.answer_held();
    }

    /// Sends the answers held until a snapshot shows them.
    pub(crate) fn answer_held(&mut self) {
        for (reply, answer) in self.after_publish.drain(..) {
            let _ = reply.send(answer);
        }
    }

    /// Applies queued commands; false when every sender is gone (the server shut down).
    pub(crate) fn apply_commands(&mut self) -> bool {
        let mut applied = 0;
        while applied < MAX_COMMANDS_PER_TICK {
            match self.channels.requests.try_recv() {
                Ok(request) => {
                    applied += 1;
                    self.apply_request(request);
                }
                Err(mpsc::error::TryRecvError::Empty) => break,
                Err(mpsc::error::TryRecvError::Disconnected) => return false,
            }
        }
        if applied > 0 {
            self.stats.commands(applied as u64);
        }
        true
    }

    /// Applies every queued land and stop request and answers it (they are never persisted).
    pub(crate) fn apply_urgent(&mut self) {
        while let Ok(request) = self.channels.urgent.try_recv() {
            let outcome = self.apply(request.command).map(|applied| applied.outcome);
            let _ = request.reply.send(outcome);
            self.stats.commands(1);
        }
    }

    pub(crate) fn road_changed(&mut self) {
        self.road_version += 1;
        self.stats.fleet_reloaded(self.fleet.config.params.dt);
        self.publish_road();
    }

    fn tick(&mut self, started: Instant) {
        self.hook.before_tick(&mut self.fleet);
        self.ticks += 1;
        self.time += self.fleet.config.params.dt;
        let previous = Arc::clone(&self.channels.snapshots.borrow());
        let (fleet, ticks, time, road_version) = (&mut self.fleet, self.ticks, self.time, self.road_version);
        // The tick and its snapshot as one job of the worker pool: each of their parallel passes
        // (about thirty) then starts on a worker that is awake, instead of this thread handing it
        // over and waking the pool each time.
        let (fleet_stages, snapshot, snapshot_us) = rayon::scope(|_| {
            let mut stages = fleet::StageTimes::default();
            if !fleet.uavs().is_empty() {
                fleet.tick();
                stages = fleet.stage_times();
            }
            let snapshot_started = Instant::now();
            let snapshot = Snapshot::after(Some(&previous), fleet, ticks, time, road_version);
            (stages, snapshot, snapshot_started.elapsed().as_secs_f64() * 1e6)
        });
        drop(previous);
        let duration_us = started.elapsed().as_secs_f64() * 1e6;
        let publish_started = Instant::now();
        self.stats.record(duration_us, &self.fleet, &snapshot);
        let snapshot = Arc::new(snapshot);
        self.hook.after_tick(&snapshot, &self.fleet, started);
        self.channels.snapshots.send_replace(snapshot);
        self.channels.metrics.send_replace(Arc::new(self.stats.metrics()));
        self.channels.clock.ticked();
        // The snapshot now shows every held answer's effect (or its absence, when taken back).
        self.answer_held();
        if self.ticks.is_multiple_of(POSITIONS_EVERY_TICKS) {
            self.send_positions();
        }
        // Published with the next tick's metrics (this tick's are out).
        let publish_us = publish_started.elapsed().as_secs_f64() * 1e6;
        self.stats.stages(TickStages::of_tick(fleet_stages, snapshot_us, duration_us, publish_us));
    }

    /// Queues the UAVs' positions for the writer (best effort: a full queue skips them).
    fn send_positions(&self) {
        if self.fleet.uavs().is_empty() {
            return;
        }
        let positions =
            self.fleet.uavs().iter().map(|u| (u.id.clone(), [u.state.p.x, u.state.p.y])).collect();
        let _ = self.channels.writer.try_send(ToWriter::Positions(positions));
    }

    pub(crate) fn publish_road(&mut self) {
        let since_ms = if self.boundary_ms > 0 { self.boundary_ms } else { now_ms() };
        let view =
            RoadView::of(self.fleet.airspace(), &self.fleet.config.params, self.road_version, since_ms);
        self.channels.road.send_replace(Arc::new(view));
        self.hook.road_changed(self.fleet.airspace());
    }
}

impl LoopEdits for Engine {
    fn fleet(&self) -> &Fleet {
        &self.fleet
    }

    fn max_uavs(&self) -> usize {
        self.max_uavs
    }

    fn road_version(&self) -> u64 {
        self.road_version
    }

    fn adopt(&mut self, arrival: Arrival) -> bool {
        let id = arrival.id.clone();
        match self.apply(Command::Adopt(Box::new(arrival))) {
            Ok(_) => true,
            Err(e) => {
                tracing::warn!("UAV `{id}` not adopted: {e}");
                false
            }
        }
    }

    fn release(&mut self, id: &str) -> Option<fleet::Uav> {
        self.fleet.remove(id).ok()
    }

    fn release_all(&mut self) -> Vec<fleet::Uav> {
        self.fleet.take_all()
    }
}
