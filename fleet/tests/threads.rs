//! The tick's parallel stages give bit-identical runs on any number of threads: the same paths,
//! arrivals, margins and stalls with 1, 2 and 4 worker threads, for a fleet large enough that the
//! stages do run in parallel (`fleet::PARALLEL_FROM_UAVS`).

use fleet::trunk::trunk_scenario;
use fleet::{FleetConfig, PARALLEL_FROM_UAVS, RunOptions, RunOutcome, Scenario, run_scenario};
use policies::PolicyRegistry;

fn run_on(threads: usize, scenario: &Scenario, policy: &str) -> RunOutcome {
    let scenario = scenario.validate().expect("generated scenarios are valid");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
    let policies = PolicyRegistry::standard(scenario.params.delta).expect("the shipped models load");
    let mut outcome = pool
        .install(|| {
            let options = RunOptions {
                config: FleetConfig::default(),
                policy: policy.into(),
                trajectory: None,
                paths: true,
            };
            run_scenario(&scenario, options, policies)
        })
        .expect("no I/O");
    // Solve times are wall-clock measurements, the only thing allowed to differ.
    (outcome.metrics.qp.p50_us, outcome.metrics.qp.p99_us) = (0.0, 0.0);
    outcome
}

#[test]
fn runs_are_identical_on_one_two_and_four_threads() {
    let mut scenario = trunk_scenario(PARALLEL_FROM_UAVS + 144, 5).expect("a trunk road");
    scenario.params.t_max = 8.0;
    for policy in ["pd", "rl"] {
        let one = run_on(1, &scenario, policy);
        assert_eq!(one.paths.len(), PARALLEL_FROM_UAVS + 144);
        assert!(one.metrics.min_collision_margin_m.is_some(), "UAVs met: neighbour rows were built");
        for threads in [2, 4] {
            let many = run_on(threads, &scenario, policy);
            assert!(many == one, "{policy}: {threads} threads differ from one");
        }
    }
}
