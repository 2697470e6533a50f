//! A road flown by one fleet per region of its layout, in one process and in lockstep, as `airroads
//! serve --region` flies it (docs/regions.md) without Zenoh: before each tick every fleet is told the
//! other fleets' UAVs as foreign ([`Fleet::set_foreign`]), one tick old (the states their fleets
//! read at their last tick); after the tick a UAV whose tracked segment lies in another region
//! leaves its fleet and joins that region's, with its state, goal and policy (a handover without
//! messages, so without an unowned tick). What splitting costs is when every UAV is home, against
//! one fleet flying the whole road (`fleet/tests/split_road.rs`).

use crate::fleet::{Fleet, FleetConfig};
use crate::member::ForeignUav;
use crate::scenario::ValidScenario;
use crate::tick::neighbours::NeighbourSearch;
use links::SimLink;
use policies::PolicyRegistry;
use uav::{UavState, Vec2};

/// How a split run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitOutcome {
    /// When every UAV was home at once (s), if before t_max.
    pub all_home_s: Option<f64>,
    /// UAVs home at the end.
    pub arrived: usize,
    /// Smallest distance (m) between two UAVs at a tick (read states), whichever fleets fly them;
    /// ∞ when no two came within 1 m.
    pub min_distance_m: f64,
    /// UAVs handed from one fleet to another.
    pub handovers: usize,
}

/// Why a scenario cannot be flown split.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplitError {
    /// Regions divide one road; the scenario flies a network.
    #[error("the scenario flies a road network: regions divide one road")]
    Network,
    /// The road's layout has no `regions`.
    #[error("the road has no regions")]
    NoRegions,
}

/// Flies `scenario` with policy `policy` (made by `policies` for each fleet) until every UAV is
/// home or t_max: split into one fleet per region of its road when `split`, else one fleet.
pub fn fly_split(
    scenario: &ValidScenario,
    mut config: FleetConfig,
    policy: &str,
    policies: impl Fn() -> PolicyRegistry,
    split: bool,
) -> Result<SplitOutcome, SplitError> {
    let road = scenario.road.road().ok_or(SplitError::Network)?;
    let regions = road.layout().regions.as_deref().unwrap_or_default();
    if split && regions.is_empty() {
        return Err(SplitError::NoRegions);
    }
    let count = if split { regions.len() } else { 1 };
    // Each segment's fleet.
    let fleet_of: Vec<usize> = (0..road.quads().len())
        .map(|s| {
            let region = road.region_of(s).filter(|_| split);
            region.and_then(|r| regions.iter().position(|q| q.name == r.name)).unwrap_or(0)
        })
        .collect();
    config.params = scenario.params;
    let dt = config.params.dt;
    let mut fleets: Vec<Fleet> = (0..count).map(|_| Fleet::new(config, road.clone(), policies())).collect();
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let k = fleet_of[road.locate(&u.start, None)];
        fleets[k].add(u.id.clone(), policy.into(), Box::new(SimLink::new(state, dt)), state, Some(u.goal));
    }
    let total = scenario.uavs.len();
    let mut outcome =
        SplitOutcome { all_home_s: None, arrived: 0, min_distance_m: f64::INFINITY, handovers: 0 };
    let (mut foreign, mut positions, mut search) = (Vec::new(), Vec::new(), NeighbourSearch::default());
    let ticks = (scenario.params.t_max / dt).ceil() as u64;
    for tick in 0..ticks {
        for k in 0..count {
            foreign.clear();
            for (_, other) in fleets.iter().enumerate().filter(|(j, _)| *j != k) {
                foreign.extend(other.uavs().iter().map(|u| ForeignUav {
                    id: u.id.clone(),
                    state: u.state,
                    // Read at the start of the other fleet's last tick (none yet: the start).
                    age_s: if tick == 0 { 0.0 } else { dt },
                }));
            }
            fleets[k].set_foreign(&foreign);
        }
        outcome.arrived = fleets.iter_mut().map(Fleet::tick).sum();
        positions.clear();
        positions.extend(fleets.iter().flat_map(|f| f.uavs().iter().map(|u| u.state.p)));
        outcome.min_distance_m = outcome.min_distance_m.min(min_distance(&mut search, &positions));
        if outcome.arrived == total {
            outcome.all_home_s = Some((tick + 1) as f64 * dt);
            break;
        }
        outcome.handovers += hand_over(&mut fleets, &fleet_of, dt);
    }
    Ok(outcome)
}

/// Moves every UAV whose tracked segment lies in another fleet's region to that fleet, with its
/// link's state now, its goal and its policy; returns how many moved.
fn hand_over(fleets: &mut [Fleet], fleet_of: &[usize], dt: f64) -> usize {
    let mut leaving = Vec::new();
    for (k, fleet) in fleets.iter().enumerate() {
        for u in fleet.uavs() {
            let to = u.nav.tracker.current.and_then(|s| fleet_of.get(s).copied());
            if let Some(to) = to.filter(|&to| to != k) {
                leaving.push((k, to, u.id.clone()));
            }
        }
    }
    for (from, to, id) in &leaving {
        let Ok(mut uav) = fleets[*from].remove(id) else { continue }; // listed just above
        let state = uav.link.state().filter(UavState::is_finite).unwrap_or(uav.state);
        let link = Box::new(SimLink::new(state, dt));
        fleets[*to].add(id.clone(), uav.policy.into_name(), link, state, uav.nav.goal());
    }
    leaving.len()
}

/// The smallest distance between two of `positions` less than 1 m apart (∞ when none are).
fn min_distance(search: &mut NeighbourSearch, positions: &[Vec2]) -> f64 {
    search.update_with_foreign(positions, positions.len(), 1.0);
    (0..positions.len())
        .flat_map(|k| search.lists[k].iter().map(move |&d| (positions[d] - positions[k]).norm()))
        .fold(f64::INFINITY, f64::min)
}
