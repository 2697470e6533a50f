//! Spatial index of a road, built once in [`crate::Road::new`]: R*-trees over the quads' bounding
//! boxes and over the walls, so that point-in-road, segment location and nearest-wall queries visit
//! the few quads and walls near the point instead of all of them (a road may have 10,000 segments).
//!
//! The index only selects candidates; every answer is still computed by the same expression as the
//! linear scans it replaces ([`Quad::margin`], [`Wall::nearest`]), over a candidate set proven to
//! hold every quad or wall the scan could pick, with rounding slack. The results are therefore
//! identical, ties included (the property tests in `index_tests.rs` check it against the scans).
//!
//! The bounds used:
//! - a point within [`CONTAINS_TOL_M`] outside a convex quad, or more generally whose margin is −t,
//!   lies within t / sin(θ/2) of it, θ the quad's smallest interior angle (the edge lines moved out
//!   by t meet at most that far from the corners); quad boxes are padded accordingly;
//! - conversely a point at distance d > 0 from a quad's box has a margin of at most −d·sin(θ/2);
//! - the box or segment distance rstar reports is a lower bound of the distance to a wall.

use crate::geometry::{Quad, Wall};
use crate::road::CONTAINS_TOL_M;
use rstar::primitives::{GeomWithData, Line, Rectangle};
use rstar::{AABB, RTree};
use uav::Vec2;

type QuadBox = GeomWithData<Rectangle<[f64; 2]>, usize>;
type WallLine = GeomWithData<Line<[f64; 2]>, usize>;

/// Points farther than this from the origin (m) are left to the linear scans: their margins and
/// distances lose all precision or overflow, and the scans define the answer (roads lie within
/// ±[`crate::MAX_COORDINATE_M`]).
const FAR_M: f64 = 1e12;
/// Relative rounding slack (per metre of coordinate magnitude) in the bounds above; generous, it
/// only makes the candidate sets a little larger.
const ROUNDING: f64 = 1e-9;

/// The R*-trees of one road and the constants of its bounds.
#[derive(Debug, Clone)]
pub(crate) struct RoadIndex {
    /// Quad boxes padded by [`pad`] (data: quad index).
    quads: RTree<QuadBox>,
    /// Walls as segments (data: wall index).
    walls: RTree<WallLine>,
    /// Per quad, the walls near it ([`segment_lists`]).
    pub(crate) near: Vec<Option<Box<[u32]>>>,
    /// Half the smallest sin(θ/2) over all quads' interior angles θ.
    sin_half: f64,
    /// Largest coordinate magnitude of the road (m).
    scale: f64,
}

/// Half the smallest sin(θ/2) over the interior angles θ of a convex quad (halved for rounding).
fn sin_half_angle(q: &Quad) -> f64 {
    let c = q.cyclic();
    let s = (0..4)
        .map(|k| {
            let v = c[k];
            let e1 = (c[(k + 3) % 4] - v).normalize();
            let e2 = (c[(k + 1) % 4] - v).normalize();
            (e1 - e2).norm() / 2.0
        })
        .fold(1.0, f64::min);
    // Validation keeps |sin θ| > 1e-6; the floor only guards against NaN.
    (s / 2.0).max(1e-12)
}

fn scale_of(q: &Quad) -> f64 {
    q.p.iter().map(|v| v.x.abs().max(v.y.abs())).fold(0.0, f64::max)
}

/// Padding (m) of a quad's box: every point with a margin ≥ −[`CONTAINS_TOL_M`] is inside it.
fn pad(q: &Quad) -> f64 {
    2.0 * (CONTAINS_TOL_M + ROUNDING * (1.0 + 2.0 * scale_of(q))) / sin_half_angle(q)
}

/// The bounding box (lower, upper corner) of a quad.
pub(crate) fn bounds(q: &Quad) -> (Vec2, Vec2) {
    let lo = q.p.iter().fold(Vec2::repeat(f64::INFINITY), |m, v| m.inf(v));
    let hi = q.p.iter().fold(Vec2::repeat(f64::NEG_INFINITY), |m, v| m.sup(v));
    (lo, hi)
}

/// An R*-tree of `quads`' bounding boxes, each grown by `pad(quad)` (data: quad index).
pub(crate) fn quad_tree(quads: &[Quad], pad: impl Fn(&Quad) -> f64) -> RTree<QuadBox> {
    let boxes = quads
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let (lo, hi) = bounds(q);
            let r = pad(q);
            GeomWithData::new(Rectangle::from_corners([lo.x - r, lo.y - r], [hi.x + r, hi.y + r]), i)
        })
        .collect();
    RTree::bulk_load(boxes)
}

/// Indices of the boxes of `tree` that touch or overlap `quad`'s bounding box.
pub(crate) fn touching(tree: &RTree<QuadBox>, quad: &Quad) -> impl Iterator<Item = usize> {
    let (lo, hi) = bounds(quad);
    tree.locate_in_envelope_intersecting(&AABB::from_corners([lo.x, lo.y], [hi.x, hi.y])).map(|b| b.data)
}

impl RoadIndex {
    /// Indexes a validated road's quads and walls.
    pub(crate) fn new(quads: &[Quad], walls: &[Wall]) -> Self {
        let lines = walls
            .iter()
            .enumerate()
            .map(|(k, w)| GeomWithData::new(Line::new([w.a.x, w.a.y], [w.b.x, w.b.y]), k));
        let walls = RTree::bulk_load(lines.collect());
        Self {
            quads: quad_tree(quads, pad),
            near: segment_lists(quads, &walls),
            walls,
            sin_half: quads.iter().map(sin_half_angle).fold(1.0, f64::min),
            scale: quads.iter().map(scale_of).fold(0.0, f64::max),
        }
    }

    /// True when the index answers for `x` (finite, within [`FAR_M`]); otherwise use the scans.
    pub(crate) fn covers(x: &Vec2) -> bool {
        x.x.abs() <= FAR_M && x.y.abs() <= FAR_M
    }

    /// Rounding slack (m) of distances and margins at `x`.
    fn slack(&self, x: &Vec2) -> f64 {
        ROUNDING * (1.0 + self.scale + x.x.abs().max(x.y.abs()))
    }

    /// True when `x` is in some quad (within [`CONTAINS_TOL_M`]).
    pub(crate) fn contains(&self, quads: &[Quad], x: &Vec2) -> bool {
        self.quads.locate_all_at_point(&[x.x, x.y]).any(|b| quads[b.data].contains(x, CONTAINS_TOL_M))
    }

    /// The quad with the largest margin at `x`, the lowest index among equals.
    pub(crate) fn best_margin(&self, quads: &[Quad], x: &Vec2) -> usize {
        let slack = self.slack(x);
        let mut best: Option<(f64, usize)> = None;
        for (b, d2) in self.quads.nearest_neighbor_iter_with_distance_2(&[x.x, x.y]) {
            // Beyond this box distance every margin is below the best one found.
            if let Some((m, _)) = best
                && d2 > 0.0
                && d2.sqrt() * self.sin_half > slack - m
            {
                break;
            }
            let (i, m) = (b.data, quads[b.data].margin(x));
            if best.is_none_or(|(bm, bi)| m > bm || (m == bm && i < bi)) {
                best = Some((m, i));
            }
        }
        best.map_or(0, |(_, i)| i)
    }

    /// The wall nearest to `x` and its squared distance, the lowest index among equals: rstar's
    /// nearest wall gives an upper bound r of the distance, and every wall rstar puts within r plus
    /// the rounding slack is a candidate.
    pub(crate) fn nearest_wall(&self, walls: &[Wall], x: &Vec2) -> (usize, f64) {
        let here = [x.x, x.y];
        let distance2 = |k: usize| (walls[k].nearest(x).0 - x).norm_squared();
        let Some(first) = self.walls.nearest_neighbor(&here) else {
            return (0, f64::INFINITY);
        };
        let r = distance2(first.data).sqrt() + self.slack(x);
        let mut best = (first.data, distance2(first.data));
        for line in self.walls.locate_within_distance(here, r * r) {
            let (k, d) = (line.data, distance2(line.data));
            if d < best.1 || (d == best.1 && k < best.0) {
                best = (k, d);
            }
        }
        best
    }
}

/// Walls gathered on the stack by [`RoadIndex::walls_near`]; more candidates than this fall back to
/// every wall (only roads of tiny segments around a fast UAV get there).
const NEAR_CAPACITY: usize = 32;

/// Radius (m) of each segment's list of nearby walls: queries from inside a segment within this
/// radius read the list instead of the tree.
pub const SEGMENT_NEAR_M: f64 = 8.0;

/// Segments with more walls than this within [`SEGMENT_NEAR_M`] keep no list (the tree answers).
const SEGMENT_NEAR_CAPACITY: usize = 64;

/// Wall indices in ascending order: a superset of the walls within a distance of a point (from the
/// index or a segment's list), or every wall of the road.
#[derive(Debug, Clone)]
pub struct NearWalls<'a>(Near<'a>);

#[derive(Debug, Clone)]
enum Near<'a> {
    /// Gathered from the tree: ids, count, next position.
    Few([u32; NEAR_CAPACITY], usize, usize),
    /// A segment's list.
    List(std::slice::Iter<'a, u32>),
    /// Every wall.
    All(std::ops::Range<usize>),
}

impl NearWalls<'_> {
    /// Every wall of a road with `count` walls.
    pub(crate) fn all(count: usize) -> Self {
        Self(Near::All(0..count))
    }

    /// The walls of a segment's list.
    pub(crate) fn list(ids: &[u32]) -> NearWalls<'_> {
        NearWalls(Near::List(ids.iter()))
    }
}

impl Iterator for NearWalls<'_> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        match &mut self.0 {
            Near::Few(ids, len, next) => {
                let k = (*next < *len).then(|| ids[*next] as usize);
                *next += 1;
                k
            }
            Near::List(ids) => ids.next().map(|&k| k as usize),
            Near::All(range) => range.next(),
        }
    }
}

/// For each quad, the walls within [`SEGMENT_NEAR_M`] of it (ascending; a superset: those whose
/// boxes touch the quad's box grown by that much), or `None` when there are too many.
pub(crate) fn segment_lists(quads: &[Quad], walls: &RTree<WallLine>) -> Vec<Option<Box<[u32]>>> {
    quads
        .iter()
        .map(|q| {
            let (lo, hi) = bounds(q);
            let r = SEGMENT_NEAR_M + ROUNDING * (1.0 + scale_of(q));
            let grown = AABB::from_corners([lo.x - r, lo.y - r], [hi.x + r, hi.y + r]);
            // Wall indices fit in u32: a road has at most 2 · MAX_SEGMENTS + 2 walls.
            let mut ids: Vec<u32> =
                walls.locate_in_envelope_intersecting(&grown).map(|l| l.data as u32).collect();
            ids.sort_unstable();
            (ids.len() <= SEGMENT_NEAR_CAPACITY).then(|| ids.into_boxed_slice())
        })
        .collect()
}

impl RoadIndex {
    /// The walls within `radius` of `x`, and perhaps a few more (rounding slack), ascending; every
    /// wall when `x` or `radius` is not finite or too many are near.
    pub(crate) fn walls_near(&self, wall_count: usize, x: &Vec2, radius: f64) -> NearWalls<'static> {
        if !Self::covers(x) || !radius.is_finite() || radius > FAR_M {
            return NearWalls::all(wall_count);
        }
        let r = radius.max(0.0) + self.slack(x);
        let (mut ids, mut len) = ([0u32; NEAR_CAPACITY], 0);
        for line in self.walls.locate_within_distance([x.x, x.y], r * r) {
            if len == NEAR_CAPACITY {
                return NearWalls::all(wall_count);
            }
            // Wall indices fit in u32: a road has at most 2 · MAX_SEGMENTS + 2 walls.
            ids[len] = line.data as u32;
            len += 1;
        }
        ids[..len].sort_unstable();
        NearWalls(Near::Few(ids, len, 0))
    }

    /// The walls whose boxes touch the box of the segment from `x` to `y` (grown by the rounding
    /// slack): every wall the segment can cross, in no particular order.
    pub(crate) fn walls_across(&self, x: &Vec2, y: &Vec2) -> impl Iterator<Item = usize> + '_ {
        let slack = self.slack(x).max(self.slack(y));
        let (lo, hi) = (x.inf(y) - Vec2::repeat(slack), x.sup(y) + Vec2::repeat(slack));
        self.walls
            .locate_in_envelope_intersecting(&AABB::from_corners([lo.x, lo.y], [hi.x, hi.y]))
            .map(|l| l.data)
    }
}
