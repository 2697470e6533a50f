//! What the fleet's integration tests share: a fleet of `pd` UAVs on simulated links.

use fleet::{Fleet, FleetConfig, Scenario};
use links::SimLink;
use policies::PolicyRegistry;
use roads::Airspace;
use uav::{Params, UavState, Vec2};

/// A fleet of `pd` UAVs with the default parameters flying `airspace`, UAV k (`u00`, `u01`, ...)
/// from its start to its goal.
#[allow(dead_code)] // Not every test that shares this module uses the default configuration.
pub fn pd_fleet(airspace: impl Into<Airspace>, uavs: &[(Vec2, Vec2)]) -> Fleet {
    let config = FleetConfig { params: Params::default(), ..FleetConfig::default() };
    pd_fleet_with(config, airspace, uavs)
}

/// [`pd_fleet`] with `config` (its parameters for the UAVs too).
#[allow(dead_code)] // Not every test that shares this module sets a configuration.
pub fn pd_fleet_with(config: FleetConfig, airspace: impl Into<Airspace>, uavs: &[(Vec2, Vec2)]) -> Fleet {
    let params = config.params;
    let mut fleet = Fleet::new(config, airspace, PolicyRegistry::with_pd(params.delta));
    for (k, &(start, goal)) in uavs.iter().enumerate() {
        let state = UavState::at_rest(start);
        let link = Box::new(SimLink::new(state, params.dt));
        fleet.add(format!("u{k:02}"), "pd".into(), link, state, Some(goal));
    }
    fleet
}

/// A fleet flying `scenario` (validated; its parameters, the standard policies), every UAV on a
/// simulated link with `policy`, from its start to its goal.
#[allow(dead_code)] // Not every test that shares this module flies a scenario.
pub fn scenario_fleet(scenario: &Scenario, policy: &str) -> Fleet {
    let scenario = scenario.validate().expect("generated scenarios are valid");
    let policies = PolicyRegistry::standard(scenario.params.delta).expect("the shipped models load");
    let config = FleetConfig { params: scenario.params, ..FleetConfig::default() };
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = Box::new(SimLink::new(state, scenario.params.dt));
        fleet.add(u.id.clone(), policy.to_string(), link, state, Some(u.goal));
    }
    fleet
}
