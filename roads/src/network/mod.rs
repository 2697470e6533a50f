//! Road networks: convex cells (the quadrilateral segments of named roads, and junction polygons of
//! 3 to 8 sides) joined along edges they share exactly. An edge shared by two cells is passable;
//! every other edge is a wall. A chain layout (`{"segments": [...]}`) is the network of one road.
//!
//! The layout as users write it is [`NetworkLayout`]; [`Network::new`] validates it (the rules of
//! [`check`]) and derives the cell graph and the walls.

mod check;
pub use check::{JUNCTION_SIDES, MAX_CELLS, MAX_SPEED_LIMIT, MIN_CORNER_DEG};
pub(crate) mod polygon;
mod regions;
mod route;
mod space;
mod way;
mod zones;
pub use regions::{NetworkRegion, RoadRange};
pub use route::{CRUISE_MPS, Route};
pub use space::{CELL_NEAR_M, NetworkWalls};
pub use way::{GateRule, Hold, Way};
pub use zones::{Conflict, ConflictZone, Movement};
#[cfg(test)]
mod regions_tests;
#[cfg(test)]
mod tests;

use crate::layout::RoadLayout;
use crate::validate::RoadError;
use serde::{Deserialize, Serialize};
use uav::Vec2;

/// A road network as users write it: named roads (chains of quads, as a chain layout's segments)
/// and named junctions whose edges the roads' ends (or other junctions) share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NetworkLayout {
    /// The roads. Their count is bounded by the cells' (at most [`MAX_CELLS`] with the junctions),
    /// stated in the description: a list of that many roads as a schema's bound would be the
    /// bound of no body the server reads (4 MiB).
    #[schemars(length(min = 1))]
    #[schemars(
        description = "the network's roads, at least one, names unique. Beyond the schema a network is refused with 422 (`rule` naming the rule, `field` the road, segment or junction) when a cell breaks a road's rule (not_convex, degenerate_edge, seamless_join, folds_back), roads and junctions together have more than 20000 cells (too_many_segments), a name is used twice (duplicate_name), cells overlap (overlap), an edge is shared by three cells (shared_by_three) or only in part (partial_edge), the network is not connected (disconnected), a passage is narrower than a UAV needs with the fleet's parameters (narrow_passage), or two walls meet at less than 90° (sharp_corner)"
    )]
    pub roads: Vec<NetworkRoad>,
    /// The junctions (none: the roads join end to end or side to end).
    #[serde(default)]
    pub junctions: Vec<Junction>,
    /// Its regions (`airroads serve --region`): named sets of cells that cover every cell exactly
    /// once; absent: the network is not divided.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<crate::schema::NetworkRegions>")]
    pub regions: Option<Vec<NetworkRegion>>,
}

/// One road of a network: a chain of quadrilateral segments `[p1, p2, p3, p4]` (p1, p3 of segment
/// i are p2, p4 of segment i + 1; its walls are p2→p1 and p4→p3 unless another cell shares them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NetworkRoad {
    /// Unique among the roads: 1 to 64 characters from `A-Z a-z 0-9 _ -`.
    #[schemars(pattern(crate::schema::region_name_pattern()))]
    pub name: String,
    /// Its segments in order, from its start to its end.
    #[schemars(with = "crate::schema::Segments")]
    pub segments: Vec<[[f64; 2]; 4]>,
    /// Flown from its start to its end only.
    #[serde(default)]
    pub one_way: bool,
    /// Its speed limit (m/s), none by default.
    #[serde(default)]
    #[schemars(with = "Option<crate::schema::SpeedLimit>")]
    pub speed_limit: Option<f64>,
}

/// A junction: a convex polygon of 3 to 8 vertices `[x, y]` in order (either way round).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Junction {
    /// Unique among the junctions: 1 to 64 characters from `A-Z a-z 0-9 _ -`.
    #[schemars(pattern(crate::schema::region_name_pattern()))]
    pub name: String,
    /// Its vertices.
    #[schemars(with = "Vec<crate::schema::Point>", length(min = 3, max = 8))]
    pub polygon: Vec<[f64; 2]>,
}

impl From<&RoadLayout> for NetworkLayout {
    /// The network of a chain layout: one road named `road`, no junction.
    fn from(layout: &RoadLayout) -> Self {
        let road = NetworkRoad {
            name: "road".into(),
            segments: layout.segments.clone(),
            one_way: false,
            speed_limit: None,
        };
        Self { roads: vec![road], junctions: Vec::new(), regions: None }
    }
}

/// What a cell of a network is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CellKind {
    /// Segment `segment` of road `road` (indices into the layout).
    Segment {
        /// The road.
        road: usize,
        /// The segment.
        segment: usize,
    },
    /// Junction `junction` of the layout.
    Junction {
        /// The junction.
        junction: usize,
    },
}

/// One convex cell: its vertices in cyclic order (a segment's p1, p2, p4, p3).
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// What it is.
    pub kind: CellKind,
    /// Its vertices in cyclic order; edge k runs from vertex k to vertex k + 1.
    pub vertices: Vec<Vec2>,
}

/// A passable edge: edge `edge` of cell `cell` is edge `other_edge` of cell `other`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Passage {
    /// The neighbour cell.
    pub other: usize,
    /// The shared edge's index in this cell.
    pub edge: usize,
    /// The shared edge's index in the neighbour.
    pub other_edge: usize,
}

/// A validated road network: its cells, their passages and their walls.
#[derive(Debug, Clone)]
pub struct Network {
    layout: NetworkLayout,
    cells: Vec<Cell>,
    /// Per cell, its passable edges.
    passages: Vec<Vec<Passage>>,
    /// Every wall: (cell, edge).
    walls: Vec<(usize, usize)>,
    /// The walls as segments and the trees over walls and cells.
    space: space::Space,
    /// The passages numbered for the route search.
    passage_index: route::PassageIndex,
    /// Per cell, its speed limit if it is a junction ([`Network::speed_limit`]).
    junction_limits: Vec<Option<f64>>,
    /// Per cell, its region ([`Network::region_of`]).
    cell_regions: regions::CellRegions,
    /// Unique per built network (clones share it), from the same counter as a road's.
    id: u64,
}

impl Network {
    /// Validates `layout`: every rule of `check` (convex cells, seamless roads, exact shared edges,
    /// no overlap, no edge of three cells, connected, no walls meeting at less than
    /// [`MIN_CORNER_DEG`]), and no passage narrower than `min_passage_m` (what a UAV needs to cross
    /// it: 2·D_s + D_c and margins).
    pub fn new(layout: NetworkLayout, min_passage_m: f64) -> Result<Self, RoadError> {
        let cells = check::cells(&layout)?;
        let cell_regions = regions::check(&layout, &cells)?;
        let passages = check::passages(&cells)?;
        check::overlaps(&cells)?;
        check::connected(&cells, &passages)?;
        check::widths(&cells, &passages, min_passage_m)?;
        check::corners(&cells, &passages)?;
        let walls = (0..cells.len())
            .flat_map(|c| {
                let open: Vec<usize> = passages[c].iter().map(|p| p.edge).collect();
                (0..cells[c].vertices.len()).filter(move |e| !open.contains(e)).map(move |e| (c, e))
            })
            .collect::<Vec<_>>();
        let space = space::Space::new(&cells, &walls);
        let passage_index = route::PassageIndex::new(&passages);
        let junction_limits = Self::junction_limits(&layout, &cells, &passages);
        let id = crate::road::next_id();
        Ok(Self { layout, cells, passages, walls, space, passage_index, junction_limits, cell_regions, id })
    }

    /// A number unique to this network among the roads and networks built by the process (its
    /// clones share it): lets users cache what they derive from it.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The layout it was built from.
    pub fn layout(&self) -> &NetworkLayout {
        &self.layout
    }

    /// Its cells: every road's segments in order, road after road, then the junctions.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The passable edges of cell `cell`.
    pub fn passages(&self, cell: usize) -> &[Passage] {
        &self.passages[cell]
    }

    /// Every wall as its two ends, with its cell.
    pub fn walls(&self) -> impl Iterator<Item = (Vec2, Vec2, usize)> + '_ {
        self.walls.iter().map(|&(c, e)| {
            let v = &self.cells[c].vertices;
            (v[e], v[(e + 1) % v.len()], c)
        })
    }
}
