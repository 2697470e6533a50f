//! Random road networks for `airroads stress --family` (docs/scenarios.md "Road networks"): a T and a
//! Y junction, a 4-way crossing, a merge of two one-way roads, a roundabout, a street grid and a ring
//! with spokes, each with random geometry (turned by a random angle) and random traffic between the
//! far ends of its roads (in the grid, between random points). Each generator retries until the
//! scenario validates.

use crate::runs::families::Family;
use crate::scenario::{Scenario, ScenarioUav};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use std::f64::consts::{PI, TAU};
use uav::{Params, Vec2};

/// Simulated time limit (s) of a network case: routes through a grid or round a ring are long.
pub const NETWORK_T_MAX_S: f64 = 120.0;

/// The scenario of case `seed` of the network family `family` (None for a family on one road).
pub(crate) fn scenario(family: Family, seed: u64) -> Option<Scenario> {
    let mut rng = StdRng::seed_from_u64(seed);
    let params = Params { t_max: NETWORK_T_MAX_S, ..Params::default() };
    loop {
        let (layout, ends) = match family {
            Family::Tee => {
                let v = rectangle(&mut rng);
                star(&mut rng, &v, &[0, 1, 3])
            }
            Family::Wye => {
                let v = on_circle(&mut rng, 3, 15.0);
                star(&mut rng, &v, &[0, 1, 2])
            }
            Family::Crossing => {
                let v = on_circle(&mut rng, 4, 10.0);
                star(&mut rng, &v, &[0, 1, 2, 3])
            }
            Family::Merge => merge(&mut rng),
            Family::Roundabout => ring(&mut rng, 3..=5, true),
            Family::Grid => grid(&mut rng),
            Family::Ring => ring(&mut rng, 5..=8, false),
            Family::Mixed
            | Family::Bends
            | Family::Bottleneck
            | Family::HeadOn
            | Family::Hairpin
            | Family::Crowd => {
                return None;
            }
        };
        let turn = rng.random_range(0.0..TAU);
        let layout = turned(layout, turn);
        let Ok(net) = Network::new(layout.clone(), crate::scenario::min_passage_m(&params)) else { continue };
        let uavs = traffic(&mut rng, &net, &ends, &params);
        if uavs.len() < 2 {
            continue;
        }
        let name = format!("{}-{seed}", family.name());
        let (roads, junctions) = (Some(layout.roads), Some(layout.junctions));
        let scenario = Scenario { name, params, segments: Vec::new(), regions: None, roads, junctions, uavs };
        if scenario.validate().is_ok() {
            return Some(scenario);
        }
    }
}

/// Where the traffic of a network flies: `from` roads' far ends to `to` roads' far ends (indices
/// into the layout's roads), or anywhere to anywhere when both are empty.
struct Ends {
    from: Vec<usize>,
    to: Vec<usize>,
    /// The `from` roads end at the junction: their far ends are their starts (a merge's).
    from_start: bool,
    /// UAVs wanted.
    uavs: std::ops::RangeInclusive<usize>,
}

pub(super) fn xy(p: Vec2) -> [f64; 2] {
    [p.x, p.y]
}

/// A road through `edges` (each `(a, b)`: the a ends along one wall, the b ends along the other),
/// one segment between consecutive edges; the first and last edges are exactly as given.
pub(super) fn road_through(name: String, edges: &[(Vec2, Vec2)], one_way: bool) -> NetworkRoad {
    let segments = edges
        .windows(2)
        .map(|w| {
            let ((a0, b0), (a1, b1)) = (w[0], w[1]);
            [xy(a1), xy(a0), xy(b1), xy(b0)]
        })
        .collect();
    NetworkRoad { name, segments, one_way, speed_limit: None }
}

/// A straight road from edge `from` to edge `to` in pieces of about 3 m.
fn straight(name: String, from: (Vec2, Vec2), to: (Vec2, Vec2), one_way: bool) -> NetworkRoad {
    let length = ((to.0 + to.1) / 2.0 - (from.0 + from.1) / 2.0).norm();
    let pieces = (length / 3.0).ceil().max(1.0) as usize;
    let at = |i: usize| {
        if i == 0 {
            from
        } else if i == pieces {
            to
        } else {
            let t = i as f64 / pieces as f64;
            (from.0 + (to.0 - from.0) * t, from.1 + (to.1 - from.1) * t)
        }
    };
    let edges: Vec<(Vec2, Vec2)> = (0..=pieces).map(at).collect();
    road_through(name, &edges, one_way)
}

/// Side `k` of the counter-clockwise polygon `v` and its outward normal.
fn side(v: &[Vec2], k: usize) -> (Vec2, Vec2, Vec2) {
    let (a, b) = (v[k], v[(k + 1) % v.len()]);
    let e = (b - a).normalize();
    (a, b, Vec2::new(e.y, -e.x))
}

/// The road leaving side `k` of junction polygon `v` outwards, `length` m long.
fn spoke(name: String, v: &[Vec2], k: usize, length: f64) -> NetworkRoad {
    let (a, b, out) = side(v, k);
    straight(name, (a, b), (a + out * length, b + out * length), false)
}

/// A rectangle 1.6–4 m by 1.6–4 m round the origin, counter-clockwise from its lower left corner.
fn rectangle(rng: &mut StdRng) -> Vec<Vec2> {
    let (w, h) = (rng.random_range(1.6..4.0) / 2.0, rng.random_range(1.6..4.0) / 2.0);
    vec![Vec2::new(-w, -h), Vec2::new(w, -h), Vec2::new(w, h), Vec2::new(-w, h)]
}

/// A polygon of `n` vertices on a circle of radius 1.2–2.8 m, evenly spaced but each moved by up
/// to `jitter_deg`, counter-clockwise.
fn on_circle(rng: &mut StdRng, n: usize, jitter_deg: f64) -> Vec<Vec2> {
    let radius = rng.random_range(1.2..2.8);
    (0..n)
        .map(|k| {
            let a = TAU * k as f64 / n as f64 + rng.random_range(-jitter_deg..=jitter_deg).to_radians();
            Vec2::new(radius * a.cos(), radius * a.sin())
        })
        .collect()
}

pub(super) fn polygon(name: &str, v: &[Vec2]) -> Junction {
    Junction { name: name.into(), polygon: v.iter().map(|&p| xy(p)).collect() }
}

/// A junction with a two-way road 6–14 m long leaving each of its sides `open`; traffic between
/// every pair of their far ends.
fn star(rng: &mut StdRng, v: &[Vec2], open: &[usize]) -> (NetworkLayout, Ends) {
    let roads = open.iter().map(|&k| spoke(format!("r{k}"), v, k, rng.random_range(6.0..14.0))).collect();
    let all: Vec<usize> = (0..open.len()).collect();
    let layout = NetworkLayout { roads, junctions: vec![polygon("j", v)], regions: None };
    (layout, Ends { from: all.clone(), to: all, from_start: false, uavs: 2..=16 })
}

/// Two one-way roads into a triangular junction and one out of it: traffic from both into the one.
fn merge(rng: &mut StdRng) -> (NetworkLayout, Ends) {
    let v = on_circle(rng, 3, 15.0);
    let mut roads = Vec::new();
    for k in 0..2 {
        let (a, b, out) = side(&v, k);
        let length = rng.random_range(8.0..16.0);
        roads.push(straight(format!("in{k}"), (a + out * length, b + out * length), (a, b), true));
    }
    let (a, b, out) = side(&v, 2);
    let length = rng.random_range(10.0..20.0);
    roads.push(straight("out".into(), (a, b), (a + out * length, b + out * length), true));
    let layout = NetworkLayout { roads, junctions: vec![polygon("j", &v)], regions: None };
    (layout, Ends { from: vec![0, 1], to: vec![2], from_start: true, uavs: 2..=12 })
}

/// A ring round an island: `entries` junctions on it, each with a spoke, joined by ring roads
/// (one-way counter-clockwise for a roundabout); traffic between the spokes' far ends.
fn ring(
    rng: &mut StdRng,
    entries: std::ops::RangeInclusive<usize>,
    roundabout: bool,
) -> (NetworkLayout, Ends) {
    let n = rng.random_range(entries);
    let inner = rng.random_range(if roundabout { 1.5..3.5 } else { 6.0..12.0 });
    let outer = inner + rng.random_range(1.5..3.0);
    // Half the angle an entry junction spans: its outer side 1.5–3 m long, at most a third of the gap.
    let half = (rng.random_range(1.5..3.0f64) / (2.0 * outer)).asin().min(PI / (3.0 * n as f64));
    let at = |r: f64, a: f64| Vec2::new(r * a.cos(), r * a.sin());
    let (mut roads, mut junctions) = (Vec::new(), Vec::new());
    for k in 0..n {
        let centre = TAU * k as f64 / n as f64;
        let (lo, hi) = (centre - half, centre + half);
        let v = [at(inner, lo), at(outer, lo), at(outer, hi), at(inner, hi)];
        junctions.push(polygon(&format!("e{k}"), &v));
        roads.push(spoke(format!("s{k}"), &v, 1, rng.random_range(5.0..12.0)));
        // The ring road from this entry to the next, in pieces of about 15°.
        let next = TAU * (k + 1) as f64 / n as f64 - half;
        let pieces = ((next - hi) / 15f64.to_radians()).ceil().max(1.0) as usize;
        let edge = |i: usize| {
            let a = if i == pieces { next } else { hi + (next - hi) * i as f64 / pieces as f64 };
            let a = if i == 0 { hi } else { a };
            (at(inner, a), at(outer, a))
        };
        let edges: Vec<(Vec2, Vec2)> = (0..=pieces).map(edge).collect();
        roads.push(road_through(format!("ring{k}"), &edges, roundabout));
    }
    // The last ring road must end exactly on the first entry's side (the angle TAU − half is not
    // bitwise −half turned once round): snap its last edge to that side.
    if let Some(last) = roads.last_mut() {
        let first = &junctions[0].polygon;
        let end = last.segments.len() - 1;
        last.segments[end][0] = first[0];
        last.segments[end][2] = first[1];
    }
    let spokes: Vec<usize> = (0..n).map(|k| 2 * k).collect();
    let layout = NetworkLayout { roads, junctions, regions: None };
    let uavs = 3..=if roundabout { 16 } else { 24 };
    (layout, Ends { from: spokes.clone(), to: spokes, from_start: false, uavs })
}

/// A street grid of 2–4 × 2–4 square junctions 8–16 m apart, streets 2–4 m wide; traffic between
/// random points.
fn grid(rng: &mut StdRng) -> (NetworkLayout, Ends) {
    let (nx, ny) = (rng.random_range(2..=4usize), rng.random_range(2..=4usize));
    let pitch = rng.random_range(8.0..16.0);
    let half = rng.random_range(1.0..2.0);
    let mut layout = NetworkLayout { roads: Vec::new(), junctions: Vec::new(), regions: None };
    let square = |x: f64, y: f64| {
        [
            Vec2::new(x - half, y - half),
            Vec2::new(x + half, y - half),
            Vec2::new(x + half, y + half),
            Vec2::new(x - half, y + half),
        ]
    };
    for i in 0..nx {
        for j in 0..ny {
            let v = square(pitch * i as f64, pitch * j as f64);
            layout.junctions.push(polygon(&format!("j{i}-{j}"), &v));
            if i + 1 < nx {
                let w = square(pitch * (i + 1) as f64, pitch * j as f64);
                layout.roads.push(straight(format!("h{i}-{j}"), (v[1], v[2]), (w[0], w[3]), false));
            }
            if j + 1 < ny {
                let w = square(pitch * i as f64, pitch * (j + 1) as f64);
                layout.roads.push(straight(format!("v{i}-{j}"), (v[3], v[2]), (w[0], w[1]), false));
            }
        }
    }
    (layout, Ends { from: Vec::new(), to: Vec::new(), from_start: false, uavs: 4..=24 })
}

/// `layout` turned by `angle` about the origin (every vertex by the same arithmetic, so shared
/// vertices stay equal).
fn turned(mut layout: NetworkLayout, angle: f64) -> NetworkLayout {
    let (c, s) = (angle.cos(), angle.sin());
    let turn = |p: &mut [f64; 2]| *p = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
    for road in &mut layout.roads {
        road.segments.iter_mut().flatten().for_each(turn);
    }
    for junction in &mut layout.junctions {
        junction.polygon.iter_mut().for_each(turn);
    }
    layout
}

/// A random point of the network's cells `cells` at least D_s + 0.2 m from every wall and D_c + 0.3 m
/// from every point in `taken`.
fn sample(rng: &mut StdRng, net: &Network, cells: &[usize], taken: &[Vec2], p: &Params) -> Option<Vec2> {
    (0..200).find_map(|_| {
        let v = &net.cells()[cells[rng.random_range(0..cells.len())]].vertices;
        let w: Vec<f64> = (0..v.len()).map(|_| rng.random_range(0.05..1.0f64)).collect();
        let x = v.iter().zip(&w).map(|(p, w)| p * *w).sum::<Vec2>() / w.iter().sum::<f64>();
        let room = net.boundary_distance(&x) >= p.d_s + 0.2;
        (room && taken.iter().all(|t| (t - x).norm() >= p.d_c + 0.3)).then_some(x)
    })
}

/// The cells of road `road`'s last two segments, or its first two when `at_start`: its far end.
fn far_end(net: &Network, road: usize, at_start: bool) -> Vec<usize> {
    let cells = net.cells();
    let of_road: Vec<usize> = (0..cells.len())
        .filter(|&c| matches!(cells[c].kind, roads::network::CellKind::Segment { road: r, .. } if r == road))
        .collect();
    let keep = 2.min(of_road.len());
    if at_start { of_road[..keep].to_vec() } else { of_road[of_road.len() - keep..].to_vec() }
}

/// Random traffic: UAVs from the far ends of `ends.from` to those of `ends.to` (another road), or
/// between random points of the whole network.
fn traffic(rng: &mut StdRng, net: &Network, ends: &Ends, p: &Params) -> Vec<ScenarioUav> {
    let wanted = rng.random_range(ends.uavs.clone());
    let everywhere: Vec<usize> = (0..net.cells().len()).collect();
    let (mut starts, mut goals, mut uavs) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..wanted {
        let (from, to) = if ends.from.is_empty() {
            (everywhere.clone(), everywhere.clone())
        } else {
            let a = ends.from[rng.random_range(0..ends.from.len())];
            let others: Vec<usize> = ends.to.iter().copied().filter(|&b| b != a).collect();
            let b = if others.is_empty() { a } else { others[rng.random_range(0..others.len())] };
            (far_end(net, a, ends.from_start), far_end(net, b, false))
        };
        let (Some(start), Some(goal)) =
            (sample(rng, net, &from, &starts, p), sample(rng, net, &to, &goals, p))
        else {
            continue;
        };
        starts.push(start);
        goals.push(goal);
        uavs.push(ScenarioUav { id: format!("u{i}"), start: xy(start), goal: xy(goal), link: None });
    }
    uavs
}
