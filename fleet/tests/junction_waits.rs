//! The maximum wait at a junction holds at any fleet size (docs/traffic.md, "Junctions and merges"):
//! in city grids of `bench scale --road city` (`fleet::city`, 3 m/s streets, 6 m junctions) with
//! more and more UAVs, no head of a line waits for its turn longer than the maximum plus the time
//! the UAVs in the zone, or too close to stop before it, take to leave it (2.5 s at 3 m/s through a
//! 6 m junction, braking from 0.95 m before it; METRICS.json's `max_wait_s`).

use fleet::city::city_scenario;
use fleet::traffic::junctions::JUNCTION_MAX_WAIT_S;
use fleet::{FleetConfig, RunOptions, run_scenario};
use policies::PolicyRegistry;

/// What a head of a line may wait beyond the maximum (s): those in the zone (6 m) or within
/// braking distance of it (0.95 m at 3 m/s) leave it at the streets' 3 m/s, rounded up.
const CLEAR_S: f64 = 3.0;

/// Flies the city scenario of `n` UAVs (seed 1, as `bench scale` writes it) with `pd` and returns
/// its longest wait for a turn at the head of a line (s), once everyone is home safely.
fn longest_wait(n: usize) -> f64 {
    let valid = city_scenario(n, 1).expect("room for the UAVs").validate().expect("a valid city grid");
    let options =
        RunOptions { config: FleetConfig::default(), policy: "pd".into(), trajectory: None, paths: false };
    let policies = PolicyRegistry::standard(valid.params.delta).expect("the shipped model loads");
    let m = run_scenario(&valid, options, policies).expect("no I/O without a trajectory").metrics;
    assert!(m.safe, "{n} UAVs: separation {:?}, wall {:.3}", m.min_separation_m, m.min_wall_distance_m);
    assert!(m.all_arrived, "{n} UAVs: not all home by t_max");
    m.max_wait_s
}

#[test]
fn no_head_of_a_line_waits_past_the_maximum_and_the_zone_s_clearing_at_300_and_600_uavs() {
    let bound = JUNCTION_MAX_WAIT_S + CLEAR_S;
    for n in [300, 600] {
        let wait = longest_wait(n);
        assert!(wait > JUNCTION_MAX_WAIT_S - 5.0, "{n} UAVs: the city is dense enough to wait ({wait} s)");
        assert!(wait <= bound, "{n} UAVs: a head waited {wait} s (bound {bound} s)");
    }
}
