//! What a fleet flies in: one road (a chain of segments, with its lanes, traffic rules and regions)
//! or a road network (cells, junctions and routes, [`crate::network`]).

use crate::boundary::Boundary;
use crate::geometry::Wall;
use crate::network::Network;
use crate::regions::Region;
use crate::road::Road;
use uav::Vec2;

/// One road or a network.
#[derive(Debug, Clone)]
pub enum Airspace {
    /// A chain of segments (`{"segments": [...]}`).
    Road(Road),
    /// A network of roads and junctions (`{"roads": [...], "junctions": [...]}`).
    Network(Network),
}

impl From<Road> for Airspace {
    fn from(road: Road) -> Self {
        Airspace::Road(road)
    }
}

impl From<Network> for Airspace {
    fn from(net: Network) -> Self {
        Airspace::Network(net)
    }
}

impl Airspace {
    /// The road, when it is one.
    pub fn road(&self) -> Option<&Road> {
        match self {
            Airspace::Road(road) => Some(road),
            Airspace::Network(_) => None,
        }
    }

    /// The network, when it is one.
    pub fn network(&self) -> Option<&Network> {
        match self {
            Airspace::Road(_) => None,
            Airspace::Network(net) => Some(net),
        }
    }

    /// True when `x` is inside.
    pub fn contains(&self, x: &Vec2) -> bool {
        match self {
            Airspace::Road(road) => road.contains(x),
            Airspace::Network(net) => net.contains(x),
        }
    }

    /// The signed distance (m) from `x` to the nearest wall: positive inside, negative outside.
    pub fn boundary_distance(&self, x: &Vec2) -> f64 {
        match self {
            Airspace::Road(road) => road.boundary_distance(x),
            Airspace::Network(net) => net.signed_distance_in(0, x),
        }
    }

    /// The region `x` is in (a network has none yet).
    pub fn region_at(&self, x: &Vec2) -> Option<&Region> {
        self.road().and_then(|road| road.region_of(road.locate(x, None)))
    }

    /// The segment (of a road) or cell (of a network) `x` is in, `previous` preferred on a road; on
    /// a network, 0 outside.
    pub fn locate(&self, x: &Vec2, previous: Option<usize>) -> usize {
        match self {
            Airspace::Road(road) => road.locate(x, previous),
            Airspace::Network(net) => net.locate(x).unwrap_or(0),
        }
    }
}

impl Boundary for Airspace {
    fn wall_list(&self) -> &[Wall] {
        match self {
            Airspace::Road(road) => road.walls(),
            Airspace::Network(net) => net.wall_list(),
        }
    }

    fn inside(&self, x: &Vec2) -> bool {
        self.contains(x)
    }

    fn inside_in(&self, hint: usize, x: &Vec2) -> bool {
        match self {
            Airspace::Road(road) => road.contains(x),
            Airspace::Network(net) => net.contains_in(hint, x),
        }
    }

    fn nearest_wall_to(&self, x: &Vec2) -> usize {
        match self {
            Airspace::Road(road) => road.nearest_wall(x),
            Airspace::Network(net) => net.nearest_wall(x),
        }
    }

    fn walls_within(&self, hint: usize, x: &Vec2, radius: f64) -> impl Iterator<Item = usize> + '_ {
        match self {
            Airspace::Road(road) => Near::Road(road.walls_near_in(hint, x, radius)),
            Airspace::Network(net) => Near::Network(net.walls_near_in(hint, x, radius)),
        }
    }

    fn signed_distance_in(&self, hint: usize, x: &Vec2) -> f64 {
        match self {
            Airspace::Road(road) => road.boundary_distance_in(hint, x),
            Airspace::Network(net) => net.signed_distance_in(hint, x),
        }
    }
}

/// The walls near a point of a road or of a network.
enum Near<R, N> {
    Road(R),
    Network(N),
}

impl<R: Iterator<Item = usize>, N: Iterator<Item = usize>> Iterator for Near<R, N> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        match self {
            Near::Road(walls) => walls.next(),
            Near::Network(walls) => walls.next(),
        }
    }
}
