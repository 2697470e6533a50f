//! A large scenario for the validation benchmark (`examples/validate_bench.rs`) and its regression
//! test (`tests/validate_large.rs`): a zigzag road of 2,000 segments (pieces of 5.2 m with bends of
//! 33°, 4 m wide) and 50,000 UAVs on a 0.4 m × 0.6 m grid in the middle of the pieces.

use fleet::{Scenario, ScenarioUav};
use roads::RoadLayout;
use uav::{Params, Vec2};

/// Segments of the road.
pub const SEGMENTS: usize = 2000;
/// UAVs of the scenario.
pub const UAVS: usize = 50_000;

/// The zigzag road: polyline vertices (5k, 0 or 1.5), 4 m wide.
pub fn road() -> RoadLayout {
    let points: Vec<[f64; 2]> =
        (0..=SEGMENTS).map(|k| [5.0 * k as f64, if k % 2 == 1 { 1.5 } else { 0.0 }]).collect();
    RoadLayout::from_centerline(&points, &vec![4.0; points.len()])
}

/// Start positions: rows every 0.4 m at least 0.8 m from a joint, five lanes 0.6 m apart (at least
/// 0.8 m from a wall), piece after piece until `count` UAVs are placed.
fn starts(count: usize) -> Vec<[f64; 2]> {
    let mut out = Vec::with_capacity(count);
    'pieces: for k in 0..SEGMENTS {
        let a = Vec2::new(5.0 * k as f64, if k % 2 == 1 { 1.5 } else { 0.0 });
        let b = Vec2::new(5.0 * (k + 1) as f64, if k % 2 == 1 { 0.0 } else { 1.5 });
        let len = (b - a).norm();
        let t = (b - a) / len;
        let n = Vec2::new(-t.y, t.x);
        let mut u = 0.8;
        while u <= len - 0.8 {
            for lane in [-1.2, -0.6, 0.0, 0.6, 1.2] {
                if out.len() == count {
                    break 'pieces;
                }
                let p = a + t * u + n * lane;
                out.push([p.x, p.y]);
            }
            u += 0.4;
        }
    }
    assert_eq!(out.len(), count, "the road has room for {count} UAVs");
    out
}

/// A valid scenario with `count` UAVs `uav0`, `uav1`, …; UAV i flies to the start of UAV count−1−i.
pub fn scenario(count: usize) -> Scenario {
    let starts = starts(count);
    let uavs = (0..count)
        .map(|i| ScenarioUav {
            id: format!("uav{i}"),
            start: starts[i],
            goal: starts[count - 1 - i],
            link: None,
        })
        .collect();
    Scenario::on_road("big".into(), Params::default(), road().segments, uavs)
}

/// The same scenario with its last UAV starting 0.1 m from the first one (closer than D_c).
pub fn invalid_last(count: usize) -> Scenario {
    let mut s = scenario(count);
    let first = s.uavs[0].start;
    s.uavs[count - 1].start = [first[0] + 0.1, first[1]];
    s
}
