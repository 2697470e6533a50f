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
        if rule == RoadRule::Walls {
            let radius = safety::activation_radius(params.d_s, speed, delta);
            if let Some(w) = unguarded_wall(&road, p, v, &params, radius, &rows) {
                prop_assert!(false, "wall {} ({:?}) has no row at {:?}", w, road.walls()[w], p);
            }
        }
    }
}

/// The first wall within `radius` of `p` whose braking barrier on the distance to the finite wall,
/// √(2δ(d − D_s)) + d′, is not the barrier of one of `rows` (None when every wall is guarded).
fn unguarded_wall(
    road: &Road,
    p: Vec2,
    v: Vec2,
    params: &Params,
    radius: f64,
    rows: &[Row],
) -> Option<usize> {
    road.walls().iter().position(|w| {
        let c = w.nearest(&p).0;
        let d = (p - c).norm();
        if d > radius || d < 1e-9 {
            return false;
        }
        let b = (2.0 * params.delta * (d - params.d_s).max(0.0)).sqrt() + (p - c).dot(&v) / d;
        !rows.iter().any(|r| (r.b - b).abs() < 1e-6 * (1.0 + b.abs()))
    })
}

/// Past the inner vertex V of a 110° bend, a UAV sliding along the first leg's inner wall towards V is
/// behind the second leg's inner wall (its foot inside that wall): that wall, whose nearest point
/// approaches V, must still have its row (stress seed 225 with `rl` met V's row only at b ≈ 0).
#[test]
fn the_next_wall_is_guarded_from_behind_past_a_sharp_inner_vertex() {
    let heading = 110f64.to_radians();
    let points = [[0.0, 0.0], [6.0, 0.0], [6.0 + 6.0 * heading.cos(), 6.0 * heading.sin()]];
    let road = Road::new(RoadLayout::from_centerline(&points, &[2.0; 3])).unwrap();
    let params = Params::default();
    // The first leg's left (inner) wall is y = 1 up to V ≈ (4.57, 1); slide along it at 0.26 m, 2.6 m/s
    // towards V, 0.97 m before it.
    let (p, v) = (Vec2::new(3.6, 0.74), Vec2::new(2.6, 0.0));
    assert!(road.contains(&p));
    let behind = road.walls().iter().any(|w| {
        let (_, t) = w.nearest(&p);
        t > 0.0 && t < 1.0 && w.signed_distance(&p) < 0.0
    });
    assert!(behind, "the test point must stand behind a wall's line, inside its slab");
    let mut rows: Vec<Row> = Vec::new();
    let segment = SegmentTracker::default().update(&road, &p);
    road_rows(&road, RoadRule::Walls, p, v, segment, &params, &mut rows);
    let radius = safety::activation_radius(params.d_s, v.norm(), params.delta);
    assert_eq!(unguarded_wall(&road, p, v, &params, radius, &rows), None, "{rows:#?}");
}
