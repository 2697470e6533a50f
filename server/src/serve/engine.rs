//! The fleet loop: a dedicated OS thread that ticks the fleet every dt (`shared/design/layout.md`,
//! one tick). Commands from REST handlers are applied between ticks, never during one; after each
//! tick an immutable snapshot, the metrics and the state to persist are published on `watch`
//! channels. The thread never waits on a client, a disk or a radio: it only `try_recv`s commands and
//! `send`s to watches (which never block); late ticks are counted and skipped, never bunched.

use super::command::{Command, Outcome, Request};
use super::linking::LinkFactory;
use super::persist::SavedState;
use super::snapshot::Snapshot;
use super::stats::{LoopMetrics, TickStats};
use fleet::{EditError, Fleet};
use roads::{Road, RoadLayout};
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use uav::UavState;

/// Most commands applied between two ticks (the rest wait for the next gap).
pub const MAX_COMMANDS_PER_TICK: usize = 64;

/// Ticks between two publications of the state to persist while nothing else changes.
const SAVE_EVERY_TICKS: u64 = 20;

/// The road as published to readers: the layout plus its drawable geometry.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoadView {
    /// Increases with every change.
    pub version: u64,
    /// The layout (`PUT /api/road` format).
    pub layout: RoadLayout,
    /// Every finite wall (barrier lines and end caps) as `[[x1, y1], [x2, y2]]`.
    pub walls: Vec<[[f64; 2]; 2]>,
    /// The centre line as a polyline.
    pub centerline: Vec<[f64; 2]>,
}

impl RoadView {
    /// The view of `road` at `version`.
    pub fn of(road: &Road, version: u64) -> Self {
        Self {
            version,
            layout: road.layout().clone(),
            walls: road.walls().iter().map(|w| [[w.a.x, w.a.y], [w.b.x, w.b.y]]).collect(),
            centerline: road.centerline().points().iter().map(|p| [p.x, p.y]).collect(),
        }
    }
}

/// The ends of the loop's channels.
pub struct LoopChannels {
    /// Commands from the REST handlers.
    pub requests: mpsc::Receiver<Request>,
    /// Land and stop requests, applied before any other command.
    pub urgent: mpsc::UnboundedReceiver<Request>,
    /// The snapshot after each tick.
    pub snapshots: watch::Sender<Arc<Snapshot>>,
    /// Loop statistics after each tick.
    pub metrics: watch::Sender<Arc<LoopMetrics>>,
    /// The state to persist, after each change and every second.
    pub saved: watch::Sender<Arc<SavedState>>,
    /// The road, after each change.
    pub road: watch::Sender<Arc<RoadView>>,
}

/// The fleet loop's own state.
pub struct Engine {
    fleet: Fleet,
    default_policy: String,
    links: LinkFactory,
    channels: LoopChannels,
    stats: TickStats,
    road_version: u64,
    ticks: u64,
    time: f64,
}

impl Engine {
    /// A loop over `fleet`; UAVs added without a policy fly `default_policy`, links come from `links`.
    pub fn new(fleet: Fleet, default_policy: String, links: LinkFactory, channels: LoopChannels) -> Self {
        let stats = TickStats::new(fleet.config.params.dt);
        Self { fleet, default_policy, links, channels, stats, road_version: 0, ticks: 0, time: 0.0 }
    }

    /// Runs the loop on a new thread until `stop` is set or every command sender is gone.
    pub fn spawn(mut self, stop: Arc<AtomicBool>) -> std::io::Result<std::thread::JoinHandle<()>> {
        std::thread::Builder::new().name("fleet-loop".into()).spawn(move || self.run(&stop))
    }

    fn run(&mut self, stop: &AtomicBool) {
        self.publish_road();
        self.publish_saved();
        let mut next = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            let now = Instant::now();
            if now < next {
                std::thread::sleep(next - now);
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
            if !self.apply_commands() {
                break;
            }
            self.tick(started);
            next += period;
        }
        self.publish_saved();
    }

    /// Applies queued commands; false when every sender is gone (the server shut down).
    fn apply_commands(&mut self) -> bool {
        // Land and stop go out ahead of anything queued (the urgent channel only carries those),
        // outside the cap on other changes.
        let mut urgent = 0;
        while let Ok(request) = self.channels.urgent.try_recv() {
            let outcome = self.apply(request.command);
            let _ = request.reply.send(outcome);
            urgent += 1;
        }
        let mut applied = 0;
        while applied < MAX_COMMANDS_PER_TICK {
            match self.channels.requests.try_recv() {
                Ok(request) => {
                    let outcome = self.apply(request.command);
                    // The client may have gone away; the change stands either way.
                    let _ = request.reply.send(outcome);
                    applied += 1;
                }
                Err(mpsc::error::TryRecvError::Empty) => break,
                Err(mpsc::error::TryRecvError::Disconnected) => return false,
            }
        }
        let applied = applied + urgent;
        if applied > 0 {
            self.stats.commands(applied as u64);
            self.publish_saved();
        }
        true
    }

    /// Applies one command to the fleet.
    pub fn apply(&mut self, command: Command) -> Result<Outcome, EditError> {
        let dt = self.fleet.config.params.dt;
        match command {
            Command::SetRoad(road) => {
                let cleared_goals = self.fleet.replace_road(road)?;
                self.road_changed();
                return Ok(Outcome::RoadReplaced { cleared_goals });
            }
            Command::AddUav { id, position, policy, goal, link } => {
                let state = UavState::at_rest(position);
                let policy = policy.unwrap_or_else(|| self.default_policy.clone());
                // Checked before the link exists: a refused UAV never starts a radio session.
                self.fleet.check_new(&id, &policy, &state, goal)?;
                let link = self.links.make(&id, link.as_deref(), state, dt);
                self.fleet.try_add(id, policy, link, state, goal)?;
            }
            Command::Land(Some(id)) => self.fleet.land(&id)?,
            Command::Land(None) => self.fleet.land_all(),
            Command::EmergencyStop => self.fleet.emergency_stop_all(),
            Command::RemoveUav(id) => drop(self.fleet.remove(&id)?),
            Command::SetGoal(id, goal) => self.fleet.set_goal(&id, goal)?,
            Command::SetPolicy(id, policy) => self.fleet.set_policy(&id, &policy)?,
            Command::LoadScenario(scenario) => {
                let policy = self.default_policy.clone();
                load_scenario(&mut self.fleet, &scenario, &policy, &self.links)?;
                self.road_changed();
                return Ok(Outcome::ScenarioLoaded { tick: self.ticks });
            }
            Command::Hold(hold) => self.fleet.set_hold(hold),
        }
        Ok(Outcome::Done)
    }

    fn road_changed(&mut self) {
        self.road_version += 1;
        self.stats.fleet_reloaded(self.fleet.config.params.dt);
        self.publish_road();
    }

    fn tick(&mut self, started: Instant) {
        if !self.fleet.uavs().is_empty() {
            self.fleet.tick();
        }
        self.ticks += 1;
        self.time += self.fleet.config.params.dt;
        let snapshot = Snapshot::of(&self.fleet, self.ticks, self.time, self.road_version);
        let duration_us = started.elapsed().as_secs_f64() * 1e6;
        self.stats.record(duration_us, &self.fleet, &snapshot);
        self.channels.snapshots.send_replace(Arc::new(snapshot));
        self.channels.metrics.send_replace(Arc::new(self.stats.metrics()));
        if self.ticks.is_multiple_of(SAVE_EVERY_TICKS) {
            self.publish_saved();
        }
    }

    fn publish_road(&self) {
        self.channels.road.send_replace(Arc::new(RoadView::of(self.fleet.road(), self.road_version)));
    }

    fn publish_saved(&self) {
        self.channels.saved.send_replace(Arc::new(SavedState::of(&self.fleet)));
    }
}

/// Replaces road, parameters and UAVs of `fleet` by those of `scenario`, every UAV flying `policy`.
pub fn load_scenario(
    fleet: &mut Fleet,
    scenario: &fleet::ValidScenario,
    policy: &str,
    links: &LinkFactory,
) -> Result<(), EditError> {
    // Checked before anything changes; the scenario's starts and goals were validated with it.
    if !fleet.policy_names().any(|n| n == policy) {
        return Err(EditError::UnknownPolicy(format!("policy `{policy}` is not loaded")));
    }
    fleet.reset(scenario.params, scenario.road.clone());
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = links.make(&u.id, u.link.as_deref(), state, scenario.params.dt);
        fleet.add(u.id.clone(), policy.to_string(), link, state, Some(u.goal));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use links::LinkPhase;
    use tokio::sync::oneshot;

    #[test]
    fn land_goes_out_ahead_of_queued_changes_and_changes_are_capped_per_gap() {
        let runtime = tokio::runtime::Builder::new_current_thread().build().unwrap();
        let scenario = super::super::demo_scenario().unwrap();
        let policies = policies::PolicyRegistry::with_pd(scenario.params.delta);
        let config = fleet::FleetConfig { params: scenario.params, ..Default::default() };
        let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
        let factory = LinkFactory::new(runtime.handle().clone(), crazyflie::RelayConfig::default());
        load_scenario(&mut fleet, &scenario, "pd", &factory).unwrap();
        let first = fleet.uavs()[0].id.clone();
        let goal = scenario.uavs[1].goal;

        let (commands, requests) = mpsc::channel(1024);
        let (urgent, urgent_requests) = mpsc::unbounded_channel();
        let snapshots = watch::channel(Arc::new(Snapshot::of(&fleet, 0, 0.0, 0))).0;
        let metrics = watch::channel(Arc::new(LoopMetrics::default())).0;
        let saved = watch::channel(Arc::new(SavedState::of(&fleet))).0;
        let road = watch::channel(Arc::new(RoadView::of(fleet.road(), 0))).0;
        let channels = LoopChannels { requests, urgent: urgent_requests, snapshots, metrics, saved, road };
        let mut engine = Engine::new(fleet, "pd".into(), factory, channels);

        // 100 goal changes queued first, then a land request on the urgent channel.
        let mut answers = Vec::new();
        for _ in 0..100 {
            let (reply, answer) = oneshot::channel();
            commands
                .try_send(Request { command: Command::SetGoal(first.clone(), Some(goal)), reply })
                .unwrap();
            answers.push(answer);
        }
        let (reply, mut landed) = oneshot::channel();
        urgent.send(Request { command: Command::Land(Some(first.clone())), reply }).unwrap();

        assert!(engine.apply_commands());
        assert_eq!(landed.try_recv().unwrap(), Ok(Outcome::Done), "the land request was applied");
        assert_eq!(engine.fleet.uavs()[0].link.phase(), LinkPhase::Landing);
        let applied = answers.iter_mut().map(|a| a.try_recv().is_ok()).filter(|done| *done).count();
        assert_eq!(applied, MAX_COMMANDS_PER_TICK, "the rest wait for the next gap between ticks");
    }
}
