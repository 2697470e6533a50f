//! Per-tick statistics of the fleet loop (`GET /api/metrics`): a bounded window of tick durations
//! for percentiles, running counters and the smallest safety margins seen.

use super::snapshot::Snapshot;
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
    scratch: Vec<f64>,
    metrics: LoopMetrics,
}

fn min_opt(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

impl TickStats {
    /// No ticks yet; `dt` is the control period.
    pub fn new(dt: f64) -> Self {
        Self {
            window: VecDeque::with_capacity(WINDOW_TICKS),
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
        (m.stalled_uavs, m.longest_stall_s, m.links) = (0, 0.0, LinkCounters::default());
        for u in fleet.uavs() {
            let l = &u.last;
            // As METRICS.json counts it.
            m.stall_s += fleet::progress::stall_time_added(l.stall_s, m.dt);
            m.stalled_uavs += u64::from(l.stall_s > 0.0);
            m.longest_stall_s = m.longest_stall_s.max(l.stall_s);
            m.qp.solves += u64::from(l.solved);
            m.qp.slack_used += u64::from(l.max_slack > 1e-6);
            m.qp.max_slack = m.qp.max_slack.max(l.max_slack);
            m.qp.failures += u64::from(l.failed);
            m.policy_fallbacks += u64::from(l.policy_fallback);
            m.stale_states += u64::from(u.stale_ticks > 0);
            m.links.unconfirmed_commands += u.link.unconfirmed_commands();
        }
        // The snapshot already read each link's description and error this tick (an error is a
        // string behind the session's lock: read it once per tick, not twice).
        for u in &snapshot.uavs {
            m.links.crazyflies += u64::from(*u.link != *links::SIM_LINK);
            m.links.with_error += u64::from(u.link_error.is_some());
            if let Some(f) = &u.firmware {
                m.links.locked += u64::from(f.locked);
                m.links.tumbled_or_crashed += u64::from(f.tumbled || f.crashed);
                m.links.min_battery_v = min_opt(m.links.min_battery_v, f.battery_v);
                m.links.min_link_quality = min_opt(m.links.min_link_quality, f.link_quality);
            }
        }
        m.min_collision_margin_m = min_opt(m.min_collision_margin_m, snapshot.min_collision_margin_m);
        m.min_road_margin_m = min_opt(m.min_road_margin_m, snapshot.min_road_margin_m);
    }

    /// The current metrics (percentiles over the window).
    pub fn metrics(&mut self) -> LoopMetrics {
        self.scratch.clear();
        self.scratch.extend(self.window.iter().copied());
        let mut m = self.metrics.clone();
        m.tick = percentiles(&mut self.scratch);
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
}
