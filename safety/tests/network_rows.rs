//! The walls rule on road networks (docs/safety.md §5.1): on random junctions (convex polygons of 3
//! to 8 sides with roads leaving some of their sides), a UAV that starts anywhere it could still stop
//! and is pushed at full input δ in a random direction for 3 s stays in the network and never comes
//! closer than D_s (less the sampling slack) to a wall or a wall's end, the junction's corners
//! included; and every row with b ≥ 0 is met by braking straight away from its wall.

use proptest::prelude::*;
use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use safety::{Row, SafetyFilter, network_rows};
use uav::{Params, UavState, Vec2};

/// As in `road_rows.rs`: how far one 50 ms step may carry a UAV past a row's boundary.
const SAMPLING_SLACK_M: f64 = 0.001;

/// A regular `sides`-gon of circumradius `radius` turned by `turn`, with a straight road of
/// `pieces` segments of `length` m leaving each side whose bit is set in `open` (at least one).
fn junction(sides: usize, radius: f64, turn: f64, open: u8, pieces: usize, length: f64) -> Option<Network> {
    let corner = |k: usize| {
        let a = turn + std::f64::consts::TAU * k as f64 / sides as f64;
        Vec2::new(radius * a.cos(), radius * a.sin())
    };
    let corners: Vec<Vec2> = (0..sides).map(corner).collect();
    let mut roads = Vec::new();
    let open = match u32::from(open) & ((1u32 << sides) - 1) {
        0 => 1,
        some => some,
    };
    for k in (0..sides).filter(|k| open & (1 << k) != 0) {
        let (a, b) = (corners[k], corners[(k + 1) % sides]);
        let e = (b - a).normalize();
        let out = Vec2::new(e.y, -e.x); // the polygon turns counter-clockwise: outwards is on the right
        let at = |p: Vec2, i: usize| {
            let q = p + out * (length * i as f64);
            [q.x, q.y]
        };
        let segments = (0..pieces).map(|i| [at(a, i + 1), at(a, i), at(b, i + 1), at(b, i)]).collect();
        roads.push(NetworkRoad { name: format!("r{k}"), segments, one_way: false, speed_limit: None });
    }
    let polygon = corners.iter().map(|c| [c.x, c.y]).collect();
    let layout =
        NetworkLayout { roads, junctions: vec![Junction { name: "j".into(), polygon }], regions: None };
    // A triangle with a closed side has a corner of 60° between walls: refused (`sharp_corner`).
    Network::new(layout, 0.5).ok()
}

fn network() -> impl Strategy<Value = Option<Network>> {
    (3usize..=8, 1.0f64..4.0, 0.0..std::f64::consts::TAU, any::<u8>(), 1usize..4, 0.5f64..3.0).prop_map(
        |(sides, radius, turn, open, pieces, length)| junction(sides, radius, turn, open, pieces, length),
    )
}

/// A point of cell `cell` from three weights (a convex combination of three of its vertices).
fn point_in(net: &Network, cell: usize, w: (f64, f64, f64)) -> Vec2 {
    let v = &net.cells()[cell % net.cells().len()].vertices;
    let total = w.0 + w.1 + w.2;
    (v[0] * w.0 + v[v.len() / 2] * w.1 + v[v.len() - 1] * w.2) / total
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn pushed_at_full_input_a_uav_keeps_d_s_from_every_wall_of_a_junction(
        net in network(),
        cell in 0usize..64,
        w in (0.01f64..1.0, 0.01f64..1.0, 0.01f64..1.0),
        (fraction, angle) in (0.0..0.8f64, 0.0..std::f64::consts::TAU),
        push in 0.0..std::f64::consts::TAU,
    ) {
        let Some(net) = net else { return Ok(()) };
        let params = Params::default();
        let p = point_in(&net, cell, w);
        let d = net.boundary_distance(&p);
        prop_assume!(net.contains(&p) && d > params.d_s);
        let speed = fraction * (2.0 * params.delta * (d - params.d_s)).sqrt().min(4.0);
        let mut state = UavState { p, v: Vec2::new(angle.cos(), angle.sin()) * speed };
        let u_ref = Vec2::new(push.cos(), push.sin()) * params.delta;
        let (mut filter, mut rows): (SafetyFilter, Vec<Row>) = (SafetyFilter::default(), Vec::new());
        let mut cell = net.locate(&p).unwrap_or(0);
        for tick in 0..60 {
            cell = net.locate(&state.p).unwrap_or(cell);
            rows.clear();
            network_rows(&net, state.p, state.v, cell, &params, &mut rows);
            for r in rows.iter().filter(|r| r.b >= 0.0) {
                prop_assert!(r.a.dot(&(-r.a * params.delta)) <= r.c + 1e-9, "row {:?} not met by full braking", r);
            }
            let f = filter.filter(u_ref, state.v, &rows, params.delta, params.dt);
            state = state.stepped(f.u, params.dt);
            let d = net.boundary_distance(&state.p);
            prop_assert!(net.contains(&state.p), "tick {tick}: left the network at {:?}", state.p);
            prop_assert!(d >= params.d_s - SAMPLING_SLACK_M, "tick {tick}: {d:.4} m from the walls at {:?}", state.p);
        }
    }
}
