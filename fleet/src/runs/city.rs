//! The city grid of `airroads bench scale --road city` (BENCHMARKS.md "Fleet engine at scale"): a
//! street grid of B × B blocks, square junctions at the crossings joined by two-way streets, with
//! UAVs flying from random points of the streets to random goals a few blocks away. Sized from the
//! fleet so that each UAV has about as much street as on the trunk road of [`crate::trunk`], and
//! limited to 3 m/s on the streets as there.

use super::networks::{polygon, road_through, xy};
use crate::scenario::{Scenario, ScenarioUav, min_passage_m};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use roads::RoadError;
use roads::network::{Network, NetworkLayout, NetworkRoad};
use std::collections::HashMap;
use uav::{Params, Vec2};

/// Width (m) of a street, and the side of a junction's square.
pub const CITY_STREET_WIDTH_M: f64 = 6.0;
/// Distance (m) between the centres of neighbouring junctions: a block and a street.
pub const CITY_PITCH_M: f64 = 24.0;
/// UAVs per block of the grid sized by [`city_scenario`]: about 14 m² of street each, as on the trunk.
pub const CITY_UAVS_PER_BLOCK: f64 = 17.0;
/// Speed limit (m/s) of every street: the trunk road's traffic rules cap speed at 3 m/s as well;
/// without it the `rl` policy flies up to 7 m/s down a street, and every UAV's activation radius
/// with it. Routes are unchanged: they assume 2 m/s ([`roads::network::CRUISE_MPS`]).
pub const CITY_SPEED_LIMIT_MPS: f64 = 3.0;
/// Longest segment (m) of a street.
const SEGMENT_M: f64 = 9.0;
/// How far (m) starts and goals keep from a street's walls (D_s and room to set off or to hover).
const FROM_WALL_M: f64 = 0.5;
/// How far (m) starts and goals keep from the junctions (a UAV hovering at its goal must not stand
/// in a junction's mouth).
const FROM_JUNCTION_M: f64 = 1.5;
/// Smallest distance (m) between two starts: D_c and room to set off.
const START_SPACING_M: f64 = 1.0;
/// Smallest distance (m) between two goals: UAVs hovering at their goals leave room between them.
const GOAL_SPACING_M: f64 = 2.0;
/// Straight-line distance from a start to its goal, in pitches: a few blocks away.
const TRIP_PITCHES: std::ops::Range<f64> = 1.5..4.0;
/// Tries per point before the grid counts as too crowded.
const TRIES: usize = 1000;

/// Why a city grid could not be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CityError {
    /// The network was refused (beyond the cell limit: more than about 90 × 90 blocks).
    #[error("the street grid is refused: {0}")]
    Network(#[from] RoadError),
    /// No room for another start or goal at the spacings kept.
    #[error("{blocks} × {blocks} blocks have no room for {wanted} UAVs (placed {placed})")]
    Crowded {
        /// Blocks per side.
        blocks: usize,
        /// UAVs wanted.
        wanted: usize,
        /// UAVs placed before there was no room.
        placed: usize,
    },
}

/// The side (blocks) of the grid [`city_scenario`] builds for `n` UAVs: at least 2.
pub fn city_blocks(n: usize) -> usize {
    ((n as f64 / CITY_UAVS_PER_BLOCK).sqrt().ceil() as usize).max(2)
}

/// The city grid scenario with `n` UAVs (at least 2) on [`city_blocks`]`(n)` blocks a side,
/// reproducible from `seed`.
pub fn city_scenario(n: usize, seed: u64) -> Result<Scenario, CityError> {
    city_grid(city_blocks(n), n, seed)
}

/// A street in the grid's own frame: its lower left corner, its direction and the unit across it.
#[derive(Debug, Clone, Copy)]
struct Street {
    origin: Vec2,
    along: Vec2,
    across: Vec2,
}

/// A scenario on a street grid of `blocks` × `blocks` blocks with `n` UAVs (at least 2): starts
/// [`START_SPACING_M`] apart, goals [`GOAL_SPACING_M`] apart, each goal 1.5–4 pitches from its start,
/// all on the streets away from the junctions; reproducible from `seed`.
pub fn city_grid(blocks: usize, n: usize, seed: u64) -> Result<Scenario, CityError> {
    let (blocks, n) = (blocks.max(1), n.max(2));
    let mut rng = StdRng::seed_from_u64(seed);
    let (layout, streets) = grid_layout(blocks);
    let params = Params { t_max: 300.0, ..Params::default() };
    // Refused only beyond the cell limit: the grid is axis-aligned squares and rectangles that meet
    // along whole edges, with passages as wide as the streets.
    Network::new(layout.clone(), min_passage_m(&params))?;
    let length = CITY_PITCH_M - CITY_STREET_WIDTH_M;
    let point = |rng: &mut StdRng| {
        let s = streets[rng.random_range(0..streets.len())];
        let along = rng.random_range(FROM_JUNCTION_M..length - FROM_JUNCTION_M);
        let across = rng.random_range(FROM_WALL_M..CITY_STREET_WIDTH_M - FROM_WALL_M);
        s.origin + s.along * along + s.across * across
    };
    let crowded = |placed| CityError::Crowded { blocks, wanted: n, placed };
    let (mut starts, mut goals) = (Spaced::new(START_SPACING_M), Spaced::new(GOAL_SPACING_M));
    let mut uavs = Vec::with_capacity(n);
    for i in 0..n {
        let start = (0..TRIES).map(|_| point(&mut rng)).find(|p| starts.free(p)).ok_or(crowded(i))?;
        let trip = TRIP_PITCHES.start * CITY_PITCH_M..TRIP_PITCHES.end * CITY_PITCH_M;
        let goal = (0..TRIES)
            .map(|_| point(&mut rng))
            .find(|g| trip.contains(&(g - start).norm()) && goals.free(g))
            .ok_or(crowded(i))?;
        starts.insert(start);
        goals.insert(goal);
        uavs.push(ScenarioUav { id: format!("u{i}"), start: xy(start), goal: xy(goal), link: None });
    }
    let (roads, junctions) = (Some(layout.roads), Some(layout.junctions));
    let name = format!("city{n}");
    Ok(Scenario { name, params, segments: Vec::new(), regions: None, roads, junctions, uavs })
}

/// The grid's layout (junction (i, j) centred at pitch × (i, j)) and its streets.
fn grid_layout(blocks: usize) -> (NetworkLayout, Vec<Street>) {
    let half = CITY_STREET_WIDTH_M / 2.0;
    let square = |i: usize, j: usize| {
        let (x, y) = (CITY_PITCH_M * i as f64, CITY_PITCH_M * j as f64);
        [
            Vec2::new(x - half, y - half),
            Vec2::new(x + half, y - half),
            Vec2::new(x + half, y + half),
            Vec2::new(x - half, y + half),
        ]
    };
    let length = CITY_PITCH_M - CITY_STREET_WIDTH_M;
    let pieces = (length / SEGMENT_M).ceil() as usize;
    // The street from edge (a0, b0) to edge (a1, b1), a along one wall and b along the other.
    let street = |name: String, (a0, b0): (Vec2, Vec2), (a1, b1): (Vec2, Vec2)| {
        let at = |k: usize| {
            let t = k as f64 / pieces as f64;
            match k {
                0 => (a0, b0),
                k if k == pieces => (a1, b1),
                _ => (a0 + (a1 - a0) * t, b0 + (b1 - b0) * t),
            }
        };
        let edges: Vec<(Vec2, Vec2)> = (0..=pieces).map(at).collect();
        NetworkRoad { speed_limit: Some(CITY_SPEED_LIMIT_MPS), ..road_through(name, &edges, false) }
    };
    let mut layout = NetworkLayout { roads: Vec::new(), junctions: Vec::new(), regions: None };
    let mut streets = Vec::new();
    let (east, north) = (Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0));
    for i in 0..=blocks {
        for j in 0..=blocks {
            let v = square(i, j);
            layout.junctions.push(polygon(&format!("j{i}-{j}"), &v));
            if i < blocks {
                let w = square(i + 1, j);
                layout.roads.push(street(format!("h{i}-{j}"), (v[1], v[2]), (w[0], w[3])));
                streets.push(Street { origin: v[1], along: east, across: north });
            }
            if j < blocks {
                let w = square(i, j + 1);
                layout.roads.push(street(format!("v{i}-{j}"), (v[3], v[2]), (w[0], w[1])));
                streets.push(Street { origin: v[3], along: north, across: east });
            }
        }
    }
    (layout, streets)
}

/// Points kept at least `spacing` apart, in a hash grid of cells `spacing` wide.
struct Spaced {
    spacing: f64,
    cells: HashMap<(i64, i64), Vec<Vec2>>,
}

impl Spaced {
    fn new(spacing: f64) -> Self {
        Self { spacing, cells: HashMap::new() }
    }

    fn cell(&self, p: &Vec2) -> (i64, i64) {
        ((p.x / self.spacing).floor() as i64, (p.y / self.spacing).floor() as i64)
    }

    /// True when `p` is at least the spacing from every point kept.
    fn free(&self, p: &Vec2) -> bool {
        let (cx, cy) = self.cell(p);
        let near = (cx - 1..=cx + 1).flat_map(|x| (cy - 1..=cy + 1).map(move |y| (x, y)));
        near.filter_map(|c| self.cells.get(&c)).flatten().all(|q| (q - p).norm() >= self.spacing)
    }

    fn insert(&mut self, p: Vec2) {
        self.cells.entry(self.cell(&p)).or_default().push(p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn city_grids_are_valid_reproducible_and_spaced() {
        for (blocks, n, seed) in [(2, 2, 1), (4, 150, 2), (11, 2000, 3)] {
            let s = city_grid(blocks, n, seed).unwrap();
            assert_eq!(s.uavs.len(), n);
            let valid = s.validate().unwrap_or_else(|e| panic!("city {blocks} × {blocks}, {n}: {e}"));
            let net = valid.road.network().expect("a city grid is a network");
            assert_eq!(net.layout().junctions.len(), (blocks + 1) * (blocks + 1));
            assert_eq!(net.layout().roads.len(), 2 * blocks * (blocks + 1));
            assert!(
                net.layout().roads.iter().all(|r| r.speed_limit == Some(CITY_SPEED_LIMIT_MPS) && !r.one_way)
            );
            for u in &valid.uavs {
                let trip = (u.goal - u.start).norm();
                assert!(TRIP_PITCHES.contains(&(trip / CITY_PITCH_M)), "{}: trip {trip} m", u.id);
                assert!(net.boundary_distance(&u.goal) >= FROM_WALL_M - 1e-9, "{}: goal by a wall", u.id);
            }
            for (points, spacing) in [
                (valid.uavs.iter().map(|u| u.start).collect::<Vec<_>>(), START_SPACING_M),
                (valid.uavs.iter().map(|u| u.goal).collect(), GOAL_SPACING_M),
            ] {
                // A plain scan: a test of the hash grid must not use it.
                for (a, p) in points.iter().enumerate() {
                    assert!(points[a + 1..].iter().all(|q| (q - p).norm() >= spacing), "too close");
                }
            }
            assert_eq!(s, city_grid(blocks, n, seed).unwrap());
            assert_ne!(s.uavs, city_grid(blocks, n, seed + 1).unwrap().uavs);
        }
    }

    #[test]
    fn a_grid_is_sized_from_the_fleet_and_refuses_a_crowd() {
        assert_eq!(city_blocks(2000), 11);
        assert_eq!(city_blocks(10_000), 25);
        let s = city_scenario(1000, 1).unwrap();
        assert_eq!(s.junctions.as_ref().map(Vec::len), Some(9 * 9));
        let err = city_grid(1, 2000, 1).unwrap_err();
        assert!(matches!(err, CityError::Crowded { blocks: 1, wanted: 2000, .. }), "{err}");
    }
}
