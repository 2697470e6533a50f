//! Where things are in a network: its walls as [`Wall`]s (the filter's road rows take them), and
//! R*-trees over the walls and the cells' boxes, so that membership, the walls near a point and the
//! distance to the boundary visit the few cells and walls near it.

use super::polygon::bounds;
use super::{Cell, Network};
use crate::geometry::{Wall, WallKind};
use rstar::primitives::{GeomWithData, Line, Rectangle};
use rstar::{AABB, Envelope, PointDistance, RTree};
use uav::{Vec2, cross};

type WallLine = GeomWithData<Line<[f64; 2]>, usize>;
type CellBox = GeomWithData<Rectangle<[f64; 2]>, usize>;

/// Tolerance (m) of the point-in-cell test, as for a chain's segments.
const CONTAINS_TOL_M: f64 = crate::road::CONTAINS_TOL_M;

/// Radii (m) of each cell's lists of nearby walls: the walls within such a distance of a point in
/// the cell's box are in that list, so a query from there within that radius reads the shortest list
/// that serves instead of the tree (a filter's activation radius is 2.6 m at rest, 7.6 m at 3.7 m/s,
/// 15 m at 7.3 m/s).
pub const CELL_NEAR_M: [f64; 3] = [4.0, 8.0, 16.0];

/// Lists longer than this are not kept (the tree answers).
const CELL_NEAR_CAPACITY: usize = 256;

/// The spatial side of a [`Network`], built once with it.
#[derive(Debug, Clone)]
pub(super) struct Space {
    /// Every wall, in the order of `Network::walls`.
    pub(super) walls: Vec<Wall>,
    wall_tree: RTree<WallLine>,
    cell_tree: RTree<CellBox>,
    /// Per cell, its box grown by the point-in-cell tolerance (as in `cell_tree`).
    boxes: Vec<AABB<[f64; 2]>>,
    /// Per cell and radius of [`CELL_NEAR_M`], the walls within it of the cell's box, ascending (a
    /// superset: those whose boxes touch the box grown by that much), or None when there are more
    /// than [`CELL_NEAR_CAPACITY`].
    near: Vec<[Option<Box<[u32]>>; 3]>,
}

/// The walls within a distance of a point, ascending: a cell's list filtered by the tree's own
/// distance test, or the tree's answer where no list serves.
#[derive(Debug, Clone)]
pub struct NetworkWalls<'a>(Near<'a>);

#[derive(Debug, Clone)]
enum Near<'a> {
    /// A cell's list, the walls in it and the query (point, squared radius).
    List { ids: std::slice::Iter<'a, u32>, lines: &'a [Wall], x: [f64; 2], r2: f64 },
    /// The tree's answer, sorted.
    Tree(std::vec::IntoIter<usize>),
}

impl Iterator for NetworkWalls<'_> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        match &mut self.0 {
            Near::List { ids, lines, x, r2 } => {
                ids.by_ref().map(|&k| k as usize).find(|&k| wall_line(&lines[k]).distance_2(x) <= *r2)
            }
            Near::Tree(ids) => ids.next(),
        }
    }
}

/// Wall `w` as the tree holds it (the same arithmetic for its distances).
fn wall_line(w: &Wall) -> Line<[f64; 2]> {
    Line::new([w.a.x, w.a.y], [w.b.x, w.b.y])
}

/// The signed distance from `x` to the nearest edge line of the convex cell `v`, positive inside.
pub(super) fn margin(v: &[Vec2], x: &Vec2) -> f64 {
    let n = v.len();
    let sigma = cross(&(v[1] - v[0]), &(v[2] - v[1])).signum();
    (0..n)
        .map(|k| {
            let (a, b) = (v[k], v[(k + 1) % n]);
            sigma * cross(&(b - a), &(x - a)) / (b - a).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// True when `margin(v, x) >= -tol` for a tolerance `tol >= 0` (the same answer), without the
/// square roots for a point inside or on every edge line.
pub(super) fn within(v: &[Vec2], x: &Vec2, tol: f64) -> bool {
    let n = v.len();
    let sigma = cross(&(v[1] - v[0]), &(v[2] - v[1])).signum();
    // Each term of the margin is this cross product over a positive edge length: none negative, so
    // the margin is at least 0 ≥ −tol.
    let inside = (0..n).all(|k| {
        let (a, b) = (v[k], v[(k + 1) % n]);
        sigma * cross(&(b - a), &(x - a)) >= 0.0
    });
    inside || margin(v, x) >= -tol
}

impl Space {
    /// The walls `(cell, edge)` of `cells` and the trees.
    pub(super) fn new(cells: &[Cell], walls: &[(usize, usize)]) -> Self {
        let walls: Vec<Wall> = walls
            .iter()
            .map(|&(c, e)| {
                let v = &cells[c].vertices;
                let (a, b) = (v[e], v[(e + 1) % v.len()]);
                let inside = v.iter().sum::<Vec2>() / v.len() as f64;
                let d = (b - a).normalize();
                let mut n_in = Vec2::new(-d.y, d.x);
                if n_in.dot(&(inside - a)) < 0.0 {
                    n_in = -n_in;
                }
                Wall { a, b, n_in, segment: c, kind: WallKind::Edge(e) }
            })
            .collect();
        let lines: Vec<WallLine> =
            walls.iter().enumerate().map(|(k, w)| GeomWithData::new(wall_line(w), k)).collect();
        let boxes: Vec<AABB<[f64; 2]>> = cells
            .iter()
            .map(|cell| {
                let (lo, hi) = bounds(&cell.vertices);
                let pad = CONTAINS_TOL_M * 2.0;
                AABB::from_corners([lo.x - pad, lo.y - pad], [hi.x + pad, hi.y + pad])
            })
            .collect();
        let wall_tree = RTree::bulk_load(lines);
        let list = |b: &AABB<[f64; 2]>, radius: f64| {
            // Grown a little beyond the radius: a wall that close is in the list whatever the rounding.
            let (lo, hi) = (b.lower(), b.upper());
            let scale = lo.iter().chain(&hi).fold(1.0f64, |m, c| m.max(c.abs()));
            let r = radius + 1e-9 * scale;
            let grown = AABB::from_corners([lo[0] - r, lo[1] - r], [hi[0] + r, hi[1] + r]);
            // Wall indices fit in u32: a network has at most MAX_CELLS cells of at most 8 edges.
            let mut ids: Vec<u32> =
                wall_tree.locate_in_envelope_intersecting(&grown).map(|l| l.data as u32).collect();
            ids.sort_unstable();
            (ids.len() <= CELL_NEAR_CAPACITY).then(|| ids.into_boxed_slice())
        };
        let near = boxes.iter().map(|b| CELL_NEAR_M.map(|radius| list(b, radius))).collect();
        let cell_boxes =
            boxes.iter().enumerate().map(|(c, b)| GeomWithData::new(Rectangle::from_aabb(*b), c));
        Self { walls, wall_tree, cell_tree: RTree::bulk_load(cell_boxes.collect()), boxes, near }
    }

    /// The shortest list of cell `cell` that holds every wall within `radius` of `x` (the radius at
    /// most the last of [`CELL_NEAR_M`], `x` in the cell's box, the list kept), and its radius.
    fn list_at(&self, cell: usize, x: &Vec2, radius: f64) -> Option<(&[u32], f64)> {
        let inside = self.boxes.get(cell).is_some_and(|b| b.contains_point(&[x.x, x.y]));
        let lists = self.near.get(cell).filter(|_| inside)?;
        let tier = CELL_NEAR_M.iter().position(|&r| radius <= r)?;
        Some((lists[tier].as_deref()?, CELL_NEAR_M[tier]))
    }

    /// [`Space::list_at`] for the cell `hint` or, when `x` is not in its box, the cell `x` is in.
    fn list_near(&self, net: &Network, hint: usize, x: &Vec2, radius: f64) -> Option<(&[u32], f64)> {
        self.list_at(hint, x, radius).or_else(|| self.list_at(net.locate(x)?, x, radius))
    }
}

impl Network {
    /// Every wall as the filter's road rows take it: `segment` is its cell, `kind` its edge there.
    pub fn wall_list(&self) -> &[Wall] {
        &self.space.walls
    }

    /// The cell `x` is in (the lowest index when on a shared edge or corner), None outside (and
    /// for a point that is not finite).
    pub fn locate(&self, x: &Vec2) -> Option<usize> {
        if !(x.x.is_finite() && x.y.is_finite()) {
            return None;
        }
        let at = AABB::from_point([x.x, x.y]);
        let inside = self.space.cell_tree.locate_in_envelope_intersecting(&at).map(|b| b.data);
        inside.filter(|&c| within(&self.cells[c].vertices, x, CONTAINS_TOL_M)).min()
    }

    /// The cells whose bounding box comes within `radius` of `x` (none for a point or radius that
    /// is not finite); from the tree, O(log n + found).
    pub fn cells_near(&self, x: &Vec2, radius: f64) -> impl Iterator<Item = usize> + '_ {
        let finite = x.x.is_finite() && x.y.is_finite() && radius.is_finite();
        let near = finite.then(|| self.space.cell_tree.locate_within_distance([x.x, x.y], radius * radius));
        near.into_iter().flatten().map(|b| b.data)
    }

    /// True when `x` is in the network.
    pub fn contains(&self, x: &Vec2) -> bool {
        self.locate(x).is_some()
    }

    /// The walls whose finite segment comes within `radius` of `x`, in index order (none for a
    /// point or radius that is not finite).
    pub fn walls_near(&self, x: &Vec2, radius: f64) -> Vec<usize> {
        if !(x.x.is_finite() && x.y.is_finite() && radius.is_finite()) {
            return Vec::new();
        }
        let near = self.space.wall_tree.locate_within_distance([x.x, x.y], radius * radius);
        let mut list: Vec<usize> = near.map(|w| w.data).collect();
        list.sort_unstable();
        list
    }

    /// [`Network::walls_near`] for a point believed to be in cell `hint` (a UAV's tracked cell, any
    /// number): the same walls in the same order, read from the list of the cell `x` is in (the
    /// hint's when `x` is in its box) instead of the tree, without allocating, for a radius up to
    /// the last of [`CELL_NEAR_M`].
    pub fn walls_near_in(&self, hint: usize, x: &Vec2, radius: f64) -> NetworkWalls<'_> {
        if x.x.is_finite()
            && x.y.is_finite()
            && let Some((ids, _)) = self.space.list_near(self, hint, x, radius)
        {
            let (lines, r2) = (&self.space.walls[..], radius * radius);
            return NetworkWalls(Near::List { ids: ids.iter(), lines, x: [x.x, x.y], r2 });
        }
        NetworkWalls(Near::Tree(self.walls_near(x, radius).into_iter()))
    }

    /// [`Network::contains`] for a point believed to be in cell `hint` (any number): that cell is
    /// asked first.
    pub fn contains_in(&self, hint: usize, x: &Vec2) -> bool {
        let in_hint = self.cells.get(hint).is_some_and(|c| within(&c.vertices, x, CONTAINS_TOL_M));
        in_hint || self.contains(x)
    }

    /// [`Network::boundary_distance`] for a point believed to be in cell `hint` (any number): the
    /// same value, from the shortest list of the cell `x` is in that holds the nearest wall, else
    /// from the tree.
    pub fn boundary_distance_in(&self, hint: usize, x: &Vec2) -> f64 {
        if x.x.is_finite() && x.y.is_finite() {
            let at = [x.x, x.y];
            for radius in CELL_NEAR_M {
                let Some((ids, radius)) = self.space.list_near(self, hint, x, radius) else { break };
                let d2 = ids.iter().map(|&k| wall_line(&self.space.walls[k as usize]).distance_2(&at));
                let d2 = d2.fold(f64::INFINITY, f64::min);
                // Every wall within `radius` of x is in the list: the nearest one is, when that close.
                if d2 <= radius * radius {
                    return d2.sqrt();
                }
            }
        }
        self.boundary_distance(x)
    }

    /// The index of a wall nearest to `x` (0 for a point that is not finite).
    pub fn nearest_wall(&self, x: &Vec2) -> usize {
        let finite = x.x.is_finite() && x.y.is_finite();
        let nearest = finite.then(|| self.space.wall_tree.nearest_neighbor(&[x.x, x.y])).flatten();
        nearest.map_or(0, |w| w.data)
    }

    /// The distance from `x` to the nearest wall (m; NaN for a point that is not finite).
    pub fn boundary_distance(&self, x: &Vec2) -> f64 {
        if !(x.x.is_finite() && x.y.is_finite()) {
            return f64::NAN;
        }
        let nearest = self.space.wall_tree.nearest_neighbor(&[x.x, x.y]);
        nearest.map_or(f64::INFINITY, |w| w.geom().distance_2(&[x.x, x.y]).sqrt())
    }
}
