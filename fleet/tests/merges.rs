//! A merge zips in order along each arm (docs/traffic.md, 6.; `fleet::traffic::junctions`): on a
//! ladder of roads, a group of 30 flying east meets a stream of 26 that merges into its road at the
//! junction `x` (one UAV from each arm in turn). A UAV that asked again (after giving a grant back,
//! say) counts as having asked no later than those behind it on its arm: before, a UAV behind it
//! could be granted the merge and stand behind it, holding the zone while it was refused for that
//! grant, and the merge stood still until the deadlock rule or luck broke it (all home 99.4 s).

#[path = "support/ladder.rs"]
mod ladder;
mod support;

use ladder::{GROUP, ladder, traffic};
use support::pd_fleet;
use uav::Params;

/// UAVs in the stream that merges into the group's road.
const STREAM: usize = 26;

#[test]
fn a_stream_merging_into_a_group_s_road_zips_and_everyone_gets_home() {
    let net = ladder(None, false, 100.0);
    let mut fleet = pd_fleet(net.clone(), &traffic(15.0, STREAM));
    let dt = fleet.config.params.dt;
    let n = fleet.uavs().len();
    let (mut arrived, mut closest, mut wall) = (vec![None; n], f64::INFINITY, f64::INFINITY);
    for tick in 0..(120.0 / dt) as usize {
        fleet.tick();
        let uavs = fleet.uavs();
        for (k, u) in uavs.iter().enumerate() {
            if u.nav.arrived {
                arrived[k].get_or_insert(tick as f64 * dt);
            }
            wall = wall.min(net.boundary_distance(&u.state.p));
            for other in &uavs[k + 1..] {
                closest = closest.min((u.state.p - other.state.p).norm());
            }
        }
        if arrived.iter().all(Option::is_some) {
            break;
        }
    }
    let p = Params::default();
    assert!(closest >= p.d_c - 1e-6 && wall >= p.d_s - 1e-6, "closest pair {closest} m, wall {wall} m");
    let home = |range: std::ops::Range<usize>| {
        arrived[range].iter().map(|t| t.unwrap_or(f64::INFINITY)).fold(0.0, f64::max)
    };
    let (group, stream) = (home(0..GROUP), home(GROUP..n));
    // Measured: the group all home at 42.5 s, the stream at 35.9 s (99.4 s and 89.0 s before).
    assert!(group <= 55.0 && stream <= 50.0, "all home: the group at {group} s, the stream at {stream} s");
}
