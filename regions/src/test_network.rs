//! A road network for the tests: a T of 4 m wide roads (`west` and `east` along the x axis,
//! `stem` down the y axis, 4 segments of 4.5 m each) meeting at the junction `tee`, the 4 m square
//! at the origin; in three regions whose borders cut the east road and separate the junction from
//! its stem: `west` (the west road, the junction and the east road's segments 0–1), `east` (its
//! segments 2–3) and `stem`.

use roads::Airspace;
use roads::network::{Junction, Network, NetworkLayout, NetworkRegion, NetworkRoad, RoadRange};

/// A road of 4 segments along +x from x = `from` to `from + 18`, 4 m wide about y = 0, each point
/// then mapped by `turn`.
fn road(name: &str, from: f64, turn: impl Fn([f64; 2]) -> [f64; 2]) -> NetworkRoad {
    let segments = (0..4)
        .map(|i| {
            let (a, b) = (from + 4.5 * i as f64, from + 4.5 * (i + 1) as f64);
            [[b, 2.0], [a, 2.0], [b, -2.0], [a, -2.0]].map(&turn)
        })
        .collect();
    NetworkRoad { name: name.into(), segments, one_way: false, speed_limit: None }
}

/// The T's layout in its three regions.
pub(crate) fn tee_layout() -> NetworkLayout {
    let range = |road: &str, first, last| RoadRange { road: road.into(), segments: [first, last] };
    let regions = vec![
        NetworkRegion { name: "stem".into(), roads: vec![range("stem", 0, 3)], junctions: vec![] },
        NetworkRegion {
            name: "west".into(),
            roads: vec![range("west", 0, 3), range("east", 0, 1)],
            junctions: vec!["tee".into()],
        },
        NetworkRegion { name: "east".into(), roads: vec![range("east", 2, 3)], junctions: vec![] },
    ];
    NetworkLayout {
        roads: vec![
            road("west", -20.0, |p| p),
            road("east", 2.0, |p| p),
            // Along -y from the junction: (x, y) ↦ (y, -x).
            road("stem", 2.0, |[x, y]| [y, -x]),
        ],
        junctions: vec![Junction {
            name: "tee".into(),
            polygon: vec![[-2.0, -2.0], [2.0, -2.0], [2.0, 2.0], [-2.0, 2.0]],
        }],
        regions: Some(regions),
    }
}

/// The T in its three regions, validated.
pub(crate) fn tee_in_three() -> Airspace {
    Network::new(tee_layout(), 1.0).expect("a valid T").into()
}
