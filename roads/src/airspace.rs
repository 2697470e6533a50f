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

    /// The name of the region `x` is in: on a road the region of the segment it is located in (the
    /// nearest outside), on a network the region of its cell (None outside).
    pub fn region_at(&self, x: &Vec2) -> Option<&str> {
        match self {
            Airspace::Road(road) => self.region_of(road.locate(x, None)),
            Airspace::Network(net) => self.region_of(net.locate(x)?),
        }
    }

    /// The name of the region of segment (road) or cell (network) `cell`; None when it is not
    /// divided or has no such cell. O(log r) on a road, O(1) on a network.
    pub fn region_of(&self, cell: usize) -> Option<&str> {
        match self {
            Airspace::Road(road) => road.region_of(cell).map(|r| r.name.as_str()),
            Airspace::Network(net) => net.region_of(cell).map(|r| r.name.as_str()),
        }
    }

    /// Its segments (road) or cells (network).
    pub fn cell_count(&self) -> usize {
        match self {
            Airspace::Road(road) => road.quads().len(),
            Airspace::Network(net) => net.cells().len(),
        }
    }

    /// The names of its regions in the layout's order (none when it is not divided).
    pub fn region_names(&self) -> Vec<&str> {
        match self {
            Airspace::Road(road) => road.layout().regions.iter().flatten().map(|r| r.name.as_str()).collect(),
            Airspace::Network(net) => {
                net.layout().regions.iter().flatten().map(|r| r.name.as_str()).collect()
            }
        }
    }

    /// The regions next to region `name` (None: no such region): on a road those whose segment
    /// range touches its own, by segment order; on a network those a passage joins to one of its
    /// cells, in the layout's order.
    pub fn neighbour_regions(&self, name: &str) -> Option<Vec<&str>> {
        match self {
            Airspace::Road(road) => {
                let regions = road.layout().regions.as_deref()?;
                let own = regions.iter().find(|r| r.name == name)?;
                let mut next: Vec<&Region> = regions
                    .iter()
                    .filter(|r| {
                        r.name != name && (r.last() + 1 == own.first() || own.last() + 1 == r.first())
                    })
                    .collect();
                next.sort_by_key(|r| r.first());
                Some(next.into_iter().map(|r| r.name.as_str()).collect())
            }
            Airspace::Network(net) => {
                let regions = net.layout().regions.as_deref()?;
                let k = regions.iter().position(|r| r.name == name)?;
                Some(net.region_neighbours(k).into_iter().map(|o| regions[o].name.as_str()).collect())
            }
        }
    }

    /// True when segment or cell `cell` lies in region `name` or next to it (a road: the segment
    /// past either end of its range; a network: a cell a passage joins to one of its cells).
    pub fn in_or_next_to_region(&self, cell: usize, name: &str) -> bool {
        match self {
            Airspace::Road(road) => {
                let own = road.layout().regions.iter().flatten().find(|r| r.name == name);
                own.is_some_and(|r| cell + 1 >= r.first() && cell <= r.last() + 1)
            }
            Airspace::Network(net) => {
                let k = net.layout().regions.iter().flatten().position(|r| r.name == name);
                k.is_some_and(|k| net.in_or_next_to_region(cell, k))
            }
        }
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
            Airspace::Road(road) => road.contains_in(hint, x),
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
