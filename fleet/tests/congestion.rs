//! Congestion-aware routes (docs/traffic.md 7.; `fleet::traffic::congestion`): on a ladder, two
//! branches between the same two junctions, a group whose shortest way meets a stream merging into
//! it (a zip: one UAV from each arm in turn) gets home sooner, all of it and on average, when the
//! UAVs that come to the fork while the queue stands there take the free branch than when all keep
//! the fastest way by travel time; and when the group comes as the stream has nearly passed, nobody
//! detours. Each flight keeps D_c between UAVs and D_s from the walls.

use fleet::{Fleet, FleetConfig};
use links::SimLink;
use policies::PolicyRegistry;
use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use uav::{Params, UavState, Vec2};

/// UAVs in the group, and in the stream that merges into the short branch.
const GROUP: usize = 30;
const STREAM: usize = 26;

/// A square junction of half-width 2 m centred on (x, y).
fn square(name: &str, x: f64, y: f64) -> Junction {
    let corners = [[x - 2.0, y - 2.0], [x + 2.0, y - 2.0], [x + 2.0, y + 2.0], [x - 2.0, y + 2.0]];
    Junction { name: name.into(), polygon: corners.to_vec() }
}

/// A straight road from edge `from` to edge `to` (each as its two ends, the first ends along one
/// wall, the second along the other), in pieces of at most 4 m.
fn road(name: &str, from: [[f64; 2]; 2], to: [[f64; 2]; 2]) -> NetworkRoad {
    let mid = |e: [[f64; 2]; 2]| Vec2::new((e[0][0] + e[1][0]) / 2.0, (e[0][1] + e[1][1]) / 2.0);
    let pieces = ((mid(to) - mid(from)).norm() / 4.0).ceil().max(1.0) as usize;
    let at = |i: usize, end: usize| {
        if i == 0 {
            from[end]
        } else if i == pieces {
            to[end]
        } else {
            let t = i as f64 / pieces as f64;
            [from[end][0] + (to[end][0] - from[end][0]) * t, from[end][1] + (to[end][1] - from[end][1]) * t]
        }
    };
    let segments = (0..pieces).map(|i| [at(i + 1, 0), at(i, 0), at(i + 1, 1), at(i, 1)]).collect();
    NetworkRoad { name: name.into(), segments, one_way: false, speed_limit: None }
}

/// The ladder: a west road into junction `j1` (x = 0), the short branch east through the junction
/// `x` (x = 10) into the main road, through `y` (x = 24) to its end at the corner `j3` (x = 60);
/// the long branch from `j1` north to the corner `k1`, east to `k2` and south into `j3`. A stream
/// comes out of a dead-end road `src` inside the ladder, through the corner `c` into `x`, where it
/// merges with the short branch (a zip: one UAV from each arm in turn), and leaves the main road at
/// `y` southwards into `drain`. Roads and junctions are 4 m wide.
fn ladder() -> Network {
    let roads = vec![
        road("west", [[-100.0, -2.0], [-100.0, 2.0]], [[-2.0, -2.0], [-2.0, 2.0]]),
        road("short", [[2.0, -2.0], [2.0, 2.0]], [[8.0, -2.0], [8.0, 2.0]]),
        road("main1", [[12.0, -2.0], [12.0, 2.0]], [[22.0, -2.0], [22.0, 2.0]]),
        road("main2", [[26.0, -2.0], [26.0, 2.0]], [[58.0, -2.0], [58.0, 2.0]]),
        road("up", [[2.0, 2.0], [-2.0, 2.0]], [[2.0, 10.0], [-2.0, 10.0]]),
        road("top", [[2.0, 10.0], [2.0, 14.0]], [[58.0, 10.0], [58.0, 14.0]]),
        road("down", [[58.0, 10.0], [62.0, 10.0]], [[58.0, 2.0], [62.0, 2.0]]),
        road("feed", [[12.0, 2.0], [8.0, 2.0]], [[12.0, 4.0], [8.0, 4.0]]),
        road("src", [[12.0, 4.0], [12.0, 8.0]], [[44.0, 4.0], [44.0, 8.0]]),
        road("drain", [[22.0, -2.0], [26.0, -2.0]], [[22.0, -50.0], [26.0, -50.0]]),
    ];
    let junctions = vec![
        square("j1", 0.0, 0.0),
        square("x", 10.0, 0.0),
        square("y", 24.0, 0.0),
        square("j3", 60.0, 0.0),
        square("k1", 0.0, 12.0),
        square("k2", 60.0, 12.0),
        square("c", 10.0, 6.0),
    ];
    Network::new(NetworkLayout { roads, junctions }, 0.6).expect("a valid ladder")
}

/// The group (west to east, one file 1.5 m apart in the eastbound lane from `head` m west of `j1`,
/// to goals along the main road's far part, the first home farthest) and the stream (packed in
/// `src`, to the drain, the first out farthest), as (start, goal).
fn traffic(head: f64) -> Vec<(Vec2, Vec2)> {
    let mut uavs: Vec<(Vec2, Vec2)> = (0..GROUP)
        .map(|k| {
            let start = Vec2::new(-head - 1.5 * k as f64, -1.0);
            let goal = Vec2::new(56.0 - 1.5 * (k / 2) as f64, if k % 2 == 0 { -1.0 } else { 1.0 });
            (start, goal)
        })
        .collect();
    uavs.extend((0..STREAM).map(|k| {
        let start = Vec2::new(13.0 + (k / 2) as f64 * 1.2, if k % 2 == 0 { 5.0 } else { 7.0 });
        let goal = Vec2::new(if k % 2 == 0 { 23.0 } else { 25.0 }, -46.0 + 1.5 * k as f64);
        (start, goal)
    }));
    uavs
}

/// What a flight showed.
#[derive(Debug)]
struct Flight {
    /// When each UAV arrived (s).
    arrived: Vec<Option<f64>>,
    /// Group UAVs that flew the long branch.
    detoured: usize,
    /// The smallest distance between two UAVs and to a wall (m).
    min_separation: f64,
    min_wall: f64,
}

impl Flight {
    /// When the last of the stream arrived (s).
    fn stream_home(&self) -> f64 {
        self.arrived[GROUP..].iter().map(|t| t.unwrap_or(f64::INFINITY)).fold(0.0, f64::max)
    }

    /// When the last of the group arrived and the group's mean arrival time (s).
    fn group_times(&self) -> (f64, f64) {
        let times: Vec<f64> = self.arrived[..GROUP].iter().map(|t| t.unwrap_or(f64::INFINITY)).collect();
        (times.iter().copied().fold(0.0, f64::max), times.iter().sum::<f64>() / GROUP as f64)
    }
}

/// Flies the ladder's traffic (the group's head `head` m west of `j1`) with `reroute_margin_s` for
/// at most `seconds`.
fn fly(head: f64, reroute_margin_s: Option<f64>, seconds: f64) -> Flight {
    let net = ladder();
    let params = Params::default();
    let config = FleetConfig { params, reroute_margin_s, ..FleetConfig::default() };
    let mut fleet = Fleet::new(config, net.clone(), PolicyRegistry::with_pd(params.delta));
    for (k, &(start, goal)) in traffic(head).iter().enumerate() {
        let state = UavState::at_rest(start);
        fleet.add(
            format!("u{k:02}"),
            "pd".into(),
            Box::new(SimLink::new(state, params.dt)),
            state,
            Some(goal),
        );
    }
    let n = fleet.uavs().len();
    let mut f = Flight {
        arrived: vec![None; n],
        detoured: 0,
        min_separation: f64::INFINITY,
        min_wall: f64::INFINITY,
    };
    let mut on_top = [false; GROUP];
    for tick in 0..(seconds / params.dt) as usize {
        fleet.tick();
        let t = tick as f64 * params.dt;
        let uavs = fleet.uavs();
        for (k, u) in uavs.iter().enumerate() {
            if u.nav.arrived {
                f.arrived[k].get_or_insert(t);
            }
            if k < GROUP && u.state.p.y > 9.0 {
                on_top[k] = true;
            }
            let wall = net.boundary_distance(&u.state.p);
            f.min_wall = f.min_wall.min(if net.contains(&u.state.p) { wall } else { -wall });
            for other in &uavs[k + 1..] {
                f.min_separation = f.min_separation.min((u.state.p - other.state.p).norm());
            }
        }
        if uavs.iter().all(|u| u.nav.arrived) {
            break;
        }
    }
    f.detoured = on_top.iter().filter(|&&d| d).count();
    f
}

/// Flies the ladder with the group's head `head` m west of `j1` without and with congestion-aware
/// routes (the default margin); checks both flights and returns them.
fn compare(head: f64) -> (Flight, Flight) {
    let p = Params::default();
    let fixed = fly(head, None, 200.0);
    let aware = fly(head, FleetConfig::default().reroute_margin_s, 200.0);
    for f in [&fixed, &aware] {
        assert!(f.arrived.iter().all(Option::is_some), "everyone arrives: {f:?}");
        assert!(f.min_separation >= p.d_c - 1e-6, "closest pair {} m", f.min_separation);
        assert!(f.min_wall >= p.d_s - 1e-6, "closest to a wall {} m", f.min_wall);
    }
    let ((fixed_all, fixed_mean), (aware_all, aware_mean)) = (fixed.group_times(), aware.group_times());
    println!(
        "head {head} m: fastest way: all home {fixed_all:.1} s, mean {fixed_mean:.1} s; congestion-aware: all home {aware_all:.1} s, mean {aware_mean:.1} s, {} of {GROUP} took the long branch; the stream all home {:.1} s / {:.1} s",
        aware.detoured,
        fixed.stream_home(),
        aware.stream_home()
    );
    assert_eq!(fixed.detoured, 0, "without the queues' cost nobody takes the long branch: {fixed:?}");
    (fixed, aware)
}

#[test]
fn a_group_that_meets_the_merging_stream_gets_home_sooner_when_some_take_the_free_branch() {
    // The group comes to the fork while the stream merges: a queue stands at `x` for a minute.
    let (fixed, aware) = compare(15.0);
    let ((fixed_all, fixed_mean), (aware_all, aware_mean)) = (fixed.group_times(), aware.group_times());
    assert!(aware.detoured > 0 && aware.detoured < GROUP, "a share takes the free branch: {aware:?}");
    // Measured: all home 85.2 s against 100.2 s, mean 64.3 s against 83.9 s (13 of 30 detoured).
    assert!(aware_all < 0.9 * fixed_all, "all home {aware_all} s against {fixed_all} s");
    assert!(aware_mean < 0.85 * fixed_mean, "mean arrival {aware_mean} s against {fixed_mean} s");
    assert!(aware.stream_home() <= fixed.stream_home(), "the stream is not held up by it either");
}

#[test]
fn a_group_that_comes_when_the_stream_has_nearly_passed_keeps_the_short_branch() {
    // The group comes 10 m later: the queue at `x` is short and the stream behind it nearly through,
    // so its cost stays small (a queue waits only as long as the other arms have UAVs to let in).
    let (fixed, aware) = compare(25.0);
    let ((fixed_all, fixed_mean), (aware_all, aware_mean)) = (fixed.group_times(), aware.group_times());
    assert_eq!(aware.detoured, 0, "{aware:?}");
    assert!(aware_all <= fixed_all + 0.5 && aware_mean <= fixed_mean + 0.5, "{aware:?}");
}
