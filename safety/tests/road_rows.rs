//! Road rows on random roads: whatever rule, state and road, every row with b ≥ 0 is satisfied by
//! braking straight away from its wall (u = −δa), and the walls rule always includes the nearest wall
//! once it is within the activation radius.

use proptest::prelude::*;
use roads::{Road, RoadLayout, SegmentTracker};
use safety::{RoadRule, Row, road_rows};
use uav::{Params, Vec2};

/// A random road: 2–6 pieces of 2–8 m with turns of up to ±120°, 1–5 m wide (invalid ones are skipped).
fn road() -> impl Strategy<Value = Road> {
    (prop::collection::vec((2.0..8.0f64, -120.0..120.0f64), 2..6), 1.0..5.0f64, 0.0..std::f64::consts::TAU)
        .prop_filter_map("valid road", |(pieces, width, heading)| {
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
            Road::new(RoadLayout::from_centerline(&points, &vec![width; points.len()])).ok()
        })
}

fn rule() -> impl Strategy<Value = RoadRule> {
    prop_oneof![Just(RoadRule::Walls), Just(RoadRule::Halfplanes), Just(RoadRule::Paper)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn full_braking_satisfies_every_row_with_nonnegative_barrier(
        road in road(),
        rule in rule(),
        (t, lateral) in (0.0..1.0f64, -1.0..1.0f64),
        (speed, angle) in (0.0..8.0f64, 0.0..std::f64::consts::TAU),
        delta in 1.0..8.0f64,
    ) {
        // A point inside the road: along the centre line, shifted sideways within its clearance.
        let line = road.centerline();
        let c = line.point_at(t * line.length());
        let normal = { let d = line.tangent_at(t * line.length()); Vec2::new(-d.y, d.x) };
        let p = c + normal * (lateral * road.boundary_distance(&c).max(0.0));
        prop_assume!(road.contains(&p));
        let v = Vec2::new(angle.cos(), angle.sin()) * speed;
        let params = Params { delta, ..Params::default() };
        let segment = SegmentTracker::default().update(&road, &p);
        let mut rows: Vec<Row> = Vec::new();
        road_rows(&road, rule, p, v, segment, &params, &mut rows);
        for r in &rows {
            prop_assert!((r.a.norm() - 1.0).abs() < 1e-9 && r.c.is_finite() && r.b.is_finite(), "{:?}", r);
            if r.b >= 0.0 {
                let braking = -r.a * delta;
                prop_assert!(r.a.dot(&braking) <= r.c + 1e-9, "row {:?} not met by full braking", r);
            }
        }
        if rule == RoadRule::Walls && road.boundary_distance(&p) <= safety::activation_radius(params.d_s, speed, delta) {
            prop_assert!(!rows.is_empty(), "no road row at {:?} ({} m from a wall)", p, road.boundary_distance(&p));
        }
    }
}
