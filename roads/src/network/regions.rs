//! Regions of a road network: named sets of cells (inclusive segment ranges of named roads and
//! whole junctions) that cover every cell exactly once, the partition `serve --region` flies one
//! part of. Validated in one pass over the cells (names through hash maps) into a per-cell table,
//! so [`Network::region_of`] is O(1).

use super::{Cell, CellKind, Network, NetworkLayout};
use crate::regions::{all, check_name, err, span, span_is};
use crate::validate::{RoadError, RoadRule};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// A region of a network (`{"name": "west", "roads": [{"road": "trunk", "segments": [0, 3]}],
/// "junctions": ["depot"]}`): either list may be left out, not both.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NetworkRegion {
    /// 1 to [`crate::MAX_REGION_NAME`] characters from `A-Z a-z 0-9 _ -`, unique among the regions.
    #[schemars(pattern(crate::schema::region_name_pattern()))]
    #[schemars(description = "unique among the regions; one chunk of a key expression")]
    pub name: String,
    /// Its segments: inclusive ranges of named roads.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub roads: Vec<RoadRange>,
    /// Its junctions, by name.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schemars(inner(pattern(crate::schema::region_name_pattern())))]
    pub junctions: Vec<String>,
}

/// Segments `[first, last]` (both included) of the road named `road`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoadRange {
    /// A road of the network, by name.
    #[schemars(pattern(crate::schema::region_name_pattern()))]
    pub road: String,
    /// `[first, last]`: segment indices of that road, both included.
    #[schemars(inner(range(max = super::MAX_CELLS - 1)))]
    #[schemars(
        description = "[first, last] segment indices of the road, both included (first ≤ last < its number of segments), written as whole numbers"
    )]
    pub segments: [usize; 2],
}

/// No region (a cell of a network without regions).
const NONE: u32 = u32::MAX;

/// The region of each cell of a validated network: `owner[cell]` is the index of its region in the
/// layout's list. Empty when the network has no regions.
#[derive(Debug, Clone, Default)]
pub(crate) struct CellRegions {
    owner: Vec<u32>,
}

impl CellRegions {
    /// The index of the region of `cell`, if any.
    pub(crate) fn of(&self, cell: usize) -> Option<usize> {
        self.owner.get(cell).filter(|&&k| k != NONE).map(|&k| k as usize)
    }
}

/// The cell a region lists, for the messages: `segment 3 of road `trunk`` or `junction `depot``.
fn cell_name(layout: &NetworkLayout, kind: CellKind) -> String {
    match kind {
        CellKind::Segment { road, segment } => {
            format!("segment {segment} of road `{}`", layout.roads[road].name)
        }
        CellKind::Junction { junction } => format!("junction `{}`", layout.junctions[junction].name),
    }
}

/// Checks the regions of `layout` (whose roads and junctions passed their own rules, names
/// unique) and returns each cell's region. Each region in list order: its name (empty, invalid,
/// taken by an earlier region), its road ranges (unknown road, reversed, out of range, a cell
/// already in a region), its junctions (unknown, already in a region), at least one cell; then the
/// first cell in no region. O(cells + listed items).
pub(crate) fn check(layout: &NetworkLayout, cells: &[Cell]) -> Result<CellRegions, RoadError> {
    let Some(regions) = layout.regions.as_deref() else { return Ok(CellRegions::default()) };
    if regions.is_empty() {
        let msg = "`regions` is empty: leave it out, or list regions that cover every cell".to_string();
        return Err(err("regions".into(), None, RoadRule::EmptyRegions, msg));
    }
    let mut first_cell = Vec::with_capacity(layout.roads.len());
    let mut next = 0;
    for road in &layout.roads {
        first_cell.push(next);
        next += road.segments.len();
    }
    let roads: HashMap<&str, usize> =
        layout.roads.iter().enumerate().map(|(i, r)| (r.name.as_str(), i)).collect();
    let junctions: HashMap<&str, usize> =
        layout.junctions.iter().enumerate().map(|(i, j)| (j.name.as_str(), i)).collect();
    let mut names: HashMap<&str, usize> = HashMap::with_capacity(regions.len());
    let kinds: Vec<CellKind> = cells.iter().map(|c| c.kind).collect();
    let mut owner = vec![NONE; kinds.len()];
    for (k, region) in regions.iter().enumerate() {
        check_name(k, &region.name)?;
        if let Some(j) = names.insert(&region.name, k) {
            let msg = format!("the name `{}` is already used by regions[{j}]", region.name);
            return Err(err(format!("regions[{k}].name"), None, RoadRule::DuplicateRegionName, msg));
        }
        // Region indices fit in u32: each region holds a cell of its own, at most MAX_CELLS.
        let mut claim = |cell: usize, field: &dyn Fn() -> String| -> Result<(), RoadError> {
            let held = owner[cell];
            if held != NONE {
                let holder = &regions[held as usize].name;
                let whose = if held as usize == k {
                    "itself".to_string()
                } else {
                    format!("region `{holder}` (regions[{held}])")
                };
                let msg = format!(
                    "region `{}` shares {} with {whose}",
                    region.name,
                    cell_name(layout, kinds[cell])
                );
                return Err(err(field(), segment_of(kinds[cell]), RoadRule::RegionOverlap, msg));
            }
            owner[cell] = k as u32;
            Ok(())
        };
        for (j, range) in region.roads.iter().enumerate() {
            let field = || format!("regions[{k}].roads[{j}]");
            let Some(&r) = roads.get(range.road.as_str()) else {
                let msg = format!("the network has no road `{}`", range.road);
                return Err(err(field(), None, RoadRule::UnknownName, msg));
            };
            let [first, last] = range.segments;
            if first > last {
                let msg = format!("the first segment {first} is after the last segment {last}");
                return Err(err(field(), None, RoadRule::ReversedRegion, msg));
            }
            let n = layout.roads[r].segments.len();
            if last >= n {
                let beyond = span_is(first.max(n), last);
                let msg = format!("{beyond} out of range: road `{}` has {}", range.road, all(n));
                return Err(err(field(), Some(last), RoadRule::RegionOutOfRange, msg));
            }
            for cell in first_cell[r] + first..=first_cell[r] + last {
                claim(cell, &field)?;
            }
        }
        for (j, name) in region.junctions.iter().enumerate() {
            let field = || format!("regions[{k}].junctions[{j}]");
            let Some(&junction) = junctions.get(name.as_str()) else {
                let msg = format!("the network has no junction `{name}`");
                return Err(err(field(), None, RoadRule::UnknownName, msg));
            };
            claim(next + junction, &field)?;
        }
        if region.roads.is_empty() && region.junctions.is_empty() {
            let msg = format!("region `{}` lists no road and no junction", region.name);
            return Err(err(format!("regions[{k}]"), None, RoadRule::EmptyRegion, msg));
        }
    }
    if let Some(cell) = owner.iter().position(|&k| k == NONE) {
        let msg = match kinds[cell] {
            CellKind::Segment { road, segment } => {
                let n = layout.roads[road].segments.len();
                let end = (segment..n).find(|&s| owner[first_cell[road] + s] != NONE).unwrap_or(n);
                let verb = if end - 1 == segment { "is" } else { "are" };
                format!(
                    "{} of road `{}` {verb} in no region",
                    span(segment, end - 1),
                    layout.roads[road].name
                )
            }
            kind => format!("{} is in no region", cell_name(layout, kind)),
        };
        return Err(err("regions".into(), segment_of(kinds[cell]), RoadRule::RegionGap, msg));
    }
    Ok(CellRegions { owner })
}

fn segment_of(kind: CellKind) -> Option<usize> {
    match kind {
        CellKind::Segment { segment, .. } => Some(segment),
        CellKind::Junction { .. } => None,
    }
}

impl Network {
    /// The region of cell `cell` (None when the network has no regions or no such cell); O(1).
    pub fn region_of(&self, cell: usize) -> Option<&NetworkRegion> {
        let k = self.cell_regions.of(cell)?;
        self.layout.regions.as_deref()?.get(k)
    }

    /// The regions a passage joins to region `k` (indices into the layout's list, in its order).
    /// O(cells + passages).
    pub fn region_neighbours(&self, k: usize) -> Vec<usize> {
        let count = self.layout.regions.as_ref().map_or(0, Vec::len);
        let mut next = vec![false; count];
        for (cell, passages) in self.passages.iter().enumerate() {
            if self.cell_regions.of(cell) != Some(k) {
                continue;
            }
            for p in passages {
                if let Some(other) = self.cell_regions.of(p.other).filter(|&o| o != k) {
                    next[other] = true;
                }
            }
        }
        (0..count).filter(|&o| next[o]).collect()
    }

    /// True when cell `cell` is in region `k` or a passage joins it to a cell of region `k`.
    pub fn in_or_next_to_region(&self, cell: usize, k: usize) -> bool {
        self.cell_regions.of(cell) == Some(k)
            || self
                .passages
                .get(cell)
                .is_some_and(|ps| ps.iter().any(|p| self.cell_regions.of(p.other) == Some(k)))
    }
}
