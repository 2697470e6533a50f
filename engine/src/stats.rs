//! Per-tick statistics of the fleet loop (`GET /api/metrics`): a bounded window of tick durations
//! for percentiles, running counters and the smallest safety margins seen.

use super::snapshot::Snapshot;
use super::tick_counts::{TickCounts, min_opt};
use fleet::Fleet;
use serde::Serialize;
use std::collections::VecDeque;

/// Ticks kept for the duration percentiles (one minute at 20 Hz).
pub const WINDOW_TICKS: usize = 1200;

/// Tick durations over the window (µs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, schemars::JsonSchema)]
pub struct DurationStats {
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Largest in the window.
    pub max_us: f64,
}

/// Where a tick's time goes (`stages` in `GET /api/metrics`): the mean over the window of each
/// stage of the fleet's tick (ARCHITECTURE.md, "One tick"), of building the snapshot, and of what the
/// loop does after the tick's duration is taken (its statistics, publishing), all in µs.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, schemars::JsonSchema)]
pub struct TickStages {
    /// Reading every link's state.
    pub read_us: f64,
    /// The neighbour search.
    pub neighbours_us: f64,
    /// Navigation and the traffic rules.
    pub navigation_us: f64,
    /// The policies and the speed limits.
    pub policies_us: f64,
    /// Building every UAV's rows.
    pub rows_us: f64,
    /// The CBF-QP filter.
    pub filter_us: f64,
    /// Sending every command.
    pub send_us: f64,
    /// Building the snapshot (the last part of the tick's duration).
    pub snapshot_us: f64,
    /// The rest of the tick's duration (a region's work before the tick, bookkeeping).
    pub other_us: f64,
    /// After the tick's duration: these statistics, publishing the snapshot and metrics (not in
    /// the tick's duration, but on the loop's thread before the next tick).
    pub publish_us: f64,
}

impl TickStages {
    /// Each stage of `self` and `other` combined by `f`.
    fn combine(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self {
            read_us: f(self.read_us, other.read_us),
            neighbours_us: f(self.neighbours_us, other.neighbours_us),
            navigation_us: f(self.navigation_us, other.navigation_us),
            policies_us: f(self.policies_us, other.policies_us),
            rows_us: f(self.rows_us, other.rows_us),
            filter_us: f(self.filter_us, other.filter_us),
            send_us: f(self.send_us, other.send_us),
            snapshot_us: f(self.snapshot_us, other.snapshot_us),
            other_us: f(self.other_us, other.other_us),
            publish_us: f(self.publish_us, other.publish_us),
        }
    }

    /// The fleet's stages of one tick with the loop's: `snapshot_us` building the snapshot, `total_us`
    /// the tick's duration (the rest is `other_us`), `publish_us` the work after it.
    pub fn of_tick(fleet: fleet::StageTimes, snapshot_us: f64, total_us: f64, publish_us: f64) -> Self {
        let f = fleet;
        let counted = f.read_us
            + f.neighbours_us
            + f.navigation_us
            + f.policies_us
            + f.rows_us
            + f.filter_us
            + f.send_us
            + snapshot_us;
        Self {
            read_us: f.read_us,
            neighbours_us: f.neighbours_us,
            navigation_us: f.navigation_us,
            policies_us: f.policies_us,
            rows_us: f.rows_us,
            filter_us: f.filter_us,
            send_us: f.send_us,
            snapshot_us,
            other_us: (total_us - counted).max(0.0),
            publish_us,
        }
    }
}

/// Solver counters since the server started.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, schemars::JsonSchema)]
pub struct QpCounters {
    /// QPs solved.
    pub solves: u64,
    /// Solves that needed a slack above 1e-6.
    pub slack_used: u64,
    /// Largest slack seen.
    pub max_slack: f64,
    /// Failed solves (the UAV braked).
    pub failures: u64,
}

/// Links with an error listed by UAV in `GET /api/metrics` (`links.errors`; the count of all is
/// `links.with_error`).
pub const LISTED_LINK_ERRORS: usize = 16;

/// A link's last error, as `links.errors` of `GET /api/metrics` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct LinkError {
    /// The UAV.
    pub id: String,
    /// Its link.
    pub link: String,
    /// What went wrong last.
    pub error: String,
}

/// The UAVs' links (`links` in `GET /api/metrics`), counted every tick.
#[derive(Debug, Clone, PartialEq, Default, Serialize, schemars::JsonSchema)]
pub struct LinkCounters {
    /// UAVs flown over a Crazyflie link (the others are simulated in process).
    pub crazyflies: u64,
    /// Links whose last error is set now (see `link_error` in the UAV's snapshot).
    pub with_error: u64,
    /// Emergency stops and landings given up on without the Crazyflie's confirmation, summed over
    /// the current links.
    pub unconfirmed_commands: u64,
    /// Crazyflies whose supervisor says locked (they fly again only after a reboot).
    pub locked: u64,
    /// Crazyflies whose supervisor says tumbled or crashed.
    pub tumbled_or_crashed: u64,
    /// The lowest battery voltage among the Crazyflies that reported one (V).
    pub min_battery_v: Option<f64>,
    /// The lowest link quality among the Crazyflies that reported one (0–1).
    pub min_link_quality: Option<f64>,
    /// The first [`LISTED_LINK_ERRORS`] links with an error, in fleet order. The loop leaves it
    /// empty (filling it would allocate every tick while links fail); `GET /api/metrics` fills it
    /// from the snapshot it answers with ([`LinkCounters::list_errors`]).
    pub errors: Vec<LinkError>,
}

impl LinkCounters {
    /// Lists the first [`LISTED_LINK_ERRORS`] links of `snapshot` with an error.
    pub fn list_errors(&mut self, snapshot: &Snapshot) {
        let failing = snapshot.uavs.iter().filter_map(|u| {
            let error = u.link_error.clone()?;
            Some(LinkError { id: u.id.to_string(), link: u.link.to_string(), error })
        });
        self.errors = failing.take(LISTED_LINK_ERRORS).collect();
    }
}

/// The document of `GET /api/metrics`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, schemars::JsonSchema)]
pub struct LoopMetrics {
    /// Ticks run.
    pub ticks: u64,
    /// Control period dt (s).
    pub dt: f64,
    /// Tick durations over the last [`WINDOW_TICKS`] ticks.
    pub tick: DurationStats,
    /// Where the ticks of the window spent their time (means).
    pub stages: TickStages,
    /// Duration of the last tick (µs).
    pub last_tick_us: f64,
    /// Ticks whose work took longer than dt (each counted, however long: a stall cannot hide in
    /// the percentiles).
    pub overruns: u64,
    /// The longest tick since the server started (µs).
    pub longest_tick_us: f64,
    /// Tick instants skipped because the loop was late (counted, never bunched).
    pub missed_ticks: u64,
    /// Solver counters.
    pub qp: QpCounters,
    /// UAV-ticks where the policy gave no finite action and the UAV braked.
    pub policy_fallbacks: u64,
    /// UAV-ticks without a fresh state from the link.
    pub stale_states: u64,
    /// Smallest collision margin S_kd seen since the fleet was last loaded (m).
    pub min_collision_margin_m: Option<f64>,
    /// Smallest road margin seen since the fleet was last loaded (m).
    pub min_road_margin_m: Option<f64>,
    /// Commands (REST changes) applied between ticks.
    pub commands_applied: u64,
    /// UAV-seconds stalled since the server started: flying with a goal and no progress towards it
    /// for at least 1 s (as `stall_s` in METRICS.json).
    pub stall_s: f64,
    /// UAVs stalled now.
    pub stalled_uavs: u64,
    /// The longest stall going on now (s).
    pub longest_stall_s: f64,
    /// The UAVs' links.
    pub links: LinkCounters,
}

/// Accumulates [`LoopMetrics`] tick by tick without allocating.
#[derive(Debug)]
pub struct TickStats {
    window: VecDeque<f64>,
    /// Each tick's stages over the same window.
    stage_window: VecDeque<TickStages>,
    scratch: Vec<f64>,
    metrics: LoopMetrics,
}

impl TickStats {
    /// No ticks yet; `dt` is the control period.
    pub fn new(dt: f64) -> Self {
        Self {
            window: VecDeque::with_capacity(WINDOW_TICKS),
            stage_window: VecDeque::with_capacity(WINDOW_TICKS),
            scratch: Vec::with_capacity(WINDOW_TICKS),
            metrics: LoopMetrics { dt, ..LoopMetrics::default() },
        }
    }

    /// Forgets the smallest margins (a new road or scenario) and takes the new period.
    pub fn fleet_reloaded(&mut self, dt: f64) {
        self.metrics.dt = dt;
        self.metrics.min_collision_margin_m = None;
        self.metrics.min_road_margin_m = None;
    }

    /// Counts `n` skipped tick instants.
    pub fn missed(&mut self, n: u64) {
        self.metrics.missed_ticks += n;
    }

    /// Counts `n` applied commands.
    pub fn commands(&mut self, n: u64) {
        self.metrics.commands_applied += n;
    }

    /// Records one tick that took `duration_us` and left `fleet` as `snapshot` shows.
    pub fn record(&mut self, duration_us: f64, fleet: &Fleet, snapshot: &Snapshot) {
        let m = &mut self.metrics;
        m.ticks += 1;
        m.last_tick_us = duration_us;
        m.overruns += u64::from(duration_us > m.dt * 1e6);
        m.longest_tick_us = m.longest_tick_us.max(duration_us);
        if self.window.len() == WINDOW_TICKS {
            self.window.pop_front();
        }
        self.window.push_back(duration_us);
        // One pass over the UAVs and their entries, on all cores for a large fleet.
        let c = TickCounts::of(fleet.uavs(), &snapshot.uavs, m.dt);
        m.stall_s += c.stall_s;
        (m.stalled_uavs, m.longest_stall_s) = (c.stalled_uavs, c.longest_stall_s);
        m.qp.solves += c.solves;
        m.qp.slack_used += c.slack_used;
        m.qp.max_slack = m.qp.max_slack.max(c.max_slack);
        m.qp.failures += c.failures;
        m.policy_fallbacks += c.policy_fallbacks;
        m.stale_states += c.stale_states;
        m.links = LinkCounters {
            crazyflies: c.crazyflies,
            with_error: c.with_error,
            unconfirmed_commands: c.unconfirmed_commands,
            locked: c.locked,
            tumbled_or_crashed: c.tumbled_or_crashed,
            min_battery_v: c.min_battery_v,
            min_link_quality: c.min_link_quality,
            errors: Vec::new(),
        };
        m.min_collision_margin_m = min_opt(m.min_collision_margin_m, snapshot.min_collision_margin_m);
        m.min_road_margin_m = min_opt(m.min_road_margin_m, snapshot.min_road_margin_m);
    }

    /// Records where the last tick's time went.
    pub fn stages(&mut self, stages: TickStages) {
        if self.stage_window.len() == WINDOW_TICKS {
            self.stage_window.pop_front();
        }
        self.stage_window.push_back(stages);
    }

    /// The current metrics (percentiles and means over the window).
    pub fn metrics(&mut self) -> LoopMetrics {
        self.scratch.clear();
        self.scratch.extend(self.window.iter().copied());
        let mut m = self.metrics.clone();
        m.tick = percentiles(&mut self.scratch);
        let sum =
            self.stage_window.iter().fold(TickStages::default(), |sum, &t| sum.combine(t, |a, b| a + b));
        let n = self.stage_window.len().max(1) as f64;
        m.stages = sum.combine(TickStages::default(), |total, _| total / n);
        m
    }
}

/// p50, p99 and max of `values` (reordered); zeros when empty.
pub fn percentiles(values: &mut [f64]) -> DurationStats {
    if values.is_empty() {
        return DurationStats::default();
    }
    let at = |values: &mut [f64], q: f64| {
        let i = ((values.len() - 1) as f64 * q).round() as usize;
        *values.select_nth_unstable_by(i, f64::total_cmp).1
    };
    let p50_us = at(values, 0.5);
    let p99_us = at(values, 0.99);
    let max_us = values.iter().copied().fold(0.0, f64::max);
    DurationStats { p50_us, p99_us, max_us }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_one_to_hundred() {
        let mut v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        let s = percentiles(&mut v);
        assert_eq!((s.p50_us, s.p99_us, s.max_us), (51.0, 99.0, 100.0));
        assert_eq!(percentiles(&mut []), DurationStats::default());
    }

    #[test]
    fn stages_are_means_over_the_window() {
        let mut stats = TickStats::new(0.05);
        assert_eq!(stats.metrics().stages, TickStages::default(), "no tick yet");
        let tick = |us: f64| TickStages { rows_us: us, publish_us: 2.0 * us, ..TickStages::default() };
        stats.stages(tick(10.0));
        stats.stages(tick(30.0));
        let stages = stats.metrics().stages;
        assert_eq!((stages.rows_us, stages.publish_us, stages.filter_us), (20.0, 40.0, 0.0));
        for _ in 0..WINDOW_TICKS {
            stats.stages(tick(5.0));
        }
        assert_eq!(stats.metrics().stages.rows_us, 5.0, "older ticks leave the window");
    }
}
