//! A validated road: segments, walls (with end caps), centre line, membership and visibility.

use crate::centerline::CenterLine;
use crate::geometry::{Quad, Wall, WallKind, segments_intersect};
use crate::index::{NearWalls, RoadIndex, SEGMENT_NEAR_M};
use crate::lanes::{ClearanceProfile, path_clear, route_walls};
use crate::layout::RoadLayout;
use crate::regions::{Region, RegionOrder, check_regions};
use crate::validate::{RoadError, check_joins, check_overlaps, check_quads};
use uav::Vec2;

/// Tolerance (m) of the point-in-segment test.
pub const CONTAINS_TOL_M: f64 = 1e-9;

/// A road that passed validation, with its derived geometry.
#[derive(Debug, Clone)]
pub struct Road {
    layout: RoadLayout,
    quads: Vec<Quad>,
    walls: Vec<Wall>,
    /// Indices of the two side walls (j = 21, 43) of each segment.
    segment_walls: Vec<[usize; 2]>,
    /// For each segment i, the walls whose infinite lines rule R3 (`halfplanes`) enforces there.
    halfplane_walls: Vec<Vec<usize>>,
    centerline: CenterLine,
    /// Clearance on each side of the centre line (traffic rules).
    profile: ClearanceProfile,
    /// R*-trees over quads and walls for the point queries.
    index: RoadIndex,
    /// The layout's regions in segment order (empty without regions).
    region_order: RegionOrder,
    /// Unique per built road (clones share it): lets users cache what they derive from the road.
    id: u64,
}

/// The id of the next road built.
static NEXT_ROAD_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// A new id for a road or network built now.
pub(crate) fn next_id() -> u64 {
    NEXT_ROAD_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl Road {
    /// Validates `layout` (docs/safety.md §5) and derives walls, end caps and the centre line.
    pub fn new(layout: RoadLayout) -> Result<Self, RoadError> {
        let quads = check_quads(&layout.segments)?;
        check_joins(&quads)?;
        check_overlaps(&quads)?;
        let region_order = check_regions(layout.regions.as_deref(), quads.len())?;
        let mut walls = Vec::with_capacity(2 * quads.len() + 2);
        let mut segment_walls = Vec::with_capacity(quads.len());
        for (i, q) in quads.iter().enumerate() {
            walls.push(Wall::new(q.p[0], q.p[1], q, i, WallKind::Side21));
            walls.push(Wall::new(q.p[2], q.p[3], q, i, WallKind::Side43));
            segment_walls.push([walls.len() - 2, walls.len() - 1]);
        }
        let (first, last) = (&quads[0], &quads[quads.len() - 1]);
        walls.push(Wall::new(first.p[1], first.p[3], first, 0, WallKind::EntryCap));
        walls.push(Wall::new(last.p[0], last.p[2], last, quads.len() - 1, WallKind::ExitCap));
        let halfplane_walls = (0..quads.len()).map(|i| halfplane_set(&quads, &walls, i)).collect();
        let centerline = CenterLine::new(&quads);
        let index = RoadIndex::new(&quads, &walls);
        let profile = ClearanceProfile::new(&centerline, &walls, quads.len());
        let id = next_id();
        Ok(Self {
            layout,
            quads,
            walls,
            segment_walls,
            halfplane_walls,
            centerline,
            profile,
            index,
            region_order,
            id,
        })
    }

    /// A number unique to this road among those built by the process (its clones share it).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The layout this road was built from.
    pub fn layout(&self) -> &RoadLayout {
        &self.layout
    }

    /// The region that holds segment `segment`: None when the layout has no regions or the road no
    /// such segment. A binary search over the regions sorted by first segment, O(log r).
    pub fn region_of(&self, segment: usize) -> Option<&Region> {
        let regions = self.layout.regions.as_deref()?;
        self.region_order.find(regions, segment).map(|k| &regions[k])
    }

    /// The segments.
    pub fn quads(&self) -> &[Quad] {
        &self.quads
    }

    /// Every wall: the side walls of all segments, then the entry and exit caps.
    pub fn walls(&self) -> &[Wall] {
        &self.walls
    }

    /// The two side walls of segment `i` (rule R1, the paper's).
    pub fn segment_walls(&self, i: usize) -> [usize; 2] {
        self.segment_walls[i]
    }

    /// The walls rule R3 (`halfplanes`) enforces, as infinite lines, while a UAV is in segment `i`.
    pub fn halfplane_walls(&self, i: usize) -> &[usize] {
        &self.halfplane_walls[i]
    }

    /// The centre line.
    pub fn centerline(&self) -> &CenterLine {
        &self.centerline
    }

    /// Clearance on each side of the centre line along its arc length.
    pub fn profile(&self) -> &ClearanceProfile {
        &self.profile
    }

    /// True when the straight path from `p` (in segment `seg_p`) to `q` (in `seg_q`) crosses no wall
    /// along the route between them and comes no closer to any than `need`, or than the nearer of its
    /// ends already is (docs/traffic.md). Costs the walls of the segments between, not all.
    pub fn path_clear(&self, p: &Vec2, seg_p: usize, q: &Vec2, seg_q: usize, need: f64) -> bool {
        let (lo, hi) = (seg_p.min(seg_q), seg_p.max(seg_q));
        path_clear(p, q, need, route_walls(&self.walls, self.quads.len(), lo, hi))
    }

    /// True when `x` is inside some segment (or within 1e-9 m of one).
    pub fn contains(&self, x: &Vec2) -> bool {
        if RoadIndex::covers(x) { self.index.contains(&self.quads, x) } else { self.contains_scan(x) }
    }

    /// [`Road::contains`] for a point believed to be in segment `hint`: that segment answers when
    /// it holds `x` (no tree query), else the index. The same answer either way.
    pub fn contains_in(&self, hint: usize, x: &Vec2) -> bool {
        self.quads.get(hint).is_some_and(|q| q.contains(x, CONTAINS_TOL_M)) || self.contains(x)
    }

    /// The segment `x` is in, preferring `previous` while `x` is still inside it (hysteresis); if `x`
    /// is in no segment, the one with the largest (least negative) margin.
    pub fn locate(&self, x: &Vec2, previous: Option<usize>) -> usize {
        if let Some(i) = previous.filter(|&i| i < self.quads.len())
            && self.quads[i].contains(x, CONTAINS_TOL_M)
        {
            return i;
        }
        if RoadIndex::covers(x) { self.index.best_margin(&self.quads, x) } else { self.best_margin_scan(x) }
    }

    /// Distance (m) from `x` to the nearest wall, negative when `x` is outside the road.
    pub fn boundary_distance(&self, x: &Vec2) -> f64 {
        let d = if RoadIndex::covers(x) {
            (self.walls[self.nearest_wall(x)].nearest(x).0 - x).norm()
        } else {
            self.wall_distance_scan(x)
        };
        if self.contains(x) { d } else { -d }
    }

    /// Index of the wall nearest to `x` (the lowest among equally near ones).
    pub fn nearest_wall(&self, x: &Vec2) -> usize {
        if RoadIndex::covers(x) {
            self.index.nearest_wall(&self.walls, x).0
        } else {
            self.nearest_wall_scan(x)
        }
    }

    /// [`Road::contains`] by scanning every quad: the definition the index reproduces, and the
    /// answer for points it does not cover (not finite, or absurdly far).
    pub(crate) fn contains_scan(&self, x: &Vec2) -> bool {
        self.quads.iter().any(|q| q.contains(x, CONTAINS_TOL_M))
    }

    /// The segment with the largest margin at `x` (the first among equals), by scanning.
    pub(crate) fn best_margin_scan(&self, x: &Vec2) -> usize {
        let mut best = (0, f64::NEG_INFINITY);
        for (i, q) in self.quads.iter().enumerate() {
            let m = q.margin(x);
            if m > best.1 {
                best = (i, m);
            }
        }
        best.0
    }

    /// The distance from `x` to the nearest wall, by scanning.
    pub(crate) fn wall_distance_scan(&self, x: &Vec2) -> f64 {
        self.walls.iter().map(|w| (w.nearest(x).0 - x).norm()).fold(f64::INFINITY, f64::min)
    }

    /// [`Road::nearest_wall`] by scanning.
    pub(crate) fn nearest_wall_scan(&self, x: &Vec2) -> usize {
        let mut best = (0, f64::INFINITY);
        for (k, w) in self.walls.iter().enumerate() {
            let d = (w.nearest(x).0 - x).norm_squared();
            if d < best.1 {
                best = (k, d);
            }
        }
        best.0
    }

    /// True when the straight segment from `x` to `y` touches no wall (only the walls whose boxes
    /// touch the segment's are tested).
    pub fn visible(&self, x: &Vec2, y: &Vec2) -> bool {
        if !RoadIndex::covers(x) || !RoadIndex::covers(y) {
            return self.visible_scan(x, y);
        }
        !self.index.walls_across(x, y).any(|k| segments_intersect(x, y, &self.walls[k].a, &self.walls[k].b))
    }

    /// [`Road::visible`] by scanning.
    pub(crate) fn visible_scan(&self, x: &Vec2, y: &Vec2) -> bool {
        !self.walls.iter().any(|w| segments_intersect(x, y, &w.a, &w.b))
    }

    /// Wall indices, ascending, that include every wall within `radius` of `x` (from the index; all
    /// walls when `x` is far out or not finite): the per-UAV loops over nearby walls.
    pub fn walls_near(&self, x: &Vec2, radius: f64) -> NearWalls<'_> {
        self.index.walls_near(self.walls.len(), x, radius)
    }

    /// [`Road::walls_near`] for a point believed to be in segment `hint` (a UAV's tracked
    /// segment): that segment's precomputed list when `x` is in it and `radius` is within the
    /// list's reach, else the tree. The same walls are guaranteed, perhaps with a few more.
    pub fn walls_near_in(&self, hint: usize, x: &Vec2, radius: f64) -> NearWalls<'_> {
        match self.segment_list(hint, x) {
            Some(list) if radius <= SEGMENT_NEAR_M => NearWalls::list(list),
            _ => self.walls_near(x, radius),
        }
    }

    /// [`Road::boundary_distance`] for a point believed to be in segment `hint`: the nearest wall of
    /// that segment's list when `x` is in it and that wall is within the list's reach (no wall off
    /// the list can then be nearer), else the tree. The same value either way.
    pub fn boundary_distance_in(&self, hint: usize, x: &Vec2) -> f64 {
        if let Some(list) = self.segment_list(hint, x) {
            let d2 = list.iter().map(|&k| (self.walls[k as usize].nearest(x).0 - x).norm_squared());
            let d = d2.fold(f64::INFINITY, f64::min).sqrt();
            if d <= SEGMENT_NEAR_M {
                // x is in quad `hint` (within the containment tolerance), so inside the road.
                return d;
            }
        }
        self.boundary_distance(x)
    }

    /// Segment `hint`'s list of nearby walls if `x` is in that segment and the index covers it.
    fn segment_list(&self, hint: usize, x: &Vec2) -> Option<&[u32]> {
        let list = self.index.near.get(hint)?.as_deref()?;
        (RoadIndex::covers(x) && self.quads[hint].contains(x, CONTAINS_TOL_M)).then_some(list)
    }
}

/// Rule R3 for segment i: its own walls and caps, plus every wall of segments i±1 whose inner
/// half-plane contains all four vertices of quad i (the neighbour walls meeting it at a convex corner).
/// Only the walls of segments i−1..=i+1 are looked at, in index order: the side walls of segment s
/// are walls 2s and 2s+1, the entry cap (segment 0) is wall 2n and the exit cap (segment n−1) 2n+1.
fn halfplane_set(quads: &[Quad], walls: &[Wall], i: usize) -> Vec<usize> {
    let n = quads.len();
    let lo = i.saturating_sub(1);
    let hi = (i + 1).min(n - 1);
    let caps = [(lo == 0).then_some(2 * n), (hi == n - 1).then_some(2 * n + 1)];
    (2 * lo..=2 * hi + 1)
        .chain(caps.into_iter().flatten())
        .filter(|&k| halfplane_wall(quads, &walls[k], i))
        .collect()
}

/// Whether rule R3 enforces `w` (a wall of segment i or a neighbour) in segment i.
fn halfplane_wall(quads: &[Quad], w: &Wall, i: usize) -> bool {
    const TOL: f64 = 1e-9;
    w.segment == i || quads[i].p.iter().all(|v| w.signed_distance(v) >= -TOL)
}

/// [`halfplane_set`] by scanning every wall (the definition).
#[cfg(test)]
pub(crate) fn halfplane_set_scan(quads: &[Quad], walls: &[Wall], i: usize) -> Vec<usize> {
    const TOL: f64 = 1e-9;
    let lo = i.saturating_sub(1);
    let hi = (i + 1).min(quads.len() - 1);
    walls
        .iter()
        .enumerate()
        .filter(|(_, w)| {
            w.segment == i
                || ((lo..=hi).contains(&w.segment) && quads[i].p.iter().all(|v| w.signed_distance(v) >= -TOL))
        })
        .map(|(k, _)| k)
        .collect()
}

/// Tracks which segment one UAV is in, with hysteresis (docs/safety.md §5).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SegmentTracker {
    /// The segment at the last update.
    pub current: Option<usize>,
}

impl SegmentTracker {
    /// Updates the membership for position `x` and returns the segment.
    pub fn update(&mut self, road: &Road, x: &Vec2) -> usize {
        let i = road.locate(x, self.current);
        self.current = Some(i);
        i
    }
}
