//! Safety metrics of a run, accumulated per tick, and the METRICS.json document.

use crate::fleet::Fleet;
use crate::member::Uav;
use crate::ragged::Ragged;
use crate::runs::margins::UavMargins;
use crate::runs::totals::{CHUNK_UAVS, StallRecord, Totals};
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

/// Accumulates metrics tick by tick.
#[derive(Debug, Default)]
pub struct MetricsRecorder {
    /// Everything added up so far.
    totals: Totals,
    /// First arrival time by UAV index (a headless run never removes UAVs).
    arrival: Vec<Option<f64>>,
    /// Stalls going on, by UAV index (a headless run never removes UAVs).
    ongoing: Vec<Option<StallRecord>>,
    /// Scratch: each chunk's totals this tick (a large fleet's, [`CHUNK_UAVS`] UAVs each).
    parts: Vec<Totals>,
    /// Scratch: each UAV's state and tracked segment, and its margins, this tick.
    states: Vec<(Option<UavState>, Option<usize>)>,
    margins: Vec<UavMargins>,
}

/// One chunk of the fleet in [`MetricsRecorder::record_with`]: its place, its totals, and its UAVs'
/// stalls going on and first arrivals.
type ChunkOf<'a> = (usize, ((&'a mut Totals, &'a mut [Option<StallRecord>]), &'a mut [Option<f64>]));

impl MetricsRecorder {
    /// A recorder with no observation yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Policy outputs replaced by braking so far (UAV-ticks; reported in the summary).
    pub fn policy_fallbacks(&self) -> u64 {
        self.totals.policy_fallbacks
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
        let n = uavs.len();
        if self.ongoing.len() < n {
            self.ongoing.resize(n, None);
        }
        if self.arrival.len() < n {
            self.arrival.resize(n, None);
        }
        let margins = &self.margins;
        // `margins_hold_for`: the rows stage has margins for every UAV.
        let margins_of =
            |k: usize| if built { rows.margins(k).unwrap_or(UavMargins::NONE) } else { margins[k] };
        let time = (t, p.dt);
        if !parallel(n) {
            let (ongoing, arrival) = (&mut self.ongoing, &mut self.arrival);
            for (k, u) in uavs.iter().enumerate() {
                self.totals.add((k, u, margins_of(k)), time, &mut ongoing[k], &mut arrival[k]);
            }
            return;
        }
        // Per chunk of consecutive UAVs on all cores, each into its own totals, added up in order.
        let chunks = n.div_ceil(CHUNK_UAVS);
        if self.parts.len() < chunks {
            self.parts.resize_with(chunks, Totals::default);
        }
        let add_chunk = |(c, ((part, ongoing), arrival)): ChunkOf<'_>| {
            part.clear();
            let first = c * CHUNK_UAVS;
            for (i, u) in uavs[first..].iter().take(CHUNK_UAVS).enumerate() {
                part.add((first + i, u, margins_of(first + i)), time, &mut ongoing[i], &mut arrival[i]);
            }
        };
        self.parts[..chunks]
            .par_iter_mut()
            .zip(self.ongoing.par_chunks_mut(CHUNK_UAVS))
            .zip(self.arrival.par_chunks_mut(CHUNK_UAVS))
            .enumerate()
            .for_each(add_chunk);
        for part in &self.parts[..chunks] {
            self.totals.merge(part);
        }
    }

    /// Every stall so far (those going on included) of the UAVs of `fleet`, longest first.
    pub fn stalls(&self, fleet: &Fleet) -> Vec<Stall> {
        let id = |k: usize| fleet.uavs().get(k).map(|u| u.id.clone()).unwrap_or_default();
        let recorded = self.totals.ended.iter().chain(self.ongoing.iter().flatten());
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
        let pct = |q: f64| self.totals.solve_us.quantile(q);
        let m = &self.totals;
        let qp = QpMetrics {
            solves: m.solves,
            slack_used: m.slack_used,
            max_slack: m.max_slack,
            failures: m.failures,
            p50_us: pct(0.5),
            p99_us: pct(0.99),
        };
        let safe = m.min_collision.is_none_or(|c| c >= p.d_c)
            && m.min_road >= p.d_s
            && m.outside == 0
            && m.failures == 0;
        RunMetrics {
            scenario: scenario.to_string(),
            ticks: fleet.ticks(),
            sim_time_s: fleet.ticks() as f64 * p.dt,
            all_arrived: arrival.values().all(Option::is_some),
            arrival_time_s: arrival,
            stall_s: m.stall_s,
            max_stall_s: m.max_stall_s,
            max_wait_s: m.max_wait_s,
            min_collision_margin_m: m.min_collision,
            min_road_margin_m: m.min_road,
            min_separation_m: m.min_separation,
            min_wall_distance_m: m.min_wall,
            steps_outside_road: m.outside,
            qp,
            safe,
        }
    }
}
