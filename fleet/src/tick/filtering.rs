//! The filter stage on all cores. The sequential share (a UAV enforces the whole pair row b_kd
//! against a neighbour d filtered before it in the tick, given its u_d, and its share
//! δ_k/(δ_k+δ_d) against the others: docs/safety.md §10.3) is defined by index order: of two UAVs
//! with a pair row, the one with the smaller index filters first. UAVs are put in levels: a UAV's
//! level is one more than the highest level of the UAVs with a smaller index it has a pair row
//! with, so two UAVs of one level never share a pair row and every pair keeps its index order.
//! Levels filter one after the other, the UAVs of a level in parallel (none reads the input of
//! another of its level). A UAV at level [`LEVELS`] or deeper (a long chain of pair rows running up
//! the indices) joins the tail, which filters after every level, one UAV at a time in index order.
//! So every pair is enforced exactly as in index order (the same inputs bit for bit), and the
//! levels depend on the rows only: runs are the same on any number of threads. Large fleets are
//! cut into chunks of consecutive indices ([`UAVS_PER_CHUNK`]), each chunk's levels filtered
//! before the next chunk's (its levels count pairs within it only): index order still holds on
//! every pair, and each chunk's rows stay in the cache through its levels. (A greedy colouring
//! gives fewer levels, but a UAV of the first colour enforces only shares, like `split`; tried once
//! while this was written, not kept, it failed `fleet/tests/stress.rs`: a violation in `headon`, 267
//! instead of at least 271 arrivals in `mixed`.)

use crate::tick::TickState;
use crate::tick::repair::Repair;
use crate::tick::rows::RowBuilder;
use crate::tick::{map_into, parallel};
use rayon::prelude::*;
use safety::{Row, SafetyFilter};
use uav::{Params, Vec2};

/// Levels of the filter's order; the tail (level `LEVELS`) filters one UAV at a time.
const LEVELS: usize = 64;

/// UAVs of one chunk of the filter's order (consecutive indices, whose levels filter one after the
/// other before the next chunk's): their rows (about 0.5 kB a UAV) stay in the cache through the
/// chunk's levels, where levels over the whole fleet would sweep all of them once per level (at
/// 100,000 UAVs, 48 MB about 17 times a tick).
const UAVS_PER_CHUNK: usize = 16_384;

/// The fewest UAVs of one level handed to one parallel task (fewer filter on the calling thread).
const MIN_UAVS_PER_TASK: usize = 32;

/// The filter's order for one tick: chunk after chunk, level after level within a chunk, by index
/// within a level.
#[derive(Debug, Default)]
pub(crate) struct FilterOrder {
    /// Each UAV's level within its chunk (`LEVELS`: the chunk's tail).
    level: Vec<u8>,
    /// The lowest level a UAV may take: one above each UAV of its chunk with a smaller index and a
    /// pair row with it, as far as those have been placed.
    floor: Vec<u8>,
    /// UAV indices by (chunk, level, index).
    order: Vec<usize>,
    /// `starts[c·(LEVELS + 1) + l]..starts[c·(LEVELS + 1) + l + 1]`: the UAVs of chunk c's level l
    /// in `order`.
    starts: Vec<usize>,
    /// The counting sort's next place of each (chunk, level).
    cursor: Vec<usize>,
}

impl FilterOrder {
    /// Places the `n` UAVs whose rows `rows` built: k and d have a pair row when one has a collision
    /// row with the other and both fly (its pair partners; only a flying neighbour's u_d is ever
    /// read).
    fn plan(&mut self, rows: &RowBuilder, n: usize) {
        self.place(n, UAVS_PER_CHUNK, |k| rows.view(k).flying, |k| rows.partners(k).iter().copied());
    }

    /// Places `n` UAVs in chunks of `chunk` consecutive indices, given which fly and, for each
    /// flying UAV, the flying UAVs it has a pair row with (`pairs(k)`; a pair may be listed by one
    /// of its UAVs only). A pair across chunks keeps index order by the chunks' order alone.
    fn place<I: Iterator<Item = usize>>(
        &mut self,
        n: usize,
        chunk: usize,
        flying: impl Fn(usize) -> bool,
        pairs: impl Fn(usize) -> I,
    ) {
        self.level.clear();
        self.level.resize(n, 0);
        self.floor.clear();
        self.floor.resize(n, 0);
        let above = |l: u8| (l + 1).min(LEVELS as u8);
        for k in (0..n).filter(|&k| flying(k)) {
            let (first, end) = (k / chunk * chunk, (k / chunk + 1) * chunk);
            let earlier = pairs(k).filter(|&d| (first..k).contains(&d));
            let level = earlier.fold(self.floor[k], |l, d| l.max(above(self.level[d])));
            self.level[k] = level;
            for d in pairs(k).filter(|&d| d > k && d < end) {
                self.floor[d] = self.floor[d].max(above(level));
            }
        }
        // Counting sort by (chunk, level), stable in index.
        let slot = |k: usize, l: u8| k / chunk * (LEVELS + 1) + usize::from(l);
        self.starts.clear();
        self.starts.resize(n.div_ceil(chunk) * (LEVELS + 1) + 1, 0);
        for (k, &l) in self.level.iter().enumerate() {
            self.starts[slot(k, l) + 1] += 1;
        }
        for s in 1..self.starts.len() {
            self.starts[s] += self.starts[s - 1];
        }
        self.order.clear();
        self.order.resize(n, 0);
        self.cursor.clone_from(&self.starts);
        for (k, &l) in self.level.iter().enumerate() {
            let at = &mut self.cursor[slot(k, l)];
            self.order[*at] = k;
            *at += 1;
        }
    }

    /// The chunks and levels in order, each as the range of its UAVs in `order` and whether it is a
    /// tail (its UAVs filter one at a time).
    fn levels(&self) -> impl Iterator<Item = (std::ops::Range<usize>, bool)> + '_ {
        self.starts.windows(2).enumerate().map(|(s, w)| (w[0]..w[1], s % (LEVELS + 1) == LEVELS))
    }
}

/// What the filter gave one UAV this tick.
#[derive(Debug, Clone, Copy, Default)]
struct Filtered {
    u: Vec2,
    rows: usize,
    active_rows: usize,
    max_slack: f64,
    solved: bool,
    failed: bool,
    solve_us: f64,
    min_barrier: f64,
}

/// One parallel task's filter and scratch rows.
struct Worker {
    filter: SafetyFilter,
    rows: Vec<Row>,
}

/// The filter stage's order, workers and buffers, reused from tick to tick.
#[derive(Default)]
pub(crate) struct FilterStage {
    order: FilterOrder,
    workers: Vec<Worker>,
    /// Each UAV's nominal input u_ref this tick, then its filtered input once filtered.
    inputs: Vec<Vec2>,
    /// The filter's result of each UAV, by position in the order.
    results: Vec<Filtered>,
    /// `place_of[k]`: UAV k's position in the order.
    place_of: Vec<usize>,
    /// The repair pass after the levels ([`crate::tick::repair`]).
    repair: Repair,
}

impl std::fmt::Debug for FilterStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FilterStage").field("order", &self.order).finish_non_exhaustive()
    }
}

/// Filters UAV k's nominal input (`inputs[k]`, not filtered yet) against its rows, the pair rows
/// against UAVs with a smaller index made whole with their inputs (`inputs[d]`, already filtered).
fn filter_one(
    k: usize,
    rows: &RowBuilder,
    inputs: &[Vec2],
    share_sequential: bool,
    p: &Params,
    worker: &mut Worker,
) -> Filtered {
    let (me, u_ref) = (rows.view(k), inputs[k]);
    if !me.flying {
        // Not following commands (taking off, landing, lost): brake, which is also what its link
        // holds it to; its neighbours treat it as an obstacle.
        return Filtered { u: u_ref, min_barrier: f64::INFINITY, ..Filtered::default() };
    }
    // Index order (module doc): d filtered before k, whatever its level.
    let before = |d: usize| share_sequential && d < k;
    let my_rows = rows.rows_of(k, p.delta, before, |d| inputs[d], &mut worker.rows);
    let (out, took) = worker.filter.filter_timed(u_ref, me.state.v, my_rows, p.delta, p.dt);
    Filtered {
        u: out.u,
        rows: my_rows.len(),
        active_rows: out.active_rows,
        max_slack: out.max_slack,
        solved: out.solved,
        failed: out.failed,
        solve_us: if out.solved { took.map_or(0.0, |t| t.as_secs_f64() * 1e6) } else { 0.0 },
        min_barrier: my_rows.iter().map(|r| r.b).fold(f64::INFINITY, f64::min),
    }
}

impl FilterStage {
    /// Filters every UAV's nominal input (`u_ref` of its last tick) against its rows and writes the
    /// results to the UAVs.
    pub(crate) fn run(&mut self, fleet: &mut TickState<'_>, rows: &RowBuilder) {
        let settings = fleet.config.filter;
        let n = fleet.uavs.len();
        let p = fleet.config.params;
        let sequential = fleet.config.share == crate::CollisionShare::Sequential;
        self.order.plan(rows, n);
        map_into(fleet.uavs, |u| u.last.u_ref, &mut self.inputs);
        self.results.clear();
        self.results.resize(n, Filtered::default());
        // A fixed set of tasks per level (a few per worker thread, for balance), each with its own
        // filter: no filter is created once the thread count is known.
        let tasks = 4 * rayon::current_num_threads().max(1);
        if self.workers.len() < tasks {
            self.workers
                .resize_with(tasks, || Worker { filter: SafetyFilter::new(settings), rows: Vec::new() });
        }
        for (span, tail) in self.order.levels() {
            let (start, end) = (span.start, span.end);
            if !tail && parallel(n) && end - start > MIN_UAVS_PER_TASK {
                let (order, inputs) = (&self.order, &self.inputs);
                let per_task = (end - start).div_ceil(tasks).max(MIN_UAVS_PER_TASK);
                self.results[start..end]
                    .par_chunks_mut(per_task)
                    .zip(order.order[start..end].par_chunks(per_task))
                    .zip(self.workers.par_iter_mut())
                    .for_each(|((out, ks), worker)| {
                        for (o, &k) in out.iter_mut().zip(ks) {
                            *o = filter_one(k, rows, inputs, sequential, &p, worker);
                        }
                    });
                for (o, &k) in self.results[start..end].iter().zip(&order.order[start..end]) {
                    self.inputs[k] = o.u;
                }
            } else {
                // One at a time: a small level, a small fleet, or the tail (whose UAVs may have
                // pair rows with each other, so each must see the inputs of those before it).
                for pos in start..end {
                    let k = self.order.order[pos];
                    let worker = &mut self.workers[0];
                    let o = filter_one(k, rows, &self.inputs, sequential, &p, worker);
                    self.results[pos] = o;
                    self.inputs[k] = o.u;
                }
            }
        }
        // The sequential share's repair pass (`split` has no inputs of others to repair against).
        self.repair.repaired.clear();
        if sequential {
            let slacked = self.results.iter().zip(&self.order.order).filter(|(o, _)| o.max_slack > 0.0);
            let uavs = &fleet.uavs;
            self.repair.run(
                slacked.map(|(_, &k)| k),
                rows,
                |k| uavs[k].last.u_ref,
                &mut self.inputs,
                &p,
                &mut self.workers[0].filter,
            );
        }
        // Written back in index order (each UAV's place in the order looked up), in parallel, not
        // in the order's level-by-level sweeps over the records (at 100,000 UAVs, 79 MB of them:
        // the filter stage 16.6 -> 16.2 ms; at 10,000 no change).
        self.place_of.clear();
        self.place_of.resize(n, 0);
        for (place, &k) in self.order.order.iter().enumerate() {
            self.place_of[k] = place;
        }
        let (results, place_of) = (&self.results, &self.place_of);
        let write = |(k, uav): (usize, &mut crate::member::Uav)| {
            let (o, last) = (&results[place_of[k]], &mut uav.last);
            (last.u, last.rows, last.active_rows, last.max_slack) = (o.u, o.rows, o.active_rows, o.max_slack);
            (last.solved, last.failed, last.solve_us, last.min_barrier) =
                (o.solved, o.failed, o.solve_us, o.min_barrier);
        };
        if parallel(n) {
            fleet.uavs.par_iter_mut().enumerate().for_each(write);
        } else {
            fleet.uavs.iter_mut().enumerate().for_each(write);
        }
        for r in &self.repair.repaired {
            let last = &mut fleet.uavs[r.k].last;
            (last.u, last.max_slack, last.active_rows) = (self.inputs[r.k], r.max_slack, r.active_rows);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// The order keeps index order on every pair (whichever UAV lists it): the smaller index is
        /// in an earlier chunk, or in the same chunk at a lower level, or both are in the chunk's
        /// tail (which filters in index order); it lists every UAV once, by chunk, level and index.
        #[test]
        fn levels_keep_index_order_on_every_pair(
            n in 0usize..200,
            chunk in prop_oneof![Just(usize::MAX / 2), 1usize..80],
            edges in prop::collection::vec((0usize..200, 0usize..200, any::<bool>()), 0..600),
            grounded in prop::collection::vec(0usize..200, 0..20),
            chain in 0usize..150,
        ) {
            let flying = |k: usize| !grounded.contains(&k);
            let mut lists = vec![Vec::new(); n];
            // Random pairs, each listed by one of its UAVs, plus a chain 0–1–2–… deeper than LEVELS.
            let chain_edges = (1..chain.min(n)).map(|k| (k - 1, k, true));
            for (a, b, by_a) in edges.into_iter().filter(|&(a, b, _)| a < n && b < n && a != b).chain(chain_edges) {
                if flying(a) && flying(b) {
                    if by_a { lists[a].push(b) } else { lists[b].push(a) }
                }
            }
            let mut order = FilterOrder::default();
            order.place(n, chunk, flying, |k| lists[k].clone().into_iter());
            let tail = LEVELS as u8;
            let rank = |k: usize| (k / chunk, order.level[k], k);
            for (a, list) in lists.iter().enumerate() {
                for &b in list {
                    let (lo, hi) = (a.min(b), a.max(b));
                    let (r_lo, r_hi) = (rank(lo), rank(hi));
                    let both_tail = r_lo.0 == r_hi.0 && r_lo.1 == tail && r_hi.1 == tail;
                    prop_assert!(r_lo.0 < r_hi.0 || r_lo.0 == r_hi.0 && r_lo.1 < r_hi.1 || both_tail,
                        "pair {lo}–{hi}: {r_lo:?}, {r_hi:?}");
                }
            }
            let mut seen = order.order.clone();
            seen.sort_unstable();
            prop_assert_eq!(seen, (0..n).collect::<Vec<_>>());
            for w in order.order.windows(2) {
                prop_assert!(rank(w[0]) < rank(w[1]));
            }
            let mut listed = 0;
            for (s, (span, is_tail)) in order.levels().enumerate() {
                let (c, l) = (s / (LEVELS + 1), s % (LEVELS + 1));
                prop_assert_eq!(is_tail, l == LEVELS);
                prop_assert_eq!(span.start, listed);
                for &k in &order.order[span.clone()] {
                    prop_assert_eq!((k / chunk, usize::from(order.level[k])), (c, l));
                }
                listed = span.end;
            }
            prop_assert_eq!(listed, n);
        }
    }
}
