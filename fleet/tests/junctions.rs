//! Junctions and merges of a network as conflict zones (docs/traffic.md, "Junctions and merges"):
//! movements that cross take turns while those that do not pass together, a crossing movement waits
//! no longer than the maximum behind a stream of any length, and a merge zips in the order the UAVs
//! came. Each flight is checked tick by tick against the zones' conflicts as `roads` computes them.

mod support;

use fleet::Fleet;
use fleet::traffic::WaitReason;
use fleet::traffic::junctions::JUNCTION_MAX_WAIT_S;
use roads::NetworkNavigator;
use roads::network::{Conflict, ConflictZone, Junction, Network, NetworkLayout, NetworkRoad};
use support::pd_fleet;
use uav::{Params, Vec2};

/// Half the width of the roads and of the square junction at the origin (m).
const HALF: f64 = 2.0;

/// A square junction at the origin with a straight two-way road of `length` m on each side named
/// in `arms` (`east`, `west`, `north`, `south`); a side without a road is a wall.
fn junction(arms: &[&str], length: f64) -> Network {
    let (h, far) = (HALF, HALF + length);
    // Each road runs away from the junction: p2, p4 on the junction's edge.
    let segments = |name: &str| -> [[f64; 2]; 4] {
        match name {
            "east" => [[far, -h], [h, -h], [far, h], [h, h]],
            "west" => [[-far, h], [-h, h], [-far, -h], [-h, -h]],
            "north" => [[h, far], [h, h], [-h, far], [-h, h]],
            _ => [[-h, -far], [-h, -h], [h, -far], [h, -h]],
        }
    };
    let roads = arms
        .iter()
        .map(|&name| NetworkRoad {
            name: name.into(),
            segments: vec![segments(name)],
            one_way: false,
            speed_limit: None,
        })
        .collect();
    let square = Junction { name: "x".into(), polygon: vec![[-h, -h], [h, -h], [h, h], [-h, h]] };
    Network::new(NetworkLayout { roads, junctions: vec![square], regions: None }, 0.6)
        .expect("a valid junction")
}

/// The network's zones as the fleet finds them (the gates of its navigator, D_c as kept).
fn zones(net: &Network) -> Vec<ConflictZone> {
    let params = Params::default();
    net.conflict_zones(NetworkNavigator::new(net, &params).gates, params.kept_d_c())
}

/// What the flight showed, tick by tick.
#[derive(Debug, Default)]
struct Flight {
    /// Per UAV: when it first asked for a zone, when it was first granted one (s).
    asked: Vec<Option<f64>>,
    granted: Vec<Option<f64>>,
    /// Per UAV: the longest it waited with reason `junction` or `merge` (s), and whether it did.
    longest_wait: Vec<f64>,
    reasons: Vec<Option<WaitReason>>,
    /// Per UAV: when it arrived (s).
    arrived: Vec<Option<f64>>,
    /// Ticks in which two UAVs held grants whose movements conflict, and in which two UAVs with
    /// grants from different arms held them together without conflict.
    conflicting_grants: u32,
    shared_grants: u32,
    /// The smallest distance between two UAVs and to a wall (m).
    min_separation: f64,
    min_wall: f64,
}

/// Flies `fleet` for at most `seconds` (until everyone arrived), recording a [`Flight`].
fn fly(fleet: &mut Fleet, net: &Network, seconds: f64) -> Flight {
    let zones = zones(net);
    let n = fleet.uavs().len();
    let mut f = Flight {
        asked: vec![None; n],
        granted: vec![None; n],
        longest_wait: vec![0.0; n],
        reasons: vec![None; n],
        arrived: vec![None; n],
        min_separation: f64::INFINITY,
        min_wall: f64::INFINITY,
        ..Flight::default()
    };
    let dt = fleet.config.params.dt;
    let mut waiting_since = vec![None; n];
    let ticks = (seconds / dt) as usize;
    for tick in 0..ticks {
        fleet.tick();
        let t = tick as f64 * dt;
        let uavs = fleet.uavs();
        for (k, u) in uavs.iter().enumerate() {
            let tr = &u.traffic;
            if tr.waiting_since.is_some() || tr.junction.is_some() {
                f.asked[k].get_or_insert(t);
            }
            if tr.junction.is_some() {
                f.granted[k].get_or_insert(t);
            }
            match tr.waiting {
                Some(reason @ (WaitReason::Junction | WaitReason::Merge)) => {
                    f.reasons[k] = Some(reason);
                    let since: f64 = *waiting_since[k].get_or_insert(t);
                    f.longest_wait[k] = f.longest_wait[k].max(t - since);
                }
                _ => waiting_since[k] = None,
            }
            if u.nav.arrived {
                f.arrived[k].get_or_insert(t);
            }
            let wall = net.boundary_distance(&u.state.p);
            f.min_wall = f.min_wall.min(if net.contains(&u.state.p) { wall } else { -wall });
            for other in &uavs[k + 1..] {
                f.min_separation = f.min_separation.min((u.state.p - other.state.p).norm());
            }
        }
        let grants: Vec<_> = uavs.iter().filter_map(|u| u.traffic.junction).collect();
        let (mut conflicting, mut shared) = (false, false);
        for (i, &(za, ma)) in grants.iter().enumerate() {
            for &(zb, mb) in &grants[i + 1..] {
                if za == zb {
                    conflicting |= zones[za].conflict(ma, mb) != Conflict::None;
                    shared |= ma.entry != mb.entry && zones[za].conflict(ma, mb) == Conflict::None;
                }
            }
        }
        f.conflicting_grants += u32::from(conflicting);
        f.shared_grants += u32::from(shared);
        if uavs.iter().all(|u| u.nav.arrived) {
            break;
        }
    }
    f
}

/// The bounds every flight here keeps: D_c between UAVs, D_s from the walls.
fn assert_safe(f: &Flight) {
    let p = Params::default();
    assert!(f.min_separation >= p.d_c - 1e-6, "closest pair {} m", f.min_separation);
    assert!(f.min_wall >= p.d_s - 1e-6, "closest to a wall {} m", f.min_wall);
}

#[test]
fn crossing_movements_take_turns_while_opposite_straights_pass_together() {
    let net = junction(&["east", "west", "north", "south"], 14.0);
    // Westbound keeps right (north of the middle), eastbound south of it, northbound east of it:
    // all three reach the junction together.
    let uavs = [
        (Vec2::new(12.0, 1.0), Vec2::new(-12.0, 1.0)),
        (Vec2::new(-12.0, -1.0), Vec2::new(12.0, -1.0)),
        (Vec2::new(1.0, -12.0), Vec2::new(1.0, 12.0)),
    ];
    let mut fleet = pd_fleet(net.clone(), &uavs);
    let f = fly(&mut fleet, &net, 60.0);
    assert!(f.arrived.iter().all(Option::is_some), "everyone arrives: {f:?}");
    assert_safe(&f);
    assert_eq!(f.conflicting_grants, 0, "no two crossing movements are ever granted together: {f:?}");
    assert!(f.shared_grants > 0, "the two opposite straights cross the junction together: {f:?}");
    assert!(f.reasons.contains(&Some(WaitReason::Junction)), "someone waits for the junction: {f:?}");
}

#[test]
fn a_crossing_movement_waits_no_longer_than_the_maximum_behind_a_stream_of_thirty() {
    let net = junction(&["east", "west", "north", "south"], 80.0);
    // Thirty UAVs westbound, 2.4 m apart (a stream 70 m long, more than the maximum wait to pass),
    // and one northbound that reaches the junction just after the stream's head.
    let mut uavs: Vec<(Vec2, Vec2)> = (0..30)
        .map(|k| {
            let x = 4.5 + 2.4 * k as f64;
            (Vec2::new(x, 1.0), Vec2::new(-x - 2.0, 1.0))
        })
        .collect();
    uavs.push((Vec2::new(1.0, -7.0), Vec2::new(1.0, 10.0)));
    let mut fleet = pd_fleet(net.clone(), &uavs);
    let f = fly(&mut fleet, &net, 150.0);
    assert!(f.arrived.iter().all(Option::is_some), "everyone arrives: {f:?}");
    assert_safe(&f);
    assert_eq!(f.conflicting_grants, 0, "{f:?}");
    let crossing = 30;
    assert_eq!(f.reasons[crossing], Some(WaitReason::Junction), "it waits for the stream: {f:?}");
    // The maximum, then the time for the stream's UAVs in the junction to clear it.
    let bound = JUNCTION_MAX_WAIT_S + 6.0;
    assert!(f.longest_wait[crossing] <= bound, "waited {} s (bound {bound} s)", f.longest_wait[crossing]);
    // It went before the stream's tail: the stream did not starve it.
    let tail_granted = f.granted[..crossing].iter().flatten().fold(0.0, |a: f64, &b| a.max(b));
    let granted = f.granted[crossing].expect("it was granted");
    assert!(granted < tail_granted, "granted at {granted} s, the stream's tail at {tail_granted} s");
}

#[test]
fn a_merge_zips_in_the_order_the_uavs_came() {
    // A T: from the east and the west arms into the south one (a left and a right turn that leave
    // by the same arm).
    let net = junction(&["east", "west", "south"], 30.0);
    // Six from each side, the east ones a little nearer; each goes down the southbound lane (west
    // of the middle), those expected through first the farthest.
    let mut uavs = Vec::new();
    for k in 0..6 {
        let x = 4.0 + 2.0 * k as f64;
        uavs.push((Vec2::new(x, 1.0), Vec2::new(-1.0, -30.0 + 3.0 * k as f64)));
        uavs.push((Vec2::new(-x - 0.7, -1.0), Vec2::new(-1.0, -28.5 + 3.0 * k as f64)));
    }
    let mut fleet = pd_fleet(net.clone(), &uavs);
    let f = fly(&mut fleet, &net, 120.0);
    assert!(f.arrived.iter().all(Option::is_some), "everyone arrives: {f:?}");
    assert_safe(&f);
    assert_eq!(f.conflicting_grants, 0, "never two merging movements at once: {f:?}");
    assert!(f.reasons.contains(&Some(WaitReason::Merge)), "someone waits for the merge: {f:?}");
    // In order: of two UAVs from different arms, the one that asked first (by more than a tick)
    // is granted first.
    let dt = Params::default().dt;
    for a in 0..uavs.len() {
        for b in 0..uavs.len() {
            let (Some(asked_a), Some(asked_b)) = (f.asked[a], f.asked[b]) else { continue };
            if a % 2 != b % 2 && asked_a + dt < asked_b {
                let (ga, gb) = (f.granted[a].expect("granted"), f.granted[b].expect("granted"));
                assert!(
                    ga <= gb,
                    "u{a:02} asked at {asked_a} s before u{b:02} at {asked_b} s: {ga} > {gb}: {:?} {:?}",
                    f.asked,
                    f.granted
                );
            }
        }
    }
    // Zipped: the arms alternate in the order of the grants.
    let mut order: Vec<(f64, usize)> =
        (0..uavs.len()).map(|k| (f.granted[k].expect("granted"), k % 2)).collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let switches = order.windows(2).filter(|w| w[0].1 != w[1].1).count();
    assert!(switches >= 6, "the arms take turns: {order:?}");
}

#[test]
fn another_region_s_uav_in_the_junction_holds_it_until_it_has_left() {
    let net = junction(&["east", "west", "north", "south"], 14.0);
    // A UAV of ours crosses northbound; another region's UAV hovers in the junction for 8 s, then
    // flies out east at 1 m/s (its region tells us its state every tick).
    let mut fleet = pd_fleet(net.clone(), &[(Vec2::new(1.0, -8.0), Vec2::new(1.0, 12.0))]);
    let dt = fleet.config.params.dt;
    let zones = zones(&net);
    let (mut waited, mut granted_inside, mut arrived) = (0.0, false, None);
    let mut closest = f64::INFINITY;
    for tick in 0..(60.0 / dt) as usize {
        let t = tick as f64 * dt;
        let (p, v) = if t < 8.0 {
            (Vec2::new(-0.5, 0.5), Vec2::zeros())
        } else {
            (Vec2::new(-0.5 + (t - 8.0), 0.5), Vec2::new(1.0, 0.0))
        };
        let state = uav::UavState { p, v };
        fleet.set_foreign(&[fleet::ForeignUav { id: "far".into(), state, age_s: 0.0 }]);
        fleet.tick();
        let u = &fleet.uavs()[0];
        let foreign_inside = net.locate(&p).is_some_and(|c| zones.iter().any(|z| z.cell == c));
        granted_inside |= foreign_inside && u.traffic.junction.is_some();
        if u.traffic.waiting == Some(WaitReason::Junction) {
            waited += dt;
        }
        closest = closest.min((u.state.p - p).norm());
        if u.nav.arrived {
            arrived = Some(t);
            break;
        }
    }
    assert!(!granted_inside, "never granted while the other region's UAV is in the junction");
    assert!(waited > 3.0, "it waited for the junction ({waited} s)");
    assert!(arrived.is_some(), "it arrives once the junction is free");
    assert!(closest >= Params::default().d_c - 1e-6, "closest to the other region's UAV {closest} m");
}
