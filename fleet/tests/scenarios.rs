//! The shipped scenarios fly safely to their goals; the hairpin of docs/safety.md §10.1 does not trap
//! UAVs at its inner vertex.

use fleet::{FleetConfig, RunMetrics, RunOptions, Scenario, ScenarioUav, ValidScenario, run_scenario};
use policies::PolicyRegistry;
use roads::RoadLayout;
use uav::Params;

fn load(name: &str) -> ValidScenario {
    let path = format!("{}/../scenarios/{name}.json", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    Scenario::from_json(&text).and_then(|s| s.validate()).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn fly(scenario: &ValidScenario, config: FleetConfig) -> RunMetrics {
    fly_policy(scenario, config, "pd")
}

/// Flies every UAV with `policy` from the standard registry (`pd`, or the shipped `rl` model).
fn fly_policy(scenario: &ValidScenario, config: FleetConfig, policy: &str) -> RunMetrics {
    let options = RunOptions { config, policy: policy.into(), trajectory: None, paths: false };
    let policies = PolicyRegistry::standard(scenario.params.delta).expect("the shipped model loads");
    run_scenario(scenario, options, policies).expect("no I/O without a trajectory").metrics
}

fn assert_safe_and_arrived(name: &str, m: &RunMetrics, p: &Params) {
    assert!(m.safe, "{name}: {m:#?}");
    assert!(m.all_arrived, "{name}: {m:#?}");
    assert!(m.min_collision_margin_m.unwrap() >= p.d_c && m.min_road_margin_m >= p.d_s);
    assert_eq!((m.steps_outside_road, m.qp.failures), (0, 0));
}

#[test]
fn lab_scale_three_uavs_are_safe_and_arrive() {
    let s = load("lab3");
    assert_eq!(s.uavs.len(), 3);
    assert_safe_and_arrived("lab3", &fly(&s, FleetConfig::default()), &s.params);
}

#[test]
fn ten_uavs_on_a_ten_segment_road_are_safe_and_arrive() {
    let s = load("snake10");
    assert!(s.uavs.len() >= 8 && s.road.road().expect("one road").quads().len() >= 8);
    assert_safe_and_arrived("snake10", &fly(&s, FleetConfig::default()), &s.params);
}

#[test]
fn lab_scale_three_uavs_with_the_rl_policy_are_safe_and_arrive() {
    // The rl policy pushes a UAV into the dead-end corner beyond another's goal; it gets out only
    // because arrived UAVs make way (fleet::yielding).
    let s = load("lab3");
    assert_safe_and_arrived("lab3 rl", &fly_policy(&s, FleetConfig::default(), "rl"), &s.params);
}

#[test]
fn ten_uavs_with_the_rl_policy_are_safe_and_arrive() {
    let s = load("snake10");
    assert_safe_and_arrived("snake10 rl", &fly_policy(&s, FleetConfig::default(), "rl"), &s.params);
}

#[test]
fn hairpin_uavs_with_the_rl_policy_are_safe_and_arrive() {
    let s = hairpin().validate().unwrap();
    assert_safe_and_arrived("hairpin rl", &fly_policy(&s, FleetConfig::default(), "rl"), &s.params);
}

/// Two 120° bends 3 m wide (a hairpin); UAVs start in the first leg and must get round both.
fn hairpin() -> Scenario {
    let centre = [[0.0, 0.0], [8.0, 0.0], [4.0, 6.928], [12.0, 6.928]];
    let layout = RoadLayout::from_centerline(&centre, &[3.0; 4]);
    let uav = |i: usize, start: [f64; 2], goal: [f64; 2]| ScenarioUav {
        id: format!("h{i}"),
        start,
        goal,
        link: None,
    };
    let params = Params { t_max: 60.0, ..Params::default() };
    let uavs = vec![
        uav(0, [1.0, -0.8], [11.0, 6.9]),
        uav(1, [1.0, 0.8], [10.0, 7.6]),
        uav(2, [2.5, 0.0], [10.0, 6.2]),
        uav(3, [4.0, -0.8], [9.0, 6.9]),
    ];
    Scenario::on_road("hairpin".into(), params, layout.segments, uavs)
}

#[test]
fn hairpin_uavs_cut_the_inner_corner_without_getting_stuck() {
    let s = hairpin().validate().unwrap();
    assert_safe_and_arrived("hairpin", &fly(&s, FleetConfig::default()), &s.params);
}

#[test]
fn a_depot_with_branches_is_flown_through_its_junctions_safely_home_with_pd_and_rl() {
    let s = load("depot");
    let net = s.road.network().expect("depot is a road network");
    assert!(net.layout().junctions.len() >= 2 && net.layout().roads.len() >= 5);
    for policy in ["pd", "rl"] {
        let m = fly_policy(&s, FleetConfig::default(), policy);
        assert_safe_and_arrived(&format!("depot {policy}"), &m, &s.params);
    }
}
