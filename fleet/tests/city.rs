//! A small city grid of `bench scale --road city` (`fleet::city`) flies to completion: 4 × 4 blocks,
//! 200 UAVs between random points of the streets, with `pd` and with the shipped `rl` policy; every
//! UAV home within t_max and no safety violation (margins on the network's walls and between UAVs).
//! The 2,000-UAV run on 11 × 11 blocks is in BENCHMARKS.md ("Fleet engine at scale"), not here.

use fleet::city::city_grid;
use fleet::{FleetConfig, RunOptions, run_scenario};
use policies::PolicyRegistry;

fn fly(policy: &str, seed: u64) {
    let valid = city_grid(4, 200, seed).expect("room for 200 UAVs").validate().expect("a valid city grid");
    let options =
        RunOptions { config: FleetConfig::default(), policy: policy.into(), trajectory: None, paths: false };
    let policies = PolicyRegistry::standard(valid.params.delta).expect("the shipped model loads");
    let m = run_scenario(&valid, options, policies).expect("no I/O without a trajectory").metrics;
    assert!(
        m.safe,
        "{policy}, seed {seed}: separation {:?}, wall {:.3}, outside {}, QP failures {}",
        m.min_separation_m, m.min_wall_distance_m, m.steps_outside_road, m.qp.failures
    );
    let arrived = m.arrival_time_s.values().filter(|t| t.is_some()).count();
    assert!(m.all_arrived, "{policy}, seed {seed}: {arrived} of 200 arrived by t_max");
}

#[test]
fn a_city_grid_flies_home_safely_with_pd() {
    fly("pd", 1);
}

#[test]
fn a_city_grid_flies_home_safely_with_rl() {
    fly("rl", 2);
}
