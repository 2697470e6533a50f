//! The tick's parallel stages give bit-identical runs on any number of threads: the same paths,
//! arrivals, margins and stalls with 1, 2 and 4 worker threads.

use fleet::families::Family;
use fleet::{FleetConfig, RunOptions, RunOutcome, run_scenario};
use policies::PolicyRegistry;

fn run_on(threads: usize, family: Family, seed: u64) -> RunOutcome {
    let scenario = family.scenario(seed).validate().expect("generated scenarios are valid");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
    let policies = PolicyRegistry::standard(scenario.params.delta).expect("the shipped models load");
    let mut outcome = pool
        .install(|| {
            let options = RunOptions {
                config: FleetConfig::default(),
                policy: "pd".into(),
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
    for (family, seed) in [(Family::Crowd, 3), (Family::HeadOn, 11), (Family::Mixed, 17)] {
        let one = run_on(1, family, seed);
        assert!(!one.paths.is_empty());
        for threads in [2, 4] {
            let many = run_on(threads, family, seed);
            assert!(many == one, "{} seed {seed}: {threads} threads differ from one", family.name());
        }
    }
}
