//! Safety metrics of a run, accumulated per tick, and the METRICS.json document.

use crate::fleet::Fleet;
use crate::member::Uav;
use crate::progress::stall_time_added;
use crate::ragged::Ragged;
use crate::runs::histogram::DurationHistogram;
use crate::runs::margins::UavMargins;
use crate::tick::parallel;
use rayon::prelude::*;
use roads::Airspace;
use serde::Serialize;
use std::collections::BTreeMap;
use uav::{Params, UavState};

/// Solver statistics of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QpMetrics {
    /// QPs solved (ticks where the nominal input was already safe need none).
    pub solves: u64,
    /// Solves with a slack above 1e-6.
    pub slack_used: u64,
    /// Largest slack seen.
    pub max_slack: f64,
    /// Solves that failed (the UAV braked).
    pub failures: u64,
    /// Median filter time per solved UAV (µs, within 1 %).
    pub p50_us: f64,
    /// 99th percentile filter time per solved UAV (µs, within 1 %).
    pub p99_us: f64,
}

/// The METRICS.json document of a headless run (exactly these keys).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunMetrics {
    /// Scenario name.
    pub scenario: String,
    /// Ticks run.
    pub ticks: u64,
    /// Simulated time (s).
    pub sim_time_s: f64,
    /// Every UAV reached its goal.
    pub all_arrived: bool,
    /// Arrival time per UAV id (s), null if it never arrived.
    pub arrival_time_s: BTreeMap<String, Option<f64>>,
    /// UAV-seconds spent stalled: with a goal, flying, and no progress towards it for at least
    /// [`crate::progress::STALL_AFTER_S`] (counted from the last progress).
    pub stall_s: f64,
    /// The longest single stall (s).
    pub max_stall_s: f64,
    /// The longest a UAV waited for its turn at the head of its line at a conflict zone (a
    /// single-file section, a junction or a merge of a network) (s).
    pub max_wait_s: f64,
    /// min over time and pairs of S_kd (eq. 2, corrected sign), over the pairs within each tick's
    /// neighbour radius (every other pair's S_kd is above D_c); null when no two UAVs came that close.
    pub min_collision_margin_m: Option<f64>,
    /// min over time, UAVs and walls of S_kij (eq. 6) to the finite walls.
    pub min_road_margin_m: f64,
    /// Smallest distance between two UAVs within a tick's neighbour radius; null as above.
    pub min_separation_m: Option<f64>,
    /// Smallest distance of a UAV to a wall (negative when outside).
    pub min_wall_distance_m: f64,
    /// UAV-ticks spent outside the road.
    pub steps_outside_road: u64,
    /// Solver statistics.
    pub qp: QpMetrics,
    /// Margins ≥ D_c and D_s, no step outside, no failure.
    pub safe: bool,
}

/// One stall of one UAV: no progress towards its goal for `duration_s` from `start_s`.
#[derive(Debug, Clone, PartialEq)]
pub struct Stall {
    /// The UAV.
    pub id: String,
    /// When its last progress was (s of the run).
    pub start_s: f64,
    /// How long it lasted (s).
    pub duration_s: f64,
    /// Where the UAV was when it was detected.
    pub at: [f64; 2],
}

/// A [`Stall`] as recorded, its UAV by index.
#[derive(Debug, Clone, Copy)]
struct StallRecord {
    uav: usize,
    start_s: f64,
    duration_s: f64,
    at: [f64; 2],
}

/// Accumulates metrics tick by tick.
#[derive(Debug, Default)]
pub struct MetricsRecorder {
    min_collision: Option<f64>,
    min_separation: Option<f64>,
    min_road: f64,
    min_wall: f64,
    outside: u64,
    solves: u64,
    slack_used: u64,
    max_slack: f64,
    failures: u64,
    /// Policy outputs replaced by braking (reported in the summary).
    pub policy_fallbacks: u64,
    solve_us: DurationHistogram,
    /// First arrival time by UAV index (a headless run never removes UAVs).
    arrival: Vec<Option<f64>>,
    stall_s: f64,
    max_stall_s: f64,
    max_wait_s: f64,
    /// Stalls going on, by UAV index (a headless run never removes UAVs), and those that ended, each
    /// with its UAV's index (the id is looked up when they are read: no string copied per stall).
    ongoing: Vec<Option<StallRecord>>,
    stalls: Vec<StallRecord>,
    /// Scratch: each UAV's state and tracked segment, and its margins, this tick.
    states: Vec<(Option<UavState>, Option<usize>)>,
    margins: Vec<UavMargins>,
}

fn min_opt(a: Option<f64>, b: f64) -> Option<f64> {
    Some(a.map_or(b, |a| a.min(b)))
}

impl MetricsRecorder {
    /// A recorder with no observation yet.
    pub fn new() -> Self {
        Self { min_road: f64::INFINITY, min_wall: f64::INFINITY, ..Self::default() }
    }

    /// Records the states the fleet read in its last tick (time `t`) and what the filter did.
    pub fn record(&mut self, fleet: &Fleet, t: f64) {
        self.record_with(fleet, t, None);
    }

    /// Records what the filter did in the fleet's last tick (time `t`) and the margins of `truth`,
    /// the UAVs' true states in the fleet's order (a physics simulation's ground truth), instead of
    /// the states the fleet read; `None` for a UAV not in the air (landed, or fallen after a fault),
    /// which has no margins. A `truth` of another length is ignored (the fleet's are used).
    pub fn record_truth(&mut self, fleet: &Fleet, t: f64, truth: &[Option<UavState>]) {
        self.record_with(fleet, t, Some(truth));
    }

    /// Each UAV's margins on its own into `margins`, at `truth` when it has a state per UAV, else
    /// at the fleet's states (in parallel for large fleets; a minimum does not depend on the order).
    fn measure_margins(
        &mut self,
        road: &Airspace,
        p: &Params,
        uavs: &[Uav],
        lists: &Ragged<usize>,
        truth: Option<&[Option<UavState>]>,
    ) {
        self.states.clear();
        match truth.filter(|truth| truth.len() == uavs.len()) {
            // No segment hint: the estimate's segment need not hold the true position.
            Some(truth) => self.states.extend(truth.iter().map(|s| (*s, None))),
            // On a network, the cell of the UAV's way (a hint only: any gives the same margins).
            None => self.states.extend(
                uavs.iter().map(|u| (Some(u.state), u.nav.way().map(|w| w.cell()).or(u.nav.tracker.current))),
            ),
        }
        let states = &self.states;
        let margins_of = |(k, &(state, hint)): (usize, &(Option<UavState>, Option<usize>))| {
            let Some(state) = state else { return UavMargins::NONE };
            // The pairs of this tick's neighbour search: any other pair is farther apart than the
            // activation radius at twice the fleet's top speed, so its S_kd exceeds D_c.
            let later = lists
                .get(k)
                .into_iter()
                .flatten()
                .filter(|&&d| d > k)
                .filter_map(|&d| states.get(d)?.0.as_ref());
            UavMargins::of(road, hint, &state, p.delta, later)
        };
        if parallel(states.len()) {
            states.par_iter().enumerate().map(margins_of).collect_into_vec(&mut self.margins);
        } else {
            self.margins.clear();
            self.margins.extend(states.iter().enumerate().map(margins_of));
        }
    }

    fn record_with(&mut self, fleet: &Fleet, t: f64, truth: Option<&[Option<UavState>]>) {
        let p = fleet.config.params;
        let road = fleet.airspace();
        let uavs = fleet.uavs();
        let lists = fleet.neighbour_lists();
        // The fleet's states: their margins as the tick's rows stage recorded them, if it still
        // has those states (one pass over the walls and pairs per tick, not two).
        let rows = &fleet.pipeline.rows;
        let built = truth.is_none() && rows.margins_hold_for(uavs);
        if !built {
            self.measure_margins(road, &p, uavs, lists, truth);
        }
        for (k, u) in uavs.iter().enumerate() {
            // `margins_hold_for`: the rows stage has margins for every UAV.
            let m = if built { rows.margins(k).unwrap_or(UavMargins::NONE) } else { self.margins[k] };
            self.min_wall = self.min_wall.min(m.wall);
            self.outside += u64::from(m.wall < 0.0);
            self.min_road = self.min_road.min(m.road_margin);
            if let Some((collision, separation)) = m.closest {
                self.min_collision = min_opt(self.min_collision, collision);
                self.min_separation = min_opt(self.min_separation, separation);
            }
            let last = &u.last;
            self.stall_s += stall_time_added(last.stall_s, p.dt);
            self.max_stall_s = self.max_stall_s.max(last.stall_s);
            if let Some(since) = u.traffic.front_since {
                self.max_wait_s = self.max_wait_s.max(t - since);
            }
            if self.ongoing.len() <= k {
                self.ongoing.resize(k + 1, None);
            }
            match (&mut self.ongoing[k], last.stall_s > 0.0) {
                (Some(stall), true) => stall.duration_s = last.stall_s,
                (slot @ None, true) => {
                    let at = [u.state.p.x, u.state.p.y];
                    *slot =
                        Some(StallRecord { uav: k, start_s: t - last.stall_s, duration_s: last.stall_s, at });
                }
                (slot @ Some(_), false) => self.stalls.extend(slot.take()),
                (None, false) => {}
            }
            if last.solved {
                self.solves += 1;
                self.solve_us.record(last.solve_us);
            }
            self.slack_used += u64::from(last.max_slack > 1e-6);
            self.max_slack = self.max_slack.max(last.max_slack);
            self.failures += u64::from(last.failed);
            self.policy_fallbacks += u64::from(last.policy_fallback);
            if self.arrival.len() <= k {
                self.arrival.resize(k + 1, None);
            }
            if u.nav.arrived && self.arrival[k].is_none() {
                self.arrival[k] = Some(t);
            }
        }
    }

    /// Every stall so far (those going on included) of the UAVs of `fleet`, longest first.
    pub fn stalls(&self, fleet: &Fleet) -> Vec<Stall> {
        let id = |k: usize| fleet.uavs().get(k).map(|u| u.id.clone()).unwrap_or_default();
        let recorded = self.stalls.iter().chain(self.ongoing.iter().flatten());
        let mut all: Vec<Stall> = recorded
            .map(|r| Stall { id: id(r.uav), start_s: r.start_s, duration_s: r.duration_s, at: r.at })
            .collect();
        all.sort_by(|a, b| b.duration_s.total_cmp(&a.duration_s));
        all
    }

    /// The METRICS.json document.
    pub fn finish(self, fleet: &Fleet, scenario: &str) -> RunMetrics {
        let p = fleet.config.params;
        let arrival: BTreeMap<String, Option<f64>> = fleet
            .uavs()
            .iter()
            .enumerate()
            .map(|(k, u)| (u.id.clone(), self.arrival.get(k).copied().flatten()))
            .collect();
        let pct = |q: f64| self.solve_us.quantile(q);
        let qp = QpMetrics {
            solves: self.solves,
            slack_used: self.slack_used,
            max_slack: self.max_slack,
            failures: self.failures,
            p50_us: pct(0.5),
            p99_us: pct(0.99),
        };
        let safe = self.min_collision.is_none_or(|m| m >= p.d_c)
            && self.min_road >= p.d_s
            && self.outside == 0
            && self.failures == 0;
        RunMetrics {
            scenario: scenario.to_string(),
            ticks: fleet.ticks(),
            sim_time_s: fleet.ticks() as f64 * p.dt,
            all_arrived: arrival.values().all(Option::is_some),
            arrival_time_s: arrival,
            stall_s: self.stall_s,
            max_stall_s: self.max_stall_s,
            max_wait_s: self.max_wait_s,
            min_collision_margin_m: self.min_collision,
            min_road_margin_m: self.min_road,
            min_separation_m: self.min_separation,
            min_wall_distance_m: self.min_wall,
            steps_outside_road: self.outside,
            qp,
            safe,
        }
    }
}
