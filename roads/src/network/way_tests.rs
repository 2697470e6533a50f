use super::*;
use crate::network::tests::{crossing, grid};
use crate::network::{Junction, NetworkLayout, NetworkRoad};
use proptest::prelude::*;

const RULE: GateRule = GateRule { clearance: 0.2, keep_right: None };

/// A regular `sides`-gon of circumradius `radius` turned by `turn`, with a straight road of
/// `pieces` segments of `length` m leaving each side whose bit is set in `open` (at least one).
fn junction(sides: usize, radius: f64, turn: f64, open: u8, pieces: usize, length: f64) -> Option<Network> {
    let corner = |k: usize| {
        let a = turn + std::f64::consts::TAU * k as f64 / sides as f64;
        Vec2::new(radius * a.cos(), radius * a.sin())
    };
    let corners: Vec<Vec2> = (0..sides).map(corner).collect();
    let open = match u32::from(open) & ((1u32 << sides) - 1) {
        0 => 1,
        some => some,
    };
    let mut roads = Vec::new();
    for k in (0..sides).filter(|k| open & (1 << k) != 0) {
        let (a, b) = (corners[k], corners[(k + 1) % sides]);
        let e = (b - a).normalize();
        let out = Vec2::new(e.y, -e.x);
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

/// A point of cell `cell` from three weights (a convex combination of three of its vertices).
fn point_in(net: &Network, cell: usize, w: (f64, f64, f64)) -> Vec2 {
    let v = &net.cells()[cell % net.cells().len()].vertices;
    let total = w.0 + w.1 + w.2;
    (v[0] * w.0 + v[v.len() / 2] * w.1 + v[v.len() - 1] * w.2) / total
}

/// True when the straight path a→b stays in the network (sampled every 1 cm).
fn inside_all_along(net: &Network, a: Vec2, b: Vec2) -> bool {
    let n = ((b - a).norm() / 0.01).ceil().max(1.0) as usize;
    (0..=n).all(|k| net.contains(&(a + (b - a) * (k as f64 / n as f64))))
}

/// Moves a point to its target by at most `step` m a tick until it is at the goal (or `ticks` pass);
/// checks that every target is seen inside the network; returns the ticks taken and the smallest
/// distance to a wall on the way (from the first tick at least `r_s` from the start).
fn fly(
    net: &Network,
    way: &mut Way,
    from: Vec2,
    step: f64,
    ticks: usize,
) -> Result<(usize, f64), TestCaseError> {
    let mut p = from;
    let mut closest = f64::INFINITY;
    for tick in 0..ticks {
        prop_assert!(way.follow(net, p), "left its route at {:?} (tick {})", p, tick);
        let target = way.target(net, p, 5.0);
        prop_assert!(target.x.is_finite() && target.y.is_finite());
        prop_assert!(inside_all_along(net, p, target), "target {:?} not seen from {:?}", target, p);
        if (p - way.goal()).norm() < 1e-9 {
            return Ok((tick, closest));
        }
        let d = target - p;
        let moved = if d.norm() <= step { target } else { p + d * (step / d.norm()) };
        prop_assert!(moved != p || d.norm() > 0.0, "stuck at {:?}", p);
        p = moved;
        if (p - from).norm() > 1.0 && (p - way.goal()).norm() > 1.0 {
            closest = closest.min(net.boundary_distance(&p));
        }
    }
    Err(TestCaseError::fail(format!("not home after {ticks} ticks: at {p:?}, goal {:?}", way.goal())))
}

#[test]
fn the_taut_path_turns_a_corner_of_a_crossing_at_its_clearance() {
    let net = Network::new(crossing(), 0.5).unwrap();
    let (from, to) = (Vec2::new(7.0, 0.0), Vec2::new(0.0, 7.0));
    let mut way = net.way(from, to, RULE, |_, _| 0.0).unwrap();
    assert!(way.follow(&net, from));
    // From the east road to the north road: the string pulls round the junction's corner (2, 2),
    // held off it by the clearance along both passages.
    let path = way.taut_path(from, 100.0, usize::MAX, way.goal());
    assert_eq!(path.len(), 4, "{path:?}");
    assert!((path[1] - Vec2::new(2.0, 1.8)).norm() < 1e-9, "{path:?}");
    assert!((path[2] - Vec2::new(1.8, 2.0)).norm() < 1e-9, "{path:?}");
    assert_eq!(path[3], to);
    // Far from the corner the target lies on the first leg, r_s ahead.
    let target = way.target(&net, from, 3.0);
    assert!((target - from).norm() <= 3.0 + 1e-9 && way.sees(&net, from, target));
    assert!(!way.sees(&net, from, to), "the goal round the corner is not seen from the east road");
}

#[test]
fn keeping_right_crosses_each_passage_in_its_right_half() {
    let net = Network::new(crossing(), 0.5).unwrap();
    let rule = GateRule { clearance: 0.2, keep_right: Some(0.3) };
    let (from, to) = (Vec2::new(7.0, -1.0), Vec2::new(-7.0, -1.0));
    let way = net.way(from, to, rule, |_, _| 0.0).unwrap();
    // Flying west (−x), its right is north (+y): each gate is the part 0.3 m or more north of the middle.
    for gate in &way.gates {
        assert!(gate.left.y >= 0.3 - 1e-9 && gate.right.y >= 0.3 - 1e-9, "{gate:?}");
    }
    // The goal itself lies in the other half: the last leg leaves the lane to reach it.
    let path = way.taut_path(from, 100.0, usize::MAX, way.goal());
    assert_eq!(path.last(), Some(&to));
}

#[test]
fn a_way_is_refused_outside_and_goes_back_against_a_one_way_road_only_without_a_legal_one() {
    let net = Network::new(crossing(), 0.5).unwrap();
    assert!(net.way(Vec2::new(7.0, 5.0), Vec2::new(0.0, 7.0), RULE, |_, _| 0.0).is_none());
    // East one-way, flown from the junction outwards: a UAV pushed out along it past its goal has no
    // legal way back, so it flies back against it (rather than hover there for ever).
    let mut layout = crossing();
    layout.roads[0].one_way = true;
    let one_way = Network::new(layout, 0.5).unwrap();
    let (east_end, east_start) = (Vec2::new(7.0, 0.0), Vec2::new(3.0, 0.0));
    let (from, to) = (one_way.locate(&east_end).unwrap(), one_way.locate(&east_start).unwrap());
    assert!(one_way.route((from, east_end), (to, east_start), |_, _| 0.0).is_none());
    let back = one_way.way(east_end, east_start, RULE, |_, _| 0.0).expect("the way back");
    assert_eq!(back.cells().first(), Some(&from));
    assert_eq!(back.cells().last(), Some(&to));
    // Where a legal route exists, it is the way planned.
    let north = Vec2::new(0.0, 7.0);
    let legal =
        one_way.route((one_way.locate(&north).unwrap(), north), (from, east_end), |_, _| 0.0).unwrap();
    let way = one_way.way(north, east_end, RULE, |_, _| 0.0).unwrap();
    assert_eq!(way.cells(), &legal.cells[..]);
}

fn junction_net() -> impl Strategy<Value = Option<Network>> {
    (3usize..=8, 1.5f64..4.0, 0.0..std::f64::consts::TAU, any::<u8>(), 1usize..4, 0.5f64..3.0).prop_map(
        |(sides, radius, turn, open, pieces, length)| junction(sides, radius, turn, open, pieces, length),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// On random junctions (3 to 8 sides, roads leaving any of them, so turns round shared corners
    /// too), a point that flies to its target 0.2 m a tick from anywhere to anywhere only ever aims
    /// at targets it sees inside the network, never leaves its route, and arrives.
    #[test]
    fn through_random_junctions_every_target_is_seen_and_the_goal_reached(
        net in junction_net(), a in 0usize..100, b in 0usize..100,
        wa in (0.1f64..1.0, 0.1f64..1.0, 0.1f64..1.0), wb in (0.1f64..1.0, 0.1f64..1.0, 0.1f64..1.0),
        keep_right in any::<bool>(),
    ) {
        let Some(net) = net else { return Ok(()) };
        let (from, to) = (point_in(&net, a, wa), point_in(&net, b, wb));
        let rule = GateRule { clearance: 0.2, keep_right: keep_right.then_some(0.25) };
        let mut way = net.way(from, to, rule, |_, _| 0.0).expect("a two-way network is connected");
        let length = way.remaining(from);
        let (ticks, _) = fly(&net, &mut way, from, 0.2, 20_000)?;
        // No detours: at most the gate-to-gate polyline's length, and a tick for each corner.
        prop_assert!(ticks as f64 <= length / 0.2 + way.cells().len() as f64 + 2.0, "{} ticks for {} m", ticks, length);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Across random street grids the same holds, and away from its start and goal the point keeps
    /// at least the openings' clearance (half the gates') times cos 45° from every wall: it turns
    /// corners held off them.
    #[test]
    fn across_random_grids_the_way_keeps_off_the_walls(
        nx in 1usize..5, ny in 1usize..5, pitch in 8.0f64..20.0, pieces in 1usize..3,
        a in 0usize..1000, b in 0usize..1000,
        wa in (0.1f64..1.0, 0.1f64..1.0, 0.1f64..1.0), wb in (0.1f64..1.0, 0.1f64..1.0, 0.1f64..1.0),
    ) {
        prop_assume!(nx * ny > 1);
        let net = Network::new(grid(nx, ny, pitch, 2.0, pieces), 0.5).unwrap();
        let (from, to) = (point_in(&net, a, wa), point_in(&net, b, wb));
        let start_clear = net.boundary_distance(&from).min(net.boundary_distance(&to));
        let mut way = net.way(from, to, RULE, |_, _| 0.0).unwrap();
        let (_, closest) = fly(&net, &mut way, from, 0.2, 20_000)?;
        prop_assert!(closest >= (RULE.clearance / 2.0).min(start_clear) * std::f64::consts::FRAC_1_SQRT_2 - 1e-6, "{}", closest);
    }
}
