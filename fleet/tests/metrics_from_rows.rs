//! The metrics a run records from the tick's rows stage (each UAV's road margin and closest pair,
//! recorded as its rows are built) are exactly those of a second pass over the same states
//! (`MetricsRecorder::record_truth` given the states the fleet read measures them afresh): every
//! tick, on a trunk road and on a city network, bit for bit.

use fleet::city::city_scenario;
use fleet::trunk::trunk_scenario;
use fleet::{MetricsRecorder, RunMetrics, Scenario};
use uav::UavState;

mod support;

/// The margins of one tick's metrics, as bits.
fn margins(m: &RunMetrics) -> [Option<u64>; 5] {
    [
        m.min_collision_margin_m.map(f64::to_bits),
        Some(m.min_road_margin_m.to_bits()),
        m.min_separation_m.map(f64::to_bits),
        Some(m.min_wall_distance_m.to_bits()),
        Some(m.steps_outside_road),
    ]
}

fn check(scenario: &Scenario, policy: &str, ticks: usize) {
    let mut fleet = support::scenario_fleet(scenario, policy);
    let mut met = 0;
    for tick in 0..ticks {
        fleet.tick();
        let read: Vec<Option<UavState>> = fleet.uavs().iter().map(|u| Some(u.state)).collect();
        let (mut from_rows, mut afresh) = (MetricsRecorder::new(), MetricsRecorder::new());
        from_rows.record(&fleet, 0.0);
        afresh.record_truth(&fleet, 0.0, &read);
        let (a, b) = (from_rows.finish(&fleet, "t"), afresh.finish(&fleet, "t"));
        assert_eq!(margins(&a), margins(&b), "{} {policy}, tick {tick}: {a:?} vs {b:?}", scenario.name);
        met += usize::from(a.min_collision_margin_m.is_some());
    }
    assert!(met > 0, "{}: UAVs met (pairs were measured)", scenario.name);
}

#[test]
fn margins_from_the_rows_equal_a_second_pass_on_a_trunk_road() {
    let scenario = trunk_scenario(300, 3).expect("a trunk road");
    check(&scenario, "pd", 200);
    check(&scenario, "rl", 100);
}

#[test]
fn margins_from_the_rows_equal_a_second_pass_on_a_city_network() {
    let scenario = city_scenario(300, 3).expect("a city grid");
    check(&scenario, "pd", 200);
    check(&scenario, "rl", 100);
}
