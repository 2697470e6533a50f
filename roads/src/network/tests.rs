use super::*;
use crate::validate::RoadRule;
use proptest::prelude::*;

/// A straight road of `n` equal segments along x from `x0` to `x1` (both exact), `width` wide
/// centred on y.
fn straight(name: &str, x0: f64, x1: f64, y: f64, n: usize, width: f64) -> NetworkRoad {
    let h = width / 2.0;
    let at = |i: usize| if i == n { x1 } else { x0 + (x1 - x0) * i as f64 / n as f64 };
    let segments = (0..n)
        .map(|i| {
            let (a, b) = (at(i), at(i + 1));
            // p1, p2, p3, p4: p2→p1 the left wall, p4→p3 the right, entry p2–p4, exit p1–p3.
            [[b, y + h], [a, y + h], [b, y - h], [a, y - h]]
        })
        .collect();
    NetworkRoad { name: name.into(), segments, one_way: false, speed_limit: None }
}

/// `road` turned by 90° counter-clockwise about the origin.
fn turned(mut road: NetworkRoad) -> NetworkRoad {
    for q in &mut road.segments {
        for p in q.iter_mut() {
            *p = [-p[1], p[0]];
        }
    }
    road
}

fn square(name: &str, cx: f64, cy: f64, half: f64) -> Junction {
    let polygon =
        vec![[cx - half, cy - half], [cx + half, cy - half], [cx + half, cy + half], [cx - half, cy + half]];
    Junction { name: name.into(), polygon }
}

/// A 4-way crossing: a 4 m junction at the origin and four 3-segment roads from its sides.
pub(super) fn crossing() -> NetworkLayout {
    let east = straight("east", 2.0, 8.0, 0.0, 3, 4.0);
    let west = straight("west", -8.0, -2.0, 0.0, 3, 4.0);
    let north = turned(straight("north", 2.0, 8.0, 0.0, 3, 4.0));
    let south = turned(straight("south", -8.0, -2.0, 0.0, 3, 4.0));
    NetworkLayout {
        roads: vec![east, west, north, south],
        junctions: vec![square("x", 0.0, 0.0, 2.0)],
        regions: None,
    }
}

fn rule(layout: NetworkLayout) -> (RoadRule, String) {
    let e = Network::new(layout, 0.5).expect_err("refused");
    (e.rule, e.field)
}

#[test]
fn a_chain_is_the_network_of_one_road() {
    let layout = RoadLayout::new(straight("r", 0.0, 8.0, 0.0, 4, 3.0).segments);
    let net = Network::new(NetworkLayout::from(&layout), 0.5).unwrap();
    assert_eq!(net.cells().len(), 4);
    // Two side walls per segment and the two end caps; three joins passable both ways.
    assert_eq!(net.walls().count(), 4 * 2 + 2);
    assert_eq!((0..4).map(|c| net.passages(c).len()).sum::<usize>(), 6);
}

#[test]
fn a_crossing_joins_four_roads_through_its_junction() {
    let net = Network::new(crossing(), 0.5).unwrap();
    let junction = net.cells().iter().position(|c| matches!(c.kind, CellKind::Junction { .. })).unwrap();
    assert_eq!(net.passages(junction).len(), 4, "every side of the junction is open");
    // The roads' outer ends stay walls: 4 roads × (3 × 2 sides + 1 end cap).
    assert_eq!(net.walls().count(), 4 * 7);
    for (a, b, c) in net.walls() {
        assert!(net.passages(c).iter().all(|p| {
            let v = &net.cells()[c].vertices;
            let (x, y) = (v[p.edge], v[(p.edge + 1) % v.len()]);
            (x, y) != (a, b)
        }));
    }
}

#[test]
fn each_rule_is_named_with_the_field_at_fault() {
    let mut nine = crossing();
    nine.junctions[0].polygon = (0..9).map(|k| [f64::from(k).cos(), f64::from(k).sin()]).collect();
    assert_eq!(rule(nine), (RoadRule::JunctionSides, "junctions[0].polygon".into()));

    let mut dart = crossing();
    dart.junctions[0].polygon = vec![[-2.0, -2.0], [2.0, -2.0], [0.0, 0.0], [-2.0, 2.0]];
    assert_eq!(rule(dart).0, RoadRule::NotConvex);

    let mut twice = crossing();
    twice.roads[1].name = "east".into();
    assert_eq!(rule(twice), (RoadRule::DuplicateName, "roads[1].name".into()));

    // A road attached to half a side of the junction.
    let mut half = crossing();
    half.roads[0] = straight("east", 2.0, 8.0, 1.0, 3, 2.0);
    assert_eq!(rule(half).0, RoadRule::PartialEdge);

    // A fifth road on the east road's cells.
    let mut over = crossing();
    over.roads.push(straight("over", 3.5, 6.5, 0.0, 2, 2.0));
    assert_eq!(rule(over).0, RoadRule::Overlap);

    // A road apart from the rest.
    let mut apart = crossing();
    apart.roads.push(straight("apart", 50.0, 54.0, 50.0, 2, 4.0));
    assert_eq!(rule(apart), (RoadRule::Disconnected, "roads[4].segments[0]".into()));

    // The same crossing, too narrow for its UAVs.
    let e = Network::new(crossing(), 4.5).unwrap_err();
    assert_eq!(e.rule, RoadRule::NarrowPassage);

    // A third cell on the junction's east edge: a triangle beyond the east road's first segment
    // cannot share it, but a second junction drawn on the same edge can.
    let mut three = crossing();
    three.junctions.push(Junction { name: "y".into(), polygon: vec![[2.0, -2.0], [2.0, 2.0], [0.5, 0.0]] });
    let (r, _) = rule(three);
    assert!(matches!(r, RoadRule::SharedByThree | RoadRule::Overlap), "{r:?}");

    let mut limit = crossing();
    limit.roads[2].speed_limit = Some(f64::NAN);
    assert_eq!(rule(limit), (RoadRule::SpeedLimit, "roads[2].speed_limit".into()));

    let mut joints = crossing();
    joints.roads[3].segments[1][1][0] += 0.5;
    assert_eq!(rule(joints).1, "roads[3].segments[1]");
}

#[test]
fn an_edge_of_three_cells_is_refused() {
    // Three triangles around one edge cannot be convex and apart, so build the count directly:
    // two junctions on either side of a road end, the road's end edge being both junctions' edge.
    let cells = vec![
        Cell {
            kind: CellKind::Segment { road: 0, segment: 0 },
            vertices: vec![
                Vec2::new(2.0, 1.0),
                Vec2::new(0.0, 1.0),
                Vec2::new(0.0, -1.0),
                Vec2::new(2.0, -1.0),
            ],
        },
        Cell {
            kind: CellKind::Junction { junction: 0 },
            vertices: vec![Vec2::new(2.0, 1.0), Vec2::new(2.0, -1.0), Vec2::new(3.0, 0.0)],
        },
        Cell {
            kind: CellKind::Junction { junction: 1 },
            vertices: vec![Vec2::new(2.0, -1.0), Vec2::new(2.0, 1.0), Vec2::new(4.0, 0.0)],
        },
    ];
    let e = check::passages(&cells).unwrap_err();
    assert_eq!((e.rule, e.field.as_str()), (RoadRule::SharedByThree, "junctions[1].polygon"));
}

/// A street grid: `nx` × `ny` junctions `pitch` apart, each `2·half` wide, joined by roads of
/// `pieces` segments.
pub(super) fn grid(nx: usize, ny: usize, pitch: f64, half: f64, pieces: usize) -> NetworkLayout {
    let mut layout = NetworkLayout { roads: Vec::new(), junctions: Vec::new(), regions: None };
    for i in 0..nx {
        for j in 0..ny {
            let (x, y) = (pitch * i as f64, pitch * j as f64);
            layout.junctions.push(square(&format!("j{i}-{j}"), x, y, half));
            if i + 1 < nx {
                let to = pitch * (i + 1) as f64 - half;
                layout.roads.push(straight(&format!("h{i}-{j}"), x + half, to, y, pieces, 2.0 * half));
            }
            if j + 1 < ny {
                // Built along x from the turned start, then turned: x' = -y, y' = x.
                let to = pitch * (j + 1) as f64 - half;
                let road = straight(&format!("v{i}-{j}"), y + half, to, -x, pieces, 2.0 * half);
                layout.roads.push(turned(road));
            }
        }
    }
    layout
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// On random street grids every cell edge is a wall or a passage, never both; passages pair up
    /// (each shared edge is seen from both cells); and the walls are exactly the grid's outline and
    /// the streets' sides.
    #[test]
    fn a_grid_is_valid_and_its_edges_are_walls_or_passages(
        nx in 1usize..5, ny in 1usize..5, pitch in 8.0f64..30.0, half in 1.0f64..3.0, pieces in 1usize..4,
    ) {
        prop_assume!(nx * ny > 1);
        let layout = grid(nx, ny, pitch, half, pieces);
        let net = Network::new(layout.clone(), 0.5).unwrap();
        let cells = net.cells();
        let edges: usize = cells.iter().map(|c| c.vertices.len()).sum();
        let open: usize = (0..cells.len()).map(|c| net.passages(c).len()).sum();
        prop_assert_eq!(net.walls().count() + open, edges);
        for c in 0..cells.len() {
            for p in net.passages(c) {
                let back = net.passages(p.other).iter().any(|q| q.other == c && q.edge == p.other_edge);
                prop_assert!(back);
            }
        }
        // Streets: pieces segments each, two passages per inner join, one at each end.
        let streets = nx * (ny - 1) + ny * (nx - 1);
        prop_assert_eq!(open, streets * 2 * (pieces + 1));
        // A junction side with no street is a wall: 4 per junction minus the streets' ends.
        prop_assert_eq!(net.walls().count(), streets * 2 * pieces + 4 * nx * ny - 2 * streets);
    }

    /// Moving one vertex of a street's end off the junction's corner breaks the exact join: the
    /// network is refused (a partial edge, a seam, a non-convex cell or a piece cut off), never
    /// accepted with a gap in a wall.
    #[test]
    fn a_street_end_off_its_junction_is_refused(
        nx in 2usize..4, pitch in 10.0f64..20.0, dx in -0.4f64..0.4, dy in -0.4f64..0.4, which in 0usize..4,
    ) {
        prop_assume!(dx.abs() > 1e-6 || dy.abs() > 1e-6);
        let mut layout = grid(nx, 1, pitch, 2.0, 2);
        let last = layout.roads[0].segments.len() - 1;
        let (segment, vertex) = [(0, 1), (0, 3), (last, 0), (last, 2)][which];
        layout.roads[0].segments[segment][vertex][0] += dx;
        layout.roads[0].segments[segment][vertex][1] += dy;
        prop_assert!(Network::new(layout, 0.5).is_err());
    }
}

fn cell_of(net: &Network, kind: CellKind) -> usize {
    net.cells().iter().position(|c| c.kind == kind).unwrap()
}

#[test]
fn a_route_crosses_the_junction_and_respects_one_way_roads() {
    let net = Network::new(crossing(), 0.5).unwrap();
    let east_end = cell_of(&net, CellKind::Segment { road: 0, segment: 2 });
    let north_end = cell_of(&net, CellKind::Segment { road: 2, segment: 2 });
    let x = cell_of(&net, CellKind::Junction { junction: 0 });
    let (from, to) = (Vec2::new(7.0, 0.0), Vec2::new(0.0, 7.0));
    let route = net.route((east_end, from), (north_end, to), |_, _| 0.0).unwrap();
    assert_eq!(route.cells.len(), 7);
    assert_eq!(route.cells[3], x);
    // Straight to the junction's east side, across to its north side, straight on: 5 + 2·√2 + 5 m.
    let length: f64 = route.waypoints.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    assert!((length - (10.0 + 8f64.sqrt())).abs() < 1e-9, "{length}");
    assert!((route.cost - length / CRUISE_MPS).abs() < 1e-9);

    // East one-way, flown from the junction outwards: nobody comes back in from its end.
    let mut layout = crossing();
    layout.roads[0].one_way = true;
    let one_way = Network::new(layout, 0.5).unwrap();
    assert!(one_way.route((east_end, from), (north_end, to), |_, _| 0.0).is_none());
    let out = one_way.route((north_end, to), (east_end, from), |_, _| 0.0).unwrap();
    assert_eq!(out.cells.first(), Some(&north_end));
    assert_eq!(out.cells.last(), Some(&east_end));
}

#[test]
fn a_route_takes_the_free_branch_when_one_is_jammed() {
    // Two junctions side by side and two below: from the top left to the bottom right there are two
    // routes of equal length; a queue at one makes the other the faster.
    let net = Network::new(grid(2, 2, 12.0, 2.0, 2), 0.5).unwrap();
    let junction = |i: usize, j: usize| cell_of(&net, CellKind::Junction { junction: 2 * i + j });
    let (a, b) = (junction(0, 1), junction(1, 0));
    let (from, to) = (Vec2::new(0.0, 12.0), Vec2::new(12.0, 0.0));
    let free = net.route((a, from), (b, to), |_, _| 0.0).unwrap();
    let first_turn = free.cells[1];
    // A queue of 60 s on the first passage of the free route.
    let jammed = net
        .route((a, from), (b, to), |cell, edge| {
            let p = net.passages(cell).iter().find(|p| p.edge == edge).unwrap();
            if cell == a && p.other == first_turn { 60.0 } else { 0.0 }
        })
        .unwrap();
    assert_ne!(jammed.cells[1], first_turn, "the jammed branch is avoided");
    assert!((jammed.cost - free.cost).abs() < 1e-9, "both branches are as long");
}

/// True when `x` is in the convex polygon `v` (either orientation), within 1e-9 m.
fn in_cell(v: &[Vec2], x: &Vec2) -> bool {
    let n = v.len();
    let sides: Vec<f64> = (0..n)
        .map(|k| {
            let e = v[(k + 1) % n] - v[k];
            uav::cross(&e, &(x - v[k])) / e.norm()
        })
        .collect();
    sides.iter().all(|s| *s >= -1e-9) || sides.iter().all(|s| *s <= 1e-9)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Between any two cells of a random grid there is a route; each leg of it lies in one cell (so
    /// the polyline never leaves the road), consecutive cells share a passage, and it costs its
    /// length at cruise speed, never less than the straight line.
    #[test]
    fn routes_on_a_grid_stay_in_their_cells(
        nx in 1usize..4, ny in 1usize..4, pitch in 8.0f64..20.0, pieces in 1usize..3,
        a in 0usize..1000, b in 0usize..1000,
    ) {
        prop_assume!(nx * ny > 1);
        let net = Network::new(grid(nx, ny, pitch, 2.0, pieces), 0.5).unwrap();
        let cells = net.cells();
        let (start, goal) = (a % cells.len(), b % cells.len());
        let centre = |c: usize| cells[c].vertices.iter().sum::<Vec2>() / cells[c].vertices.len() as f64;
        let (from, to) = (centre(start), centre(goal));
        let route = net.route((start, from), (goal, to), |_, _| 0.0).unwrap();
        prop_assert_eq!(route.cells.first(), Some(&start));
        prop_assert_eq!(route.cells.last(), Some(&goal));
        prop_assert_eq!(route.waypoints.len(), route.cells.len() + 1);
        for (k, pair) in route.cells.windows(2).enumerate() {
            prop_assert!(net.passages(pair[0]).iter().any(|p| p.other == pair[1]), "{} {}", k, pair[0]);
        }
        for (k, &c) in route.cells.iter().enumerate() {
            let (p, q) = (route.waypoints[k], route.waypoints[k + 1]);
            prop_assert!(in_cell(&cells[c].vertices, &p) && in_cell(&cells[c].vertices, &q), "leg {} leaves cell {}", k, c);
        }
        let length: f64 = route.waypoints.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        prop_assert!((route.cost - length / CRUISE_MPS).abs() < 1e-9);
        prop_assert!(length >= (to - from).norm() - 1e-9);
        // `route_cost` prices a route's cells as the search did, and with costs added per passage no
        // other route (the free one) is cheaper.
        let extra = |cell: usize, edge: usize| ((cell * 7 + edge) % 5) as f64;
        let priced = net.route((start, from), (goal, to), extra).unwrap();
        prop_assert!((net.route_cost(&priced.cells, from, to, extra).unwrap() - priced.cost).abs() < 1e-9);
        prop_assert!(net.route_cost(&route.cells, from, to, extra).unwrap() >= priced.cost - 1e-9);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The trees answer as the definitions: membership as "in some cell", the walls near a point as
    /// a scan of every wall, the boundary distance as the nearest wall's; and inside the network
    /// every wall's normal points to the side the point is on when the point is in its cell.
    #[test]
    fn where_things_are_agrees_with_a_scan(
        nx in 1usize..4, ny in 1usize..4, pitch in 8.0f64..20.0, pieces in 1usize..3,
        (x, y) in (-5.0f64..65.0, -5.0f64..65.0), radius in 0.1f64..6.0,
    ) {
        prop_assume!(nx * ny > 1);
        let net = Network::new(grid(nx, ny, pitch, 2.0, pieces), 0.5).unwrap();
        let p = Vec2::new(x, y);
        let inside = net.cells().iter().any(|c| space::margin(&c.vertices, &p) >= -1e-9);
        prop_assert_eq!(net.contains(&p), inside);
        for c in net.cells() {
            for tol in [0.0, 1e-9, 1e-6, 0.5] {
                prop_assert_eq!(space::within(&c.vertices, &p, tol), space::margin(&c.vertices, &p) >= -tol);
            }
        }
        let walls = net.wall_list();
        let scan: Vec<usize> = (0..walls.len()).filter(|&k| walls[k].nearest(&p).0.metric_distance(&p) <= radius).collect();
        prop_assert_eq!(net.walls_near(&p, radius), scan);
        let nearest = walls.iter().map(|w| w.nearest(&p).0.metric_distance(&p)).fold(f64::INFINITY, f64::min);
        prop_assert!((net.boundary_distance(&p) - nearest).abs() < 1e-9);
        if let Some(c) = net.locate(&p) {
            for w in walls.iter().filter(|w| w.segment == c) {
                prop_assert!(w.signed_distance(&p) >= -1e-9, "{:?} behind a wall of its own cell", p);
            }
        }
        prop_assert_eq!(walls.len(), net.walls().count());
        // With any cell as the hint (right, wrong or none), the cells' lists answer as the trees.
        let cells = net.cells().len();
        for hint in [0, cells / 2, net.locate(&p).unwrap_or(0), cells] {
            prop_assert_eq!(net.walls_near_in(hint, &p, radius).collect::<Vec<_>>(), net.walls_near(&p, radius));
            for wide in [radius + 3.0, radius + 10.0, radius + 20.0] {
                prop_assert_eq!(net.walls_near_in(hint, &p, wide).collect::<Vec<_>>(), net.walls_near(&p, wide));
            }
            prop_assert_eq!(net.boundary_distance_in(hint, &p).to_bits(), net.boundary_distance(&p).to_bits());
            prop_assert_eq!(net.contains_in(hint, &p), net.contains(&p));
        }
    }
}

#[test]
fn walls_meeting_at_less_than_90_degrees_are_refused() {
    // A triangular junction with one road: its far corner is 60° between two walls.
    let (a, b, c) = ([2.0, -2.0], [2.0, 2.0], [2.0 + 12f64.sqrt(), 0.0]);
    let west = straight("west", -6.0, 2.0, 0.0, 2, 4.0);
    let layout = NetworkLayout {
        roads: vec![west],
        junctions: vec![Junction { name: "tip".into(), polygon: vec![a, c, b] }],
        regions: None,
    };
    let (rule, field) = rule(layout);
    assert_eq!((rule, field.as_str()), (RoadRule::SharpCorner, "junctions[0].polygon"));
    // A square junction's dead-end corners are 90°: accepted.
    let square_end = NetworkLayout {
        roads: vec![straight("west", -6.0, -2.0, 0.0, 2, 4.0)],
        junctions: vec![square("end", 0.0, 0.0, 2.0)],
        regions: None,
    };
    assert!(Network::new(square_end, 0.5).is_ok());
}

#[test]
fn a_junction_between_limited_roads_takes_their_largest_limit() {
    let mut layout = grid(2, 1, 10.0, 2.0, 1);
    let junction =
        |net: &Network| net.cells().iter().position(|c| matches!(c.kind, CellKind::Junction { .. })).unwrap();
    let net = Network::new(layout.clone(), 0.5).unwrap();
    assert_eq!(net.speed_limit(junction(&net)), None);
    for (k, road) in layout.roads.iter_mut().enumerate() {
        road.speed_limit = Some(1.0 + k as f64);
    }
    let net = Network::new(layout.clone(), 0.5).unwrap();
    let j = junction(&net);
    let attached: Vec<f64> = net.passages(j).iter().filter_map(|p| net.speed_limit(p.other)).collect();
    assert!(!attached.is_empty());
    assert_eq!(net.speed_limit(j), attached.iter().copied().reduce(f64::max));
    layout.roads[0].speed_limit = None;
    let net = Network::new(layout, 0.5).unwrap();
    let unlimited = net.passages(junction(&net)).iter().any(|p| net.speed_limit(p.other).is_none());
    assert_eq!(net.speed_limit(junction(&net)).is_none(), unlimited);
}
