//! A 50,000-UAV scenario on a 2,000-segment road, invalid only in its last UAV, is rejected naming
//! that UAV's field and the earlier UAV it clashes with (correctness only; the timing is in
//! `examples/validate_bench.rs`).

#[path = "../examples/support/big_scenario.rs"]
mod big_scenario;

use big_scenario::{UAVS, invalid_last, scenario};
use fleet::ScenarioError;

fn rejected(s: &fleet::Scenario) -> (String, String) {
    match s.validate() {
        Err(ScenarioError::Invalid { field, reason }) => (field, reason),
        other => panic!("expected a field error, got {:?}", other.map(|v| v.uavs.len())),
    }
}

#[test]
fn fifty_thousand_uavs_invalid_in_the_last_one_name_it() {
    let last = format!("uavs[{}]", UAVS - 1);
    assert_eq!(
        rejected(&invalid_last(UAVS)),
        (format!("{last}.start"), "closer than D_c = 0.3 m to uavs[0].start".into())
    );

    let mut s = scenario(UAVS);
    s.uavs[UAVS - 1].id = "uav17".into();
    assert_eq!(rejected(&s), (format!("{last}.id"), "duplicate id `uav17` (also uavs[17])".into()));

    let mut s = scenario(UAVS);
    s.uavs[UAVS - 1].goal = [0.0, 100.0];
    assert_eq!(rejected(&s), (format!("{last}.goal"), "[0, 100] is outside the road".into()));

    let mut s = scenario(UAVS);
    s.uavs[UAVS - 1].link = Some("udp://127.0.0.1:99999".into());
    assert_eq!(rejected(&s).0, format!("{last}.link"));

    let valid = scenario(UAVS).validate().expect("the big scenario is valid");
    assert_eq!(
        (valid.uavs.len(), valid.road.road().expect("one road").quads().len()),
        (UAVS, big_scenario::SEGMENTS)
    );
}
