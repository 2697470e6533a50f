//! The repair pass after the filter stage (docs/safety.md §10.6). Under the sequential share (§2)
//! the UAV filtered first on a pair enforces only its share δ_k/(δ_k+δ_d) of the pair row b_kd and
//! trusts the later one d to cover the rest given u_k. When d cannot (boxed in by a UAV ahead, a wall
//! and ‖u‖ ≤ δ), its QP takes slack and the pair's distance closes on D_c, although k (say, a fast
//! UAV closing in from behind) could have braked harder. The ground station sees every input, so it
//! fixes this after the pass: a UAV with a violated urgent row is filtered again with the **whole**
//! pair row against every cooperating neighbour, given the neighbours' current inputs (block
//! Gauss–Seidel on the fleet's rows), round after round along the UAVs next to each change.
//!
//! Invariant: a UAV's input changes only if the violation of its own rows (road rows and whole pair
//! rows), `Σ w·max(0, aᵀu_k − c)` with the QP's slack weights w, strictly drops. A pair row and its
//! weight read the same from both UAVs (the right-hand side is symmetric, §2) and u_k enters only
//! k's rows, so that drop is the drop of the fleet's total violation (each pair row counted once):
//! the total never grows, and the pass cannot make a tick less safe by that measure. UAVs
//! whose QPs took no slack are not visited, so it costs nothing in free flight; it runs in index
//! order on one thread, so runs stay the same on any number of threads.

use crate::tick::rows::RowBuilder;
use safety::{FilterSettings, Row, SafetyFilter};
use uav::{Params, Vec2};

/// Rounds of the pass: each round visits the UAVs next to a change of the round before.
const ROUNDS: usize = 4;

/// A violation below this (m/s²) counts as met (the QP's own tolerance is about 10⁻⁹).
const MET: f64 = 1e-7;

/// Rows with a barrier value b below this (m/s) are urgent; only a violated urgent row starts a
/// repair (a violated row with a comfortable b lets b fall faster this tick, not below 0, and
/// repairing those too made the fleet slower: BENCHMARKS.md "Traffic rules").
const URGENT_B: f64 = 1.0;

/// The weighted violation `Σ w·max(0, aᵀu − c)` of `rows` at `u`, w the QP's slack weight.
fn violation(rows: &[Row], u: Vec2, settings: &FilterSettings) -> f64 {
    rows.iter().map(|r| (r.a.dot(&u) - r.c).max(0.0) * settings.slack_weights(r).1).sum()
}

/// Whether some urgent row of `rows` is violated at `u`.
fn urgent(rows: &[Row], u: Vec2) -> bool {
    rows.iter().any(|r| r.b < URGENT_B && r.a.dot(&u) - r.c > MET)
}

/// What the pass changed for one UAV (its new input is in the pass's `inputs`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Repaired {
    /// The UAV's index.
    pub k: usize,
    /// The largest slack of its last repairing QP.
    pub max_slack: f64,
    /// Rows binding at the new input.
    pub active_rows: usize,
}

/// The pass's buffers, reused from tick to tick.
#[derive(Debug, Default)]
pub(crate) struct Repair {
    /// The UAVs to visit this round, and those next to a change (for the next round).
    visit: Vec<usize>,
    next: Vec<usize>,
    /// Whether a UAV is listed in `visit` (while building it) or `next` (during a round).
    listed: Vec<bool>,
    /// Each UAV's entry in `repaired`, if it has one.
    slot: Vec<Option<usize>>,
    rows: Vec<Row>,
    /// What the last pass changed, one entry per UAV changed (its last change).
    pub repaired: Vec<Repaired>,
}

impl Repair {
    /// Runs the pass from the UAVs in `slacked` (whose QPs took slack) and the cooperating flying
    /// UAVs they share pair rows with. `nominal(k)` is UAV k's u_ref, `inputs[k]` its filtered input
    /// (updated in place).
    pub fn run(
        &mut self,
        slacked: impl Iterator<Item = usize>,
        rows: &RowBuilder,
        nominal: impl Fn(usize) -> Vec2,
        inputs: &mut [Vec2],
        p: &Params,
        filter: &mut SafetyFilter,
    ) {
        let settings = filter.settings;
        let partners = |k: usize| rows.partners(k).iter().copied().filter(|&d| rows.view(d).cooperates);
        // Every list holds each UAV at most once: sized once for the fleet, they do not grow.
        let n = inputs.len();
        for list in [&mut self.visit, &mut self.next] {
            list.clear();
            list.reserve(n);
        }
        self.repaired.clear();
        self.repaired.reserve(n);
        self.listed.clear();
        self.listed.resize(n, false);
        self.slot.clear();
        self.slot.resize(n, None);
        for k in slacked {
            list_once(&mut self.visit, &mut self.listed, k);
            for d in partners(k) {
                list_once(&mut self.visit, &mut self.listed, d);
            }
        }
        for _ in 0..ROUNDS {
            if self.visit.is_empty() {
                break;
            }
            self.visit.sort_unstable();
            for &k in &self.visit {
                self.listed[k] = false;
            }
            self.next.clear();
            for &k in &self.visit {
                let me = rows.view(k);
                if !me.flying {
                    continue;
                }
                let my_rows = rows.rows_of(k, p.delta, |_| true, |d| inputs[d], &mut self.rows);
                if !urgent(my_rows, inputs[k]) {
                    continue;
                }
                let before = violation(my_rows, inputs[k], &settings);
                let outcome = filter.filter(nominal(k), me.state.v, my_rows, p.delta, p.dt);
                if outcome.failed || violation(my_rows, outcome.u, &settings) >= before - MET {
                    continue;
                }
                inputs[k] = outcome.u;
                let repaired = Repaired { k, max_slack: outcome.max_slack, active_rows: outcome.active_rows };
                match self.slot[k] {
                    Some(i) => self.repaired[i] = repaired,
                    None => {
                        self.slot[k] = Some(self.repaired.len());
                        self.repaired.push(repaired);
                    }
                }
                for d in partners(k) {
                    list_once(&mut self.next, &mut self.listed, d);
                }
            }
            std::mem::swap(&mut self.visit, &mut self.next);
        }
    }
}

/// Appends `k` to `list` unless `listed` says it is there, and marks it.
fn list_once(list: &mut Vec<usize>, listed: &mut [bool], k: usize) {
    if !listed[k] {
        listed[k] = true;
        list.push(k);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ragged::Ragged;
    use crate::tick::rows::NeighbourLists;
    use proptest::prelude::*;
    use roads::{Road, RoadLayout};
    use safety::RowKind;
    use uav::UavState;

    /// A fleet of UAVs with the given states on a straight road 4 m wide along x from 0 to 20, its
    /// rows for one tick (every UAV a neighbour of every other), and the filter's parameters.
    fn rows_of_fleet(states: &[UavState]) -> (RowBuilder, Params) {
        let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [20.0, 0.0]], &[4.0, 4.0])).unwrap();
        let params = Params::default();
        let config = crate::FleetConfig { params, ..crate::FleetConfig::default() };
        let mut fleet = crate::Fleet::new(config, road, policies::PolicyRegistry::with_pd(params.delta));
        for (k, state) in states.iter().enumerate() {
            let link = Box::new(links::SimLink::new(*state, params.dt));
            fleet.add(format!("u{k}"), "pd".into(), link, *state, Some(Vec2::new(19.0, 0.0)));
        }
        let n = states.len();
        let lists: Ragged<usize> = (0..n).map(|k| (0..n).filter(|&d| d != k).collect()).collect();
        let mut rows = RowBuilder::default();
        let no_foreign = Ragged::default();
        let neighbours = NeighbourLists { own: &lists, foreign: &no_foreign, foreign_disks: &[] };
        // Every UAV was just added with a fresh state: its disk is its position.
        rows.build(&fleet.road, fleet.config.road_rule, &params, &fleet.uavs, neighbours, |u| {
            safety::point_disk(u.state.p)
        });
        (rows, params)
    }

    /// Each UAV's weighted violation of its rows (road rows and whole pair rows) at `inputs`.
    fn violations(rows: &RowBuilder, p: &Params, inputs: &[Vec2]) -> Vec<f64> {
        let (mut scratch, settings) = (Vec::new(), FilterSettings::default());
        (0..inputs.len())
            .map(|k| {
                violation(
                    rows.rows_of(k, p.delta, |_| true, |d| inputs[d], &mut scratch),
                    inputs[k],
                    &settings,
                )
            })
            .collect()
    }

    /// The fleet's weighted violation at `inputs`, each pair row counted once (half from each of
    /// its UAVs): the sum the pass lowers.
    fn fleet_violation(rows: &RowBuilder, p: &Params, inputs: &[Vec2]) -> f64 {
        let (mut scratch, settings) = (Vec::new(), FilterSettings::default());
        (0..inputs.len())
            .map(|k| {
                let my_rows = rows.rows_of(k, p.delta, |_| true, |d| inputs[d], &mut scratch);
                let half = |r: &Row| if matches!(r.kind, RowKind::Collision(_)) { 0.5 } else { 1.0 };
                my_rows
                    .iter()
                    .map(|r| half(r) * violation(std::slice::from_ref(r), inputs[k], &settings))
                    .sum::<f64>()
            })
            .sum()
    }

    #[test]
    fn a_fast_uav_closing_on_a_boxed_in_one_brakes_for_both() {
        // u0 closes at 0.7 m/s on u1, 0.44 m ahead (b_kd ≈ 0.97 m/s: full braking by one UAV is
        // still enough), which does not move (input 0, its QP took slack); u0, filtered first, had
        // braked by its share only (here: not at all).
        let states = [
            UavState { p: Vec2::new(9.56, 0.0), v: Vec2::new(0.7, 0.0) },
            UavState { p: Vec2::new(10.0, 0.0), v: Vec2::new(0.0, 0.0) },
        ];
        let (rows, p) = rows_of_fleet(&states);
        let mut inputs = [Vec2::zeros(), Vec2::zeros()];
        let b = rows.built(0).iter().find(|r| r.kind == RowKind::Collision(1)).map(|r| r.b);
        assert!(b.is_some_and(|b| b < URGENT_B), "an urgent pair row: b = {b:?}");
        assert_eq!((rows.partners(0), rows.partners(1)), (&[1][..], &[0][..]), "the pair is known");
        assert!(violations(&rows, &p, &inputs)[0] > MET, "the pair row is violated");
        let mut repair = Repair::default();
        let mut filter = SafetyFilter::new(FilterSettings::default());
        repair.run([1].into_iter(), &rows, |_| Vec2::zeros(), &mut inputs, &p, &mut filter);
        assert!(inputs[0].x < -1.0, "u0 brakes: {:?}", inputs[0]);
        assert_eq!(inputs[1], Vec2::zeros(), "u1 is left alone");
        assert!(violations(&rows, &p, &inputs).iter().all(|&v| v <= MET), "every row met");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// After a sequential pass (index order, as the filter stage runs it) from random nominal
        /// inputs, the repair never raises the fleet's total weighted violation (each pair row
        /// counted once) and keeps ‖u‖ ≤ δ: it can only make a tick safer.
        #[test]
        fn the_pass_never_makes_a_tick_less_safe(
            uavs in prop::collection::vec(((4.0..9.0f64, -1.6..1.6f64), (-2.5..2.5f64, -2.5..2.5f64), (-1.0..1.0f64, -1.0..1.0f64)), 2..12),
        ) {
            let params = Params::default();
            let mut states: Vec<UavState> = Vec::new();
            let mut nominal = Vec::new();
            for ((x, y), (vx, vy), (ux, uy)) in uavs {
                let p = Vec2::new(x, y);
                if states.iter().all(|s| (s.p - p).norm() >= params.d_c + 0.01) {
                    states.push(UavState { p, v: Vec2::new(vx, vy) });
                    nominal.push(Vec2::new(ux, uy) * params.delta / 2f64.sqrt());
                }
            }
            let (rows, p) = rows_of_fleet(&states);
            let mut filter = SafetyFilter::new(FilterSettings::default());
            let (mut inputs, mut scratch, mut slacked) = (nominal.clone(), Vec::new(), Vec::new());
            for k in 0..states.len() {
                let my_rows = rows.rows_of(k, p.delta, |d| d < k, |d| inputs[d], &mut scratch);
                let out = filter.filter(nominal[k], states[k].v, my_rows, p.delta, p.dt);
                inputs[k] = out.u;
                if out.max_slack > 0.0 {
                    slacked.push(k);
                }
            }
            let total_before = fleet_violation(&rows, &p, &inputs);
            let mut repair = Repair::default();
            repair.run(slacked.into_iter(), &rows, |k| nominal[k], &mut inputs, &p, &mut filter);
            let total_after = fleet_violation(&rows, &p, &inputs);
            prop_assert!(total_after <= total_before * (1.0 + 1e-12) + 1e-9, "{total_before} -> {total_after}");
            for u in &inputs {
                prop_assert!(u.norm() <= p.delta + 1e-9);
            }
        }
    }
}
