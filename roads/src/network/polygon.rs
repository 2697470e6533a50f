//! Convex polygons, the cells of a road network: a segment's quad in cyclic order (p1, p2, p4, p3)
//! or a junction's polygon of 3 to 8 sides.

use crate::validate::MIN_EDGE_M;
use uav::{Vec2, cross};

/// Smallest |sin| of an interior angle of a strictly convex polygon (as for quads).
const MIN_SIN_ANGLE: f64 = 1.0e-6;
/// Distance (m) below which a point counts as on an edge, and interiors as touching.
pub(crate) const ON_EDGE_M: f64 = 1.0e-9;

/// Why a polygon is not a cell: an edge `k` (from vertex k to k+1) too short, or a vertex `k`
/// where it is not strictly convex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Shape {
    /// Edge k is shorter than [`MIN_EDGE_M`].
    ShortEdge(usize),
    /// Vertex k turns the other way, or not at all.
    NotConvex(usize),
}

/// Checks that `v` (cyclic order, either orientation) is a strictly convex polygon with edges of at
/// least [`MIN_EDGE_M`].
pub(crate) fn check_convex(v: &[Vec2]) -> Result<(), Shape> {
    let n = v.len();
    if let Some(k) = (0..n).find(|&k| (v[(k + 1) % n] - v[k]).norm() < MIN_EDGE_M) {
        return Err(Shape::ShortEdge(k));
    }
    let mut sign = 0.0;
    for k in 0..n {
        let e1 = v[(k + 1) % n] - v[k];
        let e2 = v[(k + 2) % n] - v[(k + 1) % n];
        let s = cross(&e1, &e2) / (e1.norm() * e2.norm());
        if s.abs() <= MIN_SIN_ANGLE || (sign != 0.0 && s.signum() != sign) {
            return Err(Shape::NotConvex((k + 1) % n));
        }
        sign = s.signum();
    }
    // A star polygon turns the same way at every vertex but winds more than once.
    let turning: f64 = (0..n)
        .map(|k| {
            let e1 = v[(k + 1) % n] - v[k];
            let e2 = v[(k + 2) % n] - v[(k + 1) % n];
            cross(&e1, &e2).atan2(e1.dot(&e2))
        })
        .sum();
    if (turning.abs() - std::f64::consts::TAU).abs() > 1e-6 {
        return Err(Shape::NotConvex(0));
    }
    Ok(())
}

/// The bounding box (lower, upper corner) of `v`.
pub(crate) fn bounds(v: &[Vec2]) -> (Vec2, Vec2) {
    let lo = v.iter().fold(Vec2::repeat(f64::INFINITY), |m, p| m.inf(p));
    let hi = v.iter().fold(Vec2::repeat(f64::NEG_INFINITY), |m, p| m.sup(p));
    (lo, hi)
}

/// True when the interiors of the convex polygons `a` and `b` intersect (separating-axis test;
/// polygons that only touch along an edge or at a point are apart).
pub(crate) fn interiors_overlap(a: &[Vec2], b: &[Vec2]) -> bool {
    for poly in [a, b] {
        let n = poly.len();
        for k in 0..n {
            let e = poly[(k + 1) % n] - poly[k];
            let axis = Vec2::new(-e.y, e.x).normalize();
            let (amin, amax) = project(a, &axis);
            let (bmin, bmax) = project(b, &axis);
            if amax <= bmin + ON_EDGE_M || bmax <= amin + ON_EDGE_M {
                return false;
            }
        }
    }
    true
}

fn project(poly: &[Vec2], axis: &Vec2) -> (f64, f64) {
    poly.iter()
        .map(|v| v.dot(axis))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| (lo.min(d), hi.max(d)))
}

/// True when `x` lies on the segment a–b strictly between its ends (farther than [`ON_EDGE_M`]
/// from both, within [`ON_EDGE_M`] of the segment).
pub(crate) fn inside_edge(a: &Vec2, b: &Vec2, x: &Vec2) -> bool {
    let d = b - a;
    let t = (x - a).dot(&d) / d.norm_squared();
    let off = (a + d * t - x).norm();
    let along = t * d.norm();
    off <= ON_EDGE_M && along > ON_EDGE_M && along < d.norm() - ON_EDGE_M
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poly(points: &[[f64; 2]]) -> Vec<Vec2> {
        points.iter().map(|p| Vec2::new(p[0], p[1])).collect()
    }

    #[test]
    fn convex_polygons_pass_and_the_others_are_named() {
        let square = poly(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(check_convex(&square), Ok(()));
        let mut reversed = square.clone();
        reversed.reverse();
        assert_eq!(check_convex(&reversed), Ok(()));
        let dart = poly(&[[0.0, 0.0], [2.0, 0.0], [0.5, 0.5], [0.0, 2.0]]);
        assert!(matches!(check_convex(&dart), Err(Shape::NotConvex(_))));
        let flat = poly(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 1.0]]);
        assert_eq!(check_convex(&flat), Err(Shape::NotConvex(1)));
        let short = poly(&[[0.0, 0.0], [1e-4, 0.0], [1.0, 1.0]]);
        assert_eq!(check_convex(&short), Err(Shape::ShortEdge(0)));
        // A pentagram turns one way at every vertex, twice around.
        let star: Vec<Vec2> = (0..5)
            .map(|k| {
                let a = f64::from(k) * 4.0 * std::f64::consts::PI / 5.0;
                Vec2::new(a.cos(), a.sin())
            })
            .collect();
        assert_eq!(check_convex(&star), Err(Shape::NotConvex(0)));
    }

    #[test]
    fn touching_is_apart_and_crossing_overlaps() {
        let a = poly(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        let beside = poly(&[[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0]]);
        let corner = poly(&[[1.0, 1.0], [2.0, 1.0], [2.0, 2.0]]);
        let across = poly(&[[0.5, 0.5], [1.5, 0.5], [1.5, 1.5], [0.5, 1.5]]);
        assert!(!interiors_overlap(&a, &beside));
        assert!(!interiors_overlap(&a, &corner));
        assert!(interiors_overlap(&a, &across));
        assert!(inside_edge(&Vec2::new(0.0, 0.0), &Vec2::new(2.0, 0.0), &Vec2::new(1.0, 0.0)));
        assert!(!inside_edge(&Vec2::new(0.0, 0.0), &Vec2::new(2.0, 0.0), &Vec2::new(2.0, 0.0)));
        assert!(!inside_edge(&Vec2::new(0.0, 0.0), &Vec2::new(2.0, 0.0), &Vec2::new(1.0, 0.1)));
    }
}
