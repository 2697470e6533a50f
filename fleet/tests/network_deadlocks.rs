//! Deadlocks on a network (docs/traffic.md, "Deadlocks"; `fleet::traffic::cycles`): UAVs whose
//! ways meet head-on inside a cell, where no lane keeps them apart, stop facing each other under the
//! filter; the cycle of their waits is found and one steps aside, so both arrive, D_c apart.

mod support;

use fleet::Fleet;
use fleet::traffic::WaitReason;
use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use support::pd_fleet;
use uav::{Params, Vec2};

/// A square junction (side 4 m) at the origin with a straight two-way road of `length` m, 4 m
/// wide, east and west of it, and north and south too when `crossing`.
fn junction(length: f64, crossing: bool) -> Network {
    let (h, far) = (2.0, 2.0 + length);
    let road = |name: &str, segment: [[f64; 2]; 4]| NetworkRoad {
        name: name.into(),
        segments: vec![segment],
        one_way: false,
        speed_limit: None,
    };
    let mut roads = vec![
        road("east", [[far, -h], [h, -h], [far, h], [h, h]]),
        road("west", [[-far, h], [-h, h], [-far, -h], [-h, -h]]),
    ];
    if crossing {
        roads.push(road("north", [[h, far], [h, h], [-h, far], [-h, h]]));
        roads.push(road("south", [[-h, -far], [-h, -h], [h, -far], [h, -h]]));
    }
    let square = Junction { name: "x".into(), polygon: vec![[-h, -h], [h, -h], [h, h], [-h, h]] };
    Network::new(NetworkLayout { roads, junctions: vec![square], regions: None }, 0.6)
        .expect("a valid network")
}

/// What a flight showed: when each UAV arrived, the closest pair (m), whether anyone backed off, and
/// the longest stall (s).
type Flight = (Vec<Option<f64>>, f64, bool, f64);

/// Flies until everyone arrived or `seconds` passed.
fn fly(fleet: &mut Fleet, seconds: f64) -> Flight {
    let dt = fleet.config.params.dt;
    let n = fleet.uavs().len();
    let (mut arrived, mut closest, mut backed, mut stall) = (vec![None; n], f64::INFINITY, false, 0.0f64);
    for tick in 0..(seconds / dt) as usize {
        fleet.tick();
        let uavs = fleet.uavs();
        for (k, u) in uavs.iter().enumerate() {
            if u.nav.arrived {
                arrived[k].get_or_insert(tick as f64 * dt);
            }
            backed |= u.traffic.waiting == Some(WaitReason::DeadlockBackoff);
            stall = stall.max(u.last.stall_s);
            for other in &uavs[k + 1..] {
                closest = closest.min((u.state.p - other.state.p).norm());
            }
        }
        if arrived.iter().all(Option::is_some) {
            break;
        }
    }
    (arrived, closest, backed, stall)
}

#[test]
fn two_uavs_swapping_places_in_a_street_meet_head_on_and_pass() {
    let net = junction(16.0, false);
    for (y, offset) in [(0.0, 0.0), (0.5, 0.0), (-1.0, 0.02), (1.2, -0.03)] {
        let (a, b) = (Vec2::new(6.0, y), Vec2::new(14.0, y + offset));
        let mut fleet = pd_fleet(net.clone(), &[(a, b), (b, a)]);
        let (arrived, closest, backed, _) = fly(&mut fleet, 60.0);
        assert!(backed, "y {y}: one of them stepped aside");
        assert!(arrived.iter().all(Option::is_some), "y {y}: both arrive: {arrived:?}");
        assert!(closest >= Params::default().d_c - 1e-6, "y {y}: closest pair {closest} m");
    }
}

#[test]
fn a_line_waiting_for_a_crossing_stream_is_a_chain_not_a_deadlock() {
    let net = junction(30.0, true);
    // Twenty-five UAVs northbound, 1 m apart, reach the junction first; six westbound, 1 m apart, wait in
    // line for them, stalled longer than the deadlock rule's 3 s: nobody backs off.
    let mut uavs: Vec<(Vec2, Vec2)> =
        (0..25).map(|k| (Vec2::new(1.0, -4.0 - k as f64), Vec2::new(1.0, 28.0 - k as f64))).collect();
    uavs.extend((0..6).map(|k| (Vec2::new(8.0 + k as f64, 1.0), Vec2::new(-20.0 + k as f64, 1.0))));
    let mut fleet = pd_fleet(net.clone(), &uavs);
    let (arrived, closest, backed, stall) = fly(&mut fleet, 120.0);
    assert!(arrived.iter().all(Option::is_some), "everyone arrives: {arrived:?}");
    assert!(closest >= Params::default().d_c - 1e-6, "closest pair {closest} m");
    assert!(stall > 3.0, "the line stalled longer than the deadlock rule waits: {stall} s");
    assert!(!backed, "nobody backs off out of a line");
}
