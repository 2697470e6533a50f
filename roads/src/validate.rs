//! Validation of road layouts: every rule names the segment and what is wrong.

use crate::geometry::Quad;
use crate::index::{bounds, quad_tree, touching};
use uav::{Vec2, cross};

/// Coordinates beyond this magnitude (m) are rejected as absurd.
pub const MAX_COORDINATE_M: f64 = 1.0e6;
/// Edges shorter than this (m) are degenerate.
pub const MIN_EDGE_M: f64 = 1.0e-3;
/// Largest number of segments accepted in one layout.
pub const MAX_SEGMENTS: usize = 10_000;
/// Smallest |sin| of an interior angle of a strictly convex quad.
const MIN_SIN_ANGLE: f64 = 1.0e-6;

/// The validation rule a layout broke. Its `name()` is stable (used in API error bodies).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoadRule {
    /// The layout has no segment.
    Empty,
    /// More than [`MAX_SEGMENTS`] segments.
    TooManySegments,
    /// A coordinate is NaN or infinite.
    NonFinite,
    /// A coordinate exceeds [`MAX_COORDINATE_M`].
    AbsurdCoordinate,
    /// Two vertices joined by an edge (almost) coincide.
    DegenerateEdge,
    /// The quad (p1, p2, p4, p3) is not strictly convex.
    NotConvex,
    /// `p1(i) ≠ p2(i+1)` or `p3(i) ≠ p4(i+1)`.
    SeamlessJoin,
    /// Segment i+1 lies on the same side of the shared edge as segment i.
    FoldsBack,
    /// Two non-adjacent segments overlap.
    Overlap,
    /// `regions` is present but lists no region.
    EmptyRegions,
    /// A region's name is empty.
    EmptyRegionName,
    /// A region's name is longer than [`crate::MAX_REGION_NAME`] or has a character outside `A-Za-z0-9_-`.
    InvalidRegionName,
    /// Two regions have the same name.
    DuplicateRegionName,
    /// A region's first segment is after its last.
    ReversedRegion,
    /// A region names a segment the road does not have.
    RegionOutOfRange,
    /// A segment is in two regions.
    RegionOverlap,
    /// A segment is in no region.
    RegionGap,
    /// A network's region lists no road and no junction.
    EmptyRegion,
    /// A network's region names a road or junction the network does not have.
    UnknownName,
    /// A network's road or junction name is empty, longer than 64 characters or has a character
    /// outside `A-Za-z0-9_-`.
    InvalidName,
    /// Two roads, or two junctions, of a network have the same name.
    DuplicateName,
    /// A junction has fewer than 3 or more than 8 vertices.
    JunctionSides,
    /// A road's speed limit is not a number above 0 and at most 100 m/s.
    SpeedLimit,
    /// An edge of a network belongs to three cells or more.
    SharedByThree,
    /// A vertex of a cell lies inside an edge of another: cells must meet along whole edges.
    PartialEdge,
    /// A cell of a network cannot be reached from the first through shared edges.
    Disconnected,
    /// A passable edge is narrower than a UAV needs to cross it.
    NarrowPassage,
    /// Walls meet inside the road at less than 90°: a corner too sharp to brake for both at once.
    SharpCorner,
}

impl RoadRule {
    /// Stable snake_case name of the rule.
    pub fn name(&self) -> &'static str {
        match self {
            RoadRule::Empty => "empty",
            RoadRule::TooManySegments => "too_many_segments",
            RoadRule::NonFinite => "non_finite",
            RoadRule::AbsurdCoordinate => "absurd_coordinate",
            RoadRule::DegenerateEdge => "degenerate_edge",
            RoadRule::NotConvex => "not_convex",
            RoadRule::SeamlessJoin => "seamless_join",
            RoadRule::FoldsBack => "folds_back",
            RoadRule::Overlap => "overlap",
            RoadRule::EmptyRegions => "empty_regions",
            RoadRule::EmptyRegionName => "empty_region_name",
            RoadRule::InvalidRegionName => "invalid_region_name",
            RoadRule::DuplicateRegionName => "duplicate_region_name",
            RoadRule::ReversedRegion => "reversed_region",
            RoadRule::RegionOutOfRange => "region_out_of_range",
            RoadRule::RegionOverlap => "region_overlap",
            RoadRule::RegionGap => "region_gap",
            RoadRule::EmptyRegion => "empty_region",
            RoadRule::UnknownName => "unknown_name",
            RoadRule::InvalidName => "invalid_name",
            RoadRule::DuplicateName => "duplicate_name",
            RoadRule::JunctionSides => "junction_sides",
            RoadRule::SpeedLimit => "speed_limit",
            RoadRule::SharedByThree => "shared_by_three",
            RoadRule::PartialEdge => "partial_edge",
            RoadRule::Disconnected => "disconnected",
            RoadRule::NarrowPassage => "narrow_passage",
            RoadRule::SharpCorner => "sharp_corner",
        }
    }
}

/// A layout that breaks a rule: which field and segment (if any), which rule, and a readable explanation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} ({}): {message}", rule.name())]
pub struct RoadError {
    /// JSON path of the offending field: `segments[i]`, `segments`, `regions[i].name`,
    /// `regions[i].segments` or `regions`; on a network also `regions[i].roads[j]`,
    /// `regions[i].junctions[j]` and the roads' and junctions' fields.
    pub field: String,
    /// Index of the offending segment (None for layout-wide rules and for a region's name or range;
    /// the segment in two regions or in none for [`RoadRule::RegionOverlap`], [`RoadRule::RegionGap`],
    /// of its road on a network, None for a junction).
    pub segment: Option<usize>,
    /// The rule that was broken.
    pub rule: RoadRule,
    /// Human-readable detail.
    pub message: String,
}

fn err(segment: Option<usize>, rule: RoadRule, message: String) -> RoadError {
    let field = segment.map_or_else(|| "segments".to_string(), |i| format!("segments[{i}]"));
    RoadError { field, segment, rule, message }
}

/// Converts raw vertex arrays to quads, checking finiteness, magnitude, edges and convexity.
pub(crate) fn check_quads(raw: &[[[f64; 2]; 4]]) -> Result<Vec<Quad>, RoadError> {
    if raw.is_empty() {
        return Err(err(None, RoadRule::Empty, "a road needs at least one segment".into()));
    }
    if raw.len() > MAX_SEGMENTS {
        let msg = format!("{} segments, at most {MAX_SEGMENTS} are accepted", raw.len());
        return Err(err(None, RoadRule::TooManySegments, msg));
    }
    let mut quads = Vec::with_capacity(raw.len());
    for (i, seg) in raw.iter().enumerate() {
        for (k, v) in seg.iter().enumerate() {
            if !v[0].is_finite() || !v[1].is_finite() {
                let msg = format!("p{} = [{}, {}] is not a finite number", k + 1, v[0], v[1]);
                return Err(err(Some(i), RoadRule::NonFinite, msg));
            }
            if v[0].abs() > MAX_COORDINATE_M || v[1].abs() > MAX_COORDINATE_M {
                let msg = format!(
                    "p{} = [{}, {}] is farther than {MAX_COORDINATE_M} m from the origin",
                    k + 1,
                    v[0],
                    v[1]
                );
                return Err(err(Some(i), RoadRule::AbsurdCoordinate, msg));
            }
        }
        let quad = Quad { p: seg.map(|v| Vec2::new(v[0], v[1])) };
        check_convex(i, &quad)?;
        quads.push(quad);
    }
    Ok(quads)
}

/// Labels of the cyclic order (p1, p2, p4, p3), for messages.
const CYCLIC_LABELS: [&str; 4] = ["p1", "p2", "p4", "p3"];

fn check_convex(i: usize, quad: &Quad) -> Result<(), RoadError> {
    let c = quad.cyclic();
    for k in 0..4 {
        let (a, b) = (c[k], c[(k + 1) % 4]);
        if (b - a).norm() < MIN_EDGE_M {
            let msg = format!(
                "edge {}–{} is shorter than {MIN_EDGE_M} m",
                CYCLIC_LABELS[k],
                CYCLIC_LABELS[(k + 1) % 4]
            );
            return Err(err(Some(i), RoadRule::DegenerateEdge, msg));
        }
    }
    let mut sign = 0.0;
    for k in 0..4 {
        let e1 = c[(k + 1) % 4] - c[k];
        let e2 = c[(k + 2) % 4] - c[(k + 1) % 4];
        let s = cross(&e1, &e2) / (e1.norm() * e2.norm());
        let turn_ok = s.abs() > MIN_SIN_ANGLE && (sign == 0.0 || s.signum() == sign);
        if !turn_ok {
            let msg = format!(
                "the quad p1, p2, p4, p3 is not strictly convex at {} (walls p2→p1 and p4→p3 must not cross)",
                CYCLIC_LABELS[(k + 1) % 4]
            );
            return Err(err(Some(i), RoadRule::NotConvex, msg));
        }
        sign = s.signum();
    }
    Ok(())
}

/// Checks the seamless joins and that consecutive segments continue forward.
pub(crate) fn check_joins(quads: &[Quad]) -> Result<(), RoadError> {
    for i in 0..quads.len().saturating_sub(1) {
        let (a, b) = (&quads[i], &quads[i + 1]);
        for (mine, theirs) in [(0usize, 1usize), (2, 3)] {
            let (x, y) = (a.p[mine], b.p[theirs]);
            if x != y {
                let msg = format!(
                    "seamless join broken: p{} of segment {i} is [{}, {}] but p{} of segment {} is [{}, {}]",
                    mine + 1,
                    x.x,
                    x.y,
                    theirs + 1,
                    i + 1,
                    y.x,
                    y.y
                );
                return Err(err(Some(i + 1), RoadRule::SeamlessJoin, msg));
            }
        }
        // The shared edge p1–p3 of segment i: segment i lies on one side, segment i+1 must lie on the other.
        let (e0, e1) = (a.p[0], a.p[2]);
        let side = |x: &Vec2| cross(&(e1 - e0), &(x - e0));
        let mine = side(&a.centroid());
        let theirs = side(&b.centroid());
        if mine.signum() == theirs.signum() {
            let msg =
                format!("segment {} lies on the same side of the shared edge p1–p3 as segment {i}", i + 1);
            return Err(err(Some(i + 1), RoadRule::FoldsBack, msg));
        }
    }
    Ok(())
}

/// Checks that no two non-adjacent segments overlap (separating-axis test; touching is allowed).
/// Reports the lowest j, then the lowest i < j − 1, whose quads overlap; the candidates i come from
/// an R*-tree of the quads' boxes.
pub(crate) fn check_overlaps(quads: &[Quad]) -> Result<(), RoadError> {
    let tree = quad_tree(quads, |_| 0.0);
    for (j, b) in quads.iter().enumerate() {
        let first = touching(&tree, b).filter(|&i| i + 1 < j && overlap(&quads[i], b)).min();
        if let Some(i) = first {
            let msg = format!("segment {j} overlaps segment {i}, which is not adjacent to it");
            return Err(err(Some(j), RoadRule::Overlap, msg));
        }
    }
    Ok(())
}

/// [`check_overlaps`] by testing every pair (the definition).
#[cfg(test)]
pub(crate) fn check_overlaps_pairwise(quads: &[Quad]) -> Result<(), RoadError> {
    for j in 0..quads.len() {
        for i in 0..j.saturating_sub(1) {
            if overlap(&quads[i], &quads[j]) {
                let msg = format!("segment {j} overlaps segment {i}, which is not adjacent to it");
                return Err(err(Some(j), RoadRule::Overlap, msg));
            }
        }
    }
    Ok(())
}

/// True when the bounding boxes of `a` and `b` overlap (touching is apart) and so do the quads.
fn overlap(a: &Quad, b: &Quad) -> bool {
    let ((alo, ahi), (blo, bhi)) = (bounds(a), bounds(b));
    let boxes_apart = ahi.x <= blo.x || bhi.x <= alo.x || ahi.y <= blo.y || bhi.y <= alo.y;
    !boxes_apart && interiors_overlap(a, b)
}

/// Separating-axis test for two convex quads: true when their interiors intersect.
fn interiors_overlap(a: &Quad, b: &Quad) -> bool {
    const TOL: f64 = 1e-9;
    let (ca, cb) = (a.cyclic(), b.cyclic());
    for poly in [&ca, &cb] {
        for k in 0..4 {
            let e = poly[(k + 1) % 4] - poly[k];
            let axis = Vec2::new(-e.y, e.x).normalize();
            let (amin, amax) = project(&ca, &axis);
            let (bmin, bmax) = project(&cb, &axis);
            if amax <= bmin + TOL || bmax <= amin + TOL {
                return false;
            }
        }
    }
    true
}

fn project(poly: &[Vec2; 4], axis: &Vec2) -> (f64, f64) {
    poly.iter()
        .map(|v| v.dot(axis))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| (lo.min(d), hi.max(d)))
}
