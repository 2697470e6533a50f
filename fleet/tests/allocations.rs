//! A tick in steady state allocates nothing: after a warm-up, the ticks of a pd or rl fleet and its
//! metrics recorder allocate only when a buffer grows (a shared buffer doubling at a new peak
//! density, a worker's scratch at its largest QP yet): a few dozen times at most in 300 ticks, never
//! per UAV or per tick. The rl model runs on the policies' MLP kernel, whose buffers (each thread's
//! activations, the outputs) are kept between calls: no allocation per call either.
//!
//! Counted with a counting global allocator, so this file holds a single test (tests of one binary
//! run concurrently and would count each other's allocations).

use fleet::MetricsRecorder;
use fleet::trunk::trunk_scenario;
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};
use std::alloc::System;

mod support;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Ticks before the count starts: the fleet takes off and its buffers reach their working size.
const WARM_UP_TICKS: usize = 100;

/// (new blocks, reallocations) of each tick (the fleet's and its metrics recorder's, on every thread) after
/// the warm-up, 300 ticks of a trunk road's fleet of `uavs` flying `policy` on `threads` threads.
fn allocations_per_tick(uavs: usize, policy: &str, threads: usize) -> Vec<(usize, usize)> {
    let scenario = trunk_scenario(uavs, 3).expect("a trunk road");
    let mut fleet = support::scenario_fleet(&scenario, policy);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
    pool.install(|| {
        let mut recorder = MetricsRecorder::new();
        let mut counts = Vec::with_capacity(WARM_UP_TICKS + 300);
        for tick in 0..WARM_UP_TICKS + 300 {
            let region = Region::new(GLOBAL);
            fleet.tick();
            recorder.record(&fleet, tick as f64 * scenario.params.dt);
            let change = region.change();
            counts.push((change.allocations, change.reallocations));
        }
        assert!(
            fleet.uavs().iter().all(|u| u.condition.flying()),
            "every UAV flies its policy during the count"
        );
        counts.split_off(WARM_UP_TICKS)
    })
}

/// Allocations (new blocks and growths) allowed over the 300 counted ticks: each shared buffer
/// doubles when it grows, and the scratch of each of the filter's tasks (4 per thread) grows to the
/// largest QP it has met, a few times each. A per-UAV allocation would count 300 × the fleet.
const MAX_GROWTHS: usize = 32;

#[test]
fn ticks_allocate_nothing_after_warm_up() {
    let total = |counts: &[(usize, usize)]| counts.iter().map(|c| c.0 + c.1).sum::<usize>();
    for (policy, uavs, threads) in
        [("pd", 200, 1), ("pd", 300, 2), ("pd", 600, 2), ("rl", 300, 2), ("rl", 600, 2)]
    {
        let counts = allocations_per_tick(uavs, policy, threads);
        let allocating: Vec<(usize, (usize, usize))> = counts
            .iter()
            .enumerate()
            .filter(|(_, c)| c.0 + c.1 > 0)
            .map(|(t, &c)| (t + WARM_UP_TICKS, c))
            .collect();
        assert!(
            total(&counts) <= MAX_GROWTHS,
            "{policy}, {uavs} UAVs, {threads} thread(s): (tick, (new blocks, growths)) {allocating:?}"
        );
    }
}
