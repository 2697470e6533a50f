//! What the fleet's integration tests share: a fleet of `pd` UAVs on simulated links.

use fleet::{Fleet, FleetConfig};
use links::SimLink;
use policies::PolicyRegistry;
use roads::Airspace;
use uav::{Params, UavState, Vec2};

/// A fleet of `pd` UAVs with the default parameters flying `airspace`, UAV k (`u00`, `u01`, ...)
/// from its start to its goal.
pub fn pd_fleet(airspace: impl Into<Airspace>, uavs: &[(Vec2, Vec2)]) -> Fleet {
    let params = Params::default();
    let config = FleetConfig { params, ..FleetConfig::default() };
    let mut fleet = Fleet::new(config, airspace, PolicyRegistry::with_pd(params.delta));
    for (k, &(start, goal)) in uavs.iter().enumerate() {
        let state = UavState::at_rest(start);
        let link = Box::new(SimLink::new(state, params.dt));
        fleet.add(format!("u{k:02}"), "pd".into(), link, state, Some(goal));
    }
    fleet
}
