//! Where things are in a network: its walls as [`Wall`]s (the filter's road rows take them), and
//! R*-trees over the walls and the cells' boxes, so that membership, the walls near a point and the
//! distance to the boundary visit the few cells and walls near it.

use super::polygon::bounds;
use super::{Cell, Network};
use crate::geometry::{Wall, WallKind};
use rstar::primitives::{GeomWithData, Line, Rectangle};
use rstar::{AABB, PointDistance, RTree};
use uav::{Vec2, cross};

type WallLine = GeomWithData<Line<[f64; 2]>, usize>;
type CellBox = GeomWithData<Rectangle<[f64; 2]>, usize>;

/// Tolerance (m) of the point-in-cell test, as for a chain's segments.
const CONTAINS_TOL_M: f64 = crate::road::CONTAINS_TOL_M;

/// The spatial side of a [`Network`], built once with it.
#[derive(Debug, Clone)]
pub(super) struct Space {
    /// Every wall, in the order of `Network::walls`.
    pub(super) walls: Vec<Wall>,
    wall_tree: RTree<WallLine>,
    cell_tree: RTree<CellBox>,
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
        let lines: Vec<WallLine> = walls
            .iter()
            .enumerate()
            .map(|(k, w)| GeomWithData::new(Line::new([w.a.x, w.a.y], [w.b.x, w.b.y]), k))
            .collect();
        let boxes = cells.iter().enumerate().map(|(c, cell)| {
            let (lo, hi) = bounds(&cell.vertices);
            let pad = CONTAINS_TOL_M * 2.0;
            GeomWithData::new(Rectangle::from_corners([lo.x - pad, lo.y - pad], [hi.x + pad, hi.y + pad]), c)
        });
        Self { walls, wall_tree: RTree::bulk_load(lines), cell_tree: RTree::bulk_load(boxes.collect()) }
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
        inside.filter(|&c| margin(&self.cells[c].vertices, x) >= -CONTAINS_TOL_M).min()
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
