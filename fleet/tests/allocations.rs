//! A tick in steady state allocates nothing: after a warm-up, the ticks of a pd fleet and its metrics
//! recorder allocate no new block, on one thread and on two, and their shared buffers only grow,
//! geometrically, when the fleet reaches a new peak density (a handful of times in a run, never per
//! UAV). An ONNX policy's tract call allocates its tensors, a fixed set per call: an rl tick allocates
//! the same number of blocks for 300 UAVs as for 600, nothing per UAV.
//!
//! Counted with a counting global allocator, so this file holds a single test (tests of one binary
//! run concurrently and would count each other's allocations).

use fleet::trunk::trunk_scenario;
use fleet::{Fleet, FleetConfig, MetricsRecorder};
use links::SimLink;
use policies::PolicyRegistry;
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};
use std::alloc::System;
use uav::UavState;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Ticks before the count starts: the fleet takes off and its buffers reach their working size.
const WARM_UP_TICKS: usize = 100;

/// (new blocks, reallocations) of each tick (the fleet's and its metrics recorder's, on every thread) after
/// the warm-up, 300 ticks of a trunk road's fleet of `uavs` flying `policy` on `threads` threads.
fn allocations_per_tick(uavs: usize, policy: &str, threads: usize) -> Vec<(usize, usize)> {
    let scenario = trunk_scenario(uavs, 3).expect("a trunk road").validate().expect("valid");
    let policies = PolicyRegistry::standard(scenario.params.delta).expect("the shipped models load");
    let config = FleetConfig { params: scenario.params, ..FleetConfig::default() };
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = Box::new(SimLink::new(state, scenario.params.dt));
        fleet.add(u.id.clone(), policy.into(), link, state, Some(u.goal));
    }
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
        assert!(fleet.uavs().iter().all(|u| u.flying()), "every UAV flies its policy during the count");
        counts.split_off(WARM_UP_TICKS)
    })
}

/// Buffer growths allowed over the 300 counted ticks: each shared buffer (neighbour lists, row
/// blocks, the stall record) doubles when it grows, so it grows a few times in a whole run.
const MAX_GROWTHS: usize = 12;

#[test]
fn ticks_allocate_nothing_after_warm_up() {
    for (uavs, threads) in [(200, 1), (300, 2), (600, 2)] {
        let counts = allocations_per_tick(uavs, "pd", threads);
        let fresh: Vec<(usize, usize)> = counts
            .iter()
            .enumerate()
            .filter(|(_, c)| c.0 > 0)
            .map(|(t, c)| (t + WARM_UP_TICKS, c.0))
            .collect();
        assert!(fresh.is_empty(), "{uavs} UAVs, {threads} thread(s): (tick, new blocks) {fresh:?}");
        let growths: usize = counts.iter().map(|c| c.1).sum();
        assert!(growths <= MAX_GROWTHS, "{uavs} UAVs, {threads} thread(s): {growths} buffer growths");
    }
    let (small, large) = (allocations_per_tick(300, "rl", 2), allocations_per_tick(600, "rl", 2));
    for (t, (s, l)) in small.iter().zip(&large).enumerate() {
        assert!(
            s.0 <= 40 && s.0 == l.0,
            "tick {}: {} new blocks for 300 UAVs, {} for 600",
            t + WARM_UP_TICKS,
            s.0,
            l.0
        );
    }
    for counts in [small, large] {
        let growths: usize = counts.iter().map(|c| c.1).sum();
        assert!(growths <= MAX_GROWTHS, "rl: {growths} buffer growths");
    }
}
