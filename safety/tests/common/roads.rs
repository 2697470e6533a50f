//! Random roads for the property tests: turns, and widths that change at every joint.

use proptest::prelude::*;
use roads::{Road, RoadLayout};
use uav::Vec2;

/// A random road: 2–6 pieces of 2–8 m with turns of up to ±120°, 1–5 m wide (invalid ones are skipped).
pub fn road() -> impl Strategy<Value = Road> {
    (prop::collection::vec((2.0..8.0f64, -120.0..120.0f64), 2..6), 1.0..5.0f64, 0.0..std::f64::consts::TAU)
        .prop_filter_map("valid road", |(pieces, width, heading)| {
            let points = centre_points(&pieces, heading);
            Road::new(RoadLayout::from_centerline(&points, &vec![width; points.len()])).ok()
        })
}

/// A random road as [`road`] whose width changes at every joint (0.5–5 m): funnels, narrowings and
/// their mouths, where UAVs pass vertices that stick into the road.
pub fn varying_road() -> impl Strategy<Value = Road> {
    (
        prop::collection::vec((2.0..8.0f64, -120.0..120.0f64, 0.5..5.0f64), 2..6),
        0.5..5.0f64,
        0.0..std::f64::consts::TAU,
    )
        .prop_filter_map("valid road", |(pieces, first, heading)| {
            let turns: Vec<(f64, f64)> = pieces.iter().map(|&(length, turn, _)| (length, turn)).collect();
            let points = centre_points(&turns, heading);
            let widths: Vec<f64> = std::iter::once(first).chain(pieces.iter().map(|p| p.2)).collect();
            Road::new(RoadLayout::from_centerline(&points, &widths)).ok()
        })
}

/// The centre-line points of pieces (length, turn in degrees) starting at the origin along `heading`.
pub fn centre_points(pieces: &[(f64, f64)], heading: f64) -> Vec<[f64; 2]> {
    let mut h = heading;
    let mut p = Vec2::zeros();
    let mut points = vec![[0.0, 0.0]];
    for (k, (length, turn)) in pieces.iter().enumerate() {
        if k > 0 {
            h += turn.to_radians();
        }
        p += Vec2::new(h.cos(), h.sin()) * *length;
        points.push([p.x, p.y]);
    }
    points
}
