//! The ladder of roads the merge and congestion tests fly (`#[path]`-included by them, since not
//! every test uses it): two branches between the junctions `j1` and `j3`, and a stream that merges
//! into the short one.

use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use uav::Vec2;

/// UAVs in the group.
pub const GROUP: usize = 30;

/// UAVs at most in the stream (two files packed in `src`).
pub const MAX_STREAM: usize = 52;

/// A square junction of half-width 2 m centred on (x, y).
pub fn square(name: &str, x: f64, y: f64) -> Junction {
    let corners = [[x - 2.0, y - 2.0], [x + 2.0, y - 2.0], [x + 2.0, y + 2.0], [x - 2.0, y + 2.0]];
    Junction { name: name.into(), polygon: corners.to_vec() }
}

/// A straight road from edge `from` to edge `to` (each as its two ends, the first ends along one
/// wall, the second along the other), in pieces of at most 4 m.
pub fn road(name: &str, from: [[f64; 2]; 2], to: [[f64; 2]; 2]) -> NetworkRoad {
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
/// `y` southwards into `drain`. Roads and junctions are 4 m wide. `shared_limit` is the speed
/// limit (m/s) of `main1`, the part between `x` and `y` that the group and the stream share; with
/// `exit`, a road `east` goes on from `j3` (to x = 160), where the two branches join again. The west
/// road starts `west` m west of `j1` (100 for the merge tests).
pub fn ladder(shared_limit: Option<f64>, exit: bool, west: f64) -> Network {
    let mut roads = vec![
        road("west", [[-west, -2.0], [-west, 2.0]], [[-2.0, -2.0], [-2.0, 2.0]]),
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
    roads[2].speed_limit = shared_limit;
    if exit {
        roads.push(road("east", [[62.0, -2.0], [62.0, 2.0]], [[160.0, -2.0], [160.0, 2.0]]));
    }
    let junctions = vec![
        square("j1", 0.0, 0.0),
        square("x", 10.0, 0.0),
        square("y", 24.0, 0.0),
        square("j3", 60.0, 0.0),
        square("k1", 0.0, 12.0),
        square("k2", 60.0, 12.0),
        square("c", 10.0, 6.0),
    ];
    Network::new(NetworkLayout { roads, junctions, regions: None }, 0.6).expect("a valid ladder")
}

/// The group (west to east, one file 1.5 m apart in the eastbound lane from `head` m west of `j1`,
/// to goals along the main road's far part, the first home farthest) and the stream (packed in
/// `src`, to the drain, the first out farthest; `stream` UAVs, at most [`MAX_STREAM`]), as (start,
/// goal).
pub fn traffic(head: f64, stream: usize) -> Vec<(Vec2, Vec2)> {
    assert!(stream <= MAX_STREAM, "{stream} UAVs do not fit in the stream's road");
    let mut uavs: Vec<(Vec2, Vec2)> = (0..GROUP)
        .map(|k| {
            let start = Vec2::new(-head - 1.5 * k as f64, -1.0);
            let goal = Vec2::new(56.0 - 1.5 * (k / 2) as f64, if k % 2 == 0 { -1.0 } else { 1.0 });
            (start, goal)
        })
        .collect();
    uavs.extend((0..stream).map(|k| {
        let start = Vec2::new(13.0 + (k / 2) as f64 * 1.2, if k % 2 == 0 { 5.0 } else { 7.0 });
        // The first 26 in two files along the drain, the others between them.
        let goal = match k {
            0..26 => Vec2::new(if k % 2 == 0 { 23.0 } else { 25.0 }, -46.0 + 1.5 * k as f64),
            _ => Vec2::new(24.0, -45.25 + 1.5 * (k - 26) as f64),
        };
        (start, goal)
    }));
    uavs
}
