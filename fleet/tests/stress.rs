//! A few hundred random valid scenarios (roads with 20–120° bends, 1–5 m wide, hairpins; 2–30 UAVs)
//! fly with zero safety violations: margins ≥ D_c and D_s, no step outside the road, no failed solve.

use fleet::stress::random_scenario;
use fleet::{FleetConfig, RunOptions, run_scenario};
use policies::PolicyRegistry;
use std::sync::atomic::{AtomicU64, Ordering};

const CASES: u64 = 300;

#[test]
fn stress_scenarios_have_no_safety_violation() {
    let next = AtomicU64::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    let seed = next.fetch_add(1, Ordering::Relaxed) + 1;
                    if seed > CASES {
                        break;
                    }
                    let valid = random_scenario(seed).validate().unwrap();
                    let options = RunOptions {
                        config: FleetConfig::default(),
                        policy: "pd".into(),
                        trajectory: None,
                        paths: false,
                    };
                    let policies = PolicyRegistry::with_pd(valid.params.delta);
                    let m = run_scenario(&valid, options, policies).unwrap().metrics;
                    if !m.safe {
                        failures.lock().unwrap().push((seed, m));
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    for (seed, m) in &failures {
        eprintln!(
            "seed {seed}: collision margin {:?}, road margin {}, outside {}, failures {}",
            m.min_collision_margin_m, m.min_road_margin_m, m.steps_outside_road, m.qp.failures
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {CASES} stress scenarios violated safety (replay: airroads stress --scenarios 1 --seed SEED)",
        failures.len()
    );
}
