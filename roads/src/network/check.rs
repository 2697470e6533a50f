//! The rules of a road network, each in O(n log n) for n cells: convex cells, seamless roads,
//! exact shared edges, no edge of three cells, no overlap, connected, passages wide enough. Every
//! error names the field at fault (`roads[2].segments[3]`, `junctions[1].polygon`) and its rule.

use super::polygon::{self, ON_EDGE_M, Shape};
use super::{Cell, CellKind, NetworkLayout, Passage};
use crate::geometry::Quad;
use crate::validate::{MAX_COORDINATE_M, RoadError, RoadRule, check_joins, check_quads};
use rstar::primitives::{GeomWithData, Line, Rectangle};
use rstar::{AABB, RTree};
use std::collections::{HashMap, HashSet};
use uav::Vec2;

/// Most cells a network may have (segments and junctions together).
pub const MAX_CELLS: usize = 20_000;
/// Fewest and most sides of a junction.
pub const JUNCTION_SIDES: std::ops::RangeInclusive<usize> = 3..=8;
/// Largest speed limit a road may state (m/s).
pub const MAX_SPEED_LIMIT: f64 = 100.0;

fn error(field: String, segment: Option<usize>, rule: RoadRule, message: String) -> RoadError {
    RoadError { field, segment, rule, message }
}

/// The field of cell `kind` in the layout.
fn field_of(kind: CellKind) -> String {
    match kind {
        CellKind::Segment { road, segment } => format!("roads[{road}].segments[{segment}]"),
        CellKind::Junction { junction } => format!("junctions[{junction}].polygon"),
    }
}

fn segment_of(kind: CellKind) -> Option<usize> {
    match kind {
        CellKind::Segment { segment, .. } => Some(segment),
        CellKind::Junction { .. } => None,
    }
}

fn check_name(field: String, name: &str, seen: &mut HashSet<String>) -> Result<(), RoadError> {
    let valid = (1..=crate::MAX_REGION_NAME).contains(&name.len())
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if !valid {
        let message = "must be 1 to 64 characters from A-Z, a-z, 0-9, _ and -".to_string();
        return Err(error(field, None, RoadRule::InvalidName, message));
    }
    if !seen.insert(name.to_string()) {
        return Err(error(field, None, RoadRule::DuplicateName, format!("`{name}` is named twice")));
    }
    Ok(())
}

/// The cells of `layout`, each checked alone, and every road's joins.
pub(super) fn cells(layout: &NetworkLayout) -> Result<Vec<Cell>, RoadError> {
    let total = layout.roads.iter().map(|r| r.segments.len()).sum::<usize>() + layout.junctions.len();
    if layout.roads.is_empty() {
        let message = "a network needs at least one road".to_string();
        return Err(error("roads".into(), None, RoadRule::Empty, message));
    }
    if total > MAX_CELLS {
        let message = format!("{total} cells (segments and junctions), at most {MAX_CELLS} are accepted");
        return Err(error("roads".into(), None, RoadRule::TooManySegments, message));
    }
    let (mut names, mut cells) = (HashSet::new(), Vec::with_capacity(total));
    for (k, road) in layout.roads.iter().enumerate() {
        check_name(format!("roads[{k}].name"), &road.name, &mut names)?;
        let prefix = |mut e: RoadError| {
            e.field = format!("roads[{k}].{}", e.field);
            e
        };
        let quads = check_quads(&road.segments).map_err(prefix)?;
        check_joins(&quads).map_err(prefix)?;
        if let Some(limit) =
            road.speed_limit.filter(|v| !(v.is_finite() && *v > 0.0 && *v <= MAX_SPEED_LIMIT))
        {
            let message = format!("must be more than 0 and at most {MAX_SPEED_LIMIT} m/s (got {limit})");
            return Err(error(format!("roads[{k}].speed_limit"), None, RoadRule::SpeedLimit, message));
        }
        let cyclic = quads.iter().map(Quad::cyclic);
        cells.extend(
            cyclic.enumerate().map(|(segment, c)| Cell {
                kind: CellKind::Segment { road: k, segment },
                vertices: c.to_vec(),
            }),
        );
    }
    let mut junction_names = HashSet::new();
    for (j, junction) in layout.junctions.iter().enumerate() {
        check_name(format!("junctions[{j}].name"), &junction.name, &mut junction_names)?;
        let field = format!("junctions[{j}].polygon");
        let sides = junction.polygon.len();
        if !JUNCTION_SIDES.contains(&sides) {
            let message = format!("{sides} vertices: a junction has 3 to 8");
            return Err(error(field, None, RoadRule::JunctionSides, message));
        }
        if let Some((k, v)) =
            junction.polygon.iter().enumerate().find(|(_, v)| !(v[0].is_finite() && v[1].is_finite()))
        {
            let message = format!("vertex {k} = [{}, {}] is not a finite number", v[0], v[1]);
            return Err(error(field, None, RoadRule::NonFinite, message));
        }
        if let Some((k, _)) =
            junction.polygon.iter().enumerate().find(|(_, v)| v[0].abs().max(v[1].abs()) > MAX_COORDINATE_M)
        {
            let message = format!("vertex {k} is farther than {MAX_COORDINATE_M} m from the origin");
            return Err(error(field, None, RoadRule::AbsurdCoordinate, message));
        }
        let vertices: Vec<Vec2> = junction.polygon.iter().map(|v| Vec2::new(v[0], v[1])).collect();
        match polygon::check_convex(&vertices) {
            Ok(()) => {}
            Err(Shape::ShortEdge(k)) => {
                let message = format!("edge {k}–{} is shorter than 1 mm", (k + 1) % sides);
                return Err(error(field, None, RoadRule::DegenerateEdge, message));
            }
            Err(Shape::NotConvex(k)) => {
                let message = format!("the polygon is not strictly convex at vertex {k}");
                return Err(error(field, None, RoadRule::NotConvex, message));
            }
        }
        cells.push(Cell { kind: CellKind::Junction { junction: j }, vertices });
    }
    Ok(cells)
}

/// An edge's ends as exact bit patterns, in a canonical order (-0 is 0).
type EdgeKey = [(u64, u64); 2];

fn key(a: &Vec2, b: &Vec2) -> EdgeKey {
    let bits = |v: &Vec2| ((v.x + 0.0).to_bits(), (v.y + 0.0).to_bits());
    let (a, b) = (bits(a), bits(b));
    if a <= b { [a, b] } else { [b, a] }
}

/// The passable edges of every cell: those another cell shares exactly. Refuses an edge of three
/// cells, and a vertex inside another cell's edge (two cells that meet along part of an edge).
pub(super) fn passages(cells: &[Cell]) -> Result<Vec<Vec<Passage>>, RoadError> {
    let mut by_key: HashMap<EdgeKey, Vec<(usize, usize)>> = HashMap::with_capacity(cells.len() * 4);
    for (c, cell) in cells.iter().enumerate() {
        let n = cell.vertices.len();
        for e in 0..n {
            let sharing = by_key.entry(key(&cell.vertices[e], &cell.vertices[(e + 1) % n])).or_default();
            sharing.push((c, e));
            if let [(first, _), (second, _), (third, _)] = sharing[..] {
                let message = format!(
                    "its edge {e} is also an edge of {} and of {}: an edge joins at most two cells",
                    field_of(cells[first].kind),
                    field_of(cells[second].kind)
                );
                let kind = cells[third].kind;
                return Err(error(field_of(kind), segment_of(kind), RoadRule::SharedByThree, message));
            }
        }
    }
    let mut passages = vec![Vec::new(); cells.len()];
    for sharing in by_key.values() {
        if let [(a, ea), (b, eb)] = sharing[..] {
            passages[a].push(Passage { other: b, edge: ea, other_edge: eb });
            passages[b].push(Passage { other: a, edge: eb, other_edge: ea });
        }
    }
    check_partial_edges(cells)?;
    for list in &mut passages {
        list.sort_by_key(|p| p.edge);
    }
    Ok(passages)
}

type EdgeLine = GeomWithData<Line<[f64; 2]>, (usize, usize)>;

fn check_partial_edges(cells: &[Cell]) -> Result<(), RoadError> {
    let lines: Vec<EdgeLine> = cells
        .iter()
        .enumerate()
        .flat_map(|(c, cell)| {
            let n = cell.vertices.len();
            (0..n).map(move |e| {
                let (a, b) = (cell.vertices[e], cell.vertices[(e + 1) % n]);
                GeomWithData::new(Line::new([a.x, a.y], [b.x, b.y]), (c, e))
            })
        })
        .collect();
    let tree = RTree::bulk_load(lines);
    for (c, cell) in cells.iter().enumerate() {
        for v in &cell.vertices {
            let near = tree.locate_within_distance([v.x, v.y], ON_EDGE_M * ON_EDGE_M);
            for line in near.filter(|l| l.data.0 != c) {
                let (a, b) = (
                    Vec2::new(line.geom().from[0], line.geom().from[1]),
                    Vec2::new(line.geom().to[0], line.geom().to[1]),
                );
                if polygon::inside_edge(&a, &b, v) {
                    let other = cells[line.data.0].kind;
                    let message = format!(
                        "a vertex lies inside edge {} of {}: cells meet along whole edges they share exactly (split that edge there)",
                        line.data.1,
                        field_of(other)
                    );
                    return Err(error(
                        field_of(cell.kind),
                        segment_of(cell.kind),
                        RoadRule::PartialEdge,
                        message,
                    ));
                }
            }
        }
    }
    Ok(())
}

type CellBox = GeomWithData<Rectangle<[f64; 2]>, usize>;

/// Refuses two cells whose interiors overlap (candidates from an R*-tree of their boxes).
pub(super) fn overlaps(cells: &[Cell]) -> Result<(), RoadError> {
    let boxes: Vec<CellBox> = cells
        .iter()
        .enumerate()
        .map(|(c, cell)| {
            let (lo, hi) = polygon::bounds(&cell.vertices);
            GeomWithData::new(Rectangle::from_corners([lo.x, lo.y], [hi.x, hi.y]), c)
        })
        .collect();
    let tree = RTree::bulk_load(boxes);
    for (j, cell) in cells.iter().enumerate() {
        let (lo, hi) = polygon::bounds(&cell.vertices);
        let envelope = AABB::from_corners([lo.x, lo.y], [hi.x, hi.y]);
        let mut candidates: Vec<usize> =
            tree.locate_in_envelope_intersecting(&envelope).map(|b| b.data).filter(|&i| i < j).collect();
        candidates.sort_unstable();
        if let Some(i) =
            candidates.into_iter().find(|&i| polygon::interiors_overlap(&cells[i].vertices, &cell.vertices))
        {
            let message = format!("it overlaps {}", field_of(cells[i].kind));
            return Err(error(field_of(cell.kind), segment_of(cell.kind), RoadRule::Overlap, message));
        }
    }
    Ok(())
}

/// Refuses a network in pieces: every cell must be reachable from the first through passages.
pub(super) fn connected(cells: &[Cell], passages: &[Vec<Passage>]) -> Result<(), RoadError> {
    let mut reached = vec![false; cells.len()];
    let mut stack = vec![0];
    reached[0] = true;
    while let Some(c) = stack.pop() {
        for p in &passages[c] {
            if !reached[p.other] {
                reached[p.other] = true;
                stack.push(p.other);
            }
        }
    }
    match reached.iter().position(|r| !r) {
        None => Ok(()),
        Some(c) => {
            let kind = cells[c].kind;
            let message =
                format!("it cannot be reached from {}: no shared edge leads there", field_of(cells[0].kind));
            Err(error(field_of(kind), segment_of(kind), RoadRule::Disconnected, message))
        }
    }
}

/// Smallest angle (degrees) at which walls may meet inside a network: in a sharper corner the two
/// walls' rows can ask for more than δ together (docs/safety.md §5.1, §8 (a)).
pub const MIN_CORNER_DEG: f64 = 90.0;

/// Refuses a corner of the network where walls meet at less than [`MIN_CORNER_DEG`]: at every vertex
/// that ends a wall, the network's angle is the sum of the angles there of the cells that share it.
pub(super) fn corners(cells: &[Cell], passages: &[Vec<Passage>]) -> Result<(), RoadError> {
    // Per vertex (its exact coordinates): the angle summed so far, the first cell, whether a wall ends there.
    let mut at: HashMap<(u64, u64), (f64, usize, bool)> = HashMap::new();
    for (c, cell) in cells.iter().enumerate() {
        let v = &cell.vertices;
        let n = v.len();
        let open = |e: usize| passages[c].iter().any(|p| p.edge == e);
        for k in 0..n {
            let (a, b) = (v[(k + n - 1) % n] - v[k], v[(k + 1) % n] - v[k]);
            let angle = (a.dot(&b) / (a.norm() * b.norm())).clamp(-1.0, 1.0).acos();
            let wall = !open((k + n - 1) % n) || !open(k);
            let entry = at.entry((v[k].x.to_bits(), v[k].y.to_bits())).or_insert((0.0, c, false));
            entry.0 += angle;
            entry.2 |= wall;
        }
    }
    let sharpest = at
        .iter()
        .filter(|(_, v)| v.2 && v.0.to_degrees() < MIN_CORNER_DEG - 1e-6)
        .min_by(|x, y| x.1.0.total_cmp(&y.1.0).then(x.1.1.cmp(&y.1.1)));
    if let Some((&(x, y), &(angle, c, _))) = sharpest {
        let kind = cells[c].kind;
        let message = format!(
            "walls meet at {:.1}° at [{}, {}]; at least {MIN_CORNER_DEG}°: in a sharper corner a UAV cannot brake for both walls at once",
            angle.to_degrees(),
            f64::from_bits(x),
            f64::from_bits(y)
        );
        return Err(error(field_of(kind), segment_of(kind), RoadRule::SharpCorner, message));
    }
    Ok(())
}

/// Refuses a passage narrower than `min_m`.
pub(super) fn widths(cells: &[Cell], passages: &[Vec<Passage>], min_m: f64) -> Result<(), RoadError> {
    for (c, list) in passages.iter().enumerate() {
        for p in list.iter().filter(|p| p.other > c) {
            let v = &cells[c].vertices;
            let width = (v[(p.edge + 1) % v.len()] - v[p.edge]).norm();
            if width < min_m {
                let kind = cells[c].kind;
                let message = format!(
                    "its edge {} shared with {} is {width:.3} m wide; a UAV needs {min_m:.3} m to cross it",
                    p.edge,
                    field_of(cells[p.other].kind)
                );
                return Err(error(field_of(kind), segment_of(kind), RoadRule::NarrowPassage, message));
            }
        }
    }
    Ok(())
}
