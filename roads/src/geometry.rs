//! Planar primitives: quadrilateral segments, finite walls, nearest points and intersections.

use uav::{Vec2, cross};

/// One road segment with the paper's vertex labels `p[0..4] = p1, p2, p3, p4`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quad {
    /// Vertices p1, p2, p3, p4.
    pub p: [Vec2; 4],
}

impl Quad {
    /// Vertices in cyclic polygon order (p1, p2, p4, p3).
    pub fn cyclic(&self) -> [Vec2; 4] {
        [self.p[0], self.p[1], self.p[3], self.p[2]]
    }

    /// Orientation σ = sign(cross(p2 − p1, p4 − p2)) of the cyclic order: +1 counter-clockwise.
    pub fn orientation(&self) -> f64 {
        cross(&(self.p[1] - self.p[0]), &(self.p[3] - self.p[1])).signum()
    }

    /// Signed distance from `x` to the nearest edge line, positive inside (docs/safety.md §5,
    /// membership).
    pub fn margin(&self, x: &Vec2) -> f64 {
        let c = self.cyclic();
        let sigma = self.orientation();
        (0..4)
            .map(|k| {
                let (a, b) = (c[k], c[(k + 1) % 4]);
                sigma * cross(&(b - a), &(x - a)) / (b - a).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// True when `x` is inside the quad or within `tol` metres outside it.
    pub fn contains(&self, x: &Vec2, tol: f64) -> bool {
        self.margin(x) >= -tol
    }

    /// Mean of the four vertices (an interior point of a convex quad).
    pub fn centroid(&self) -> Vec2 {
        (self.p[0] + self.p[1] + self.p[2] + self.p[3]) / 4.0
    }

    /// Mid-point of the entry edge p2–p4.
    pub fn entry_mid(&self) -> Vec2 {
        (self.p[1] + self.p[3]) / 2.0
    }

    /// Mid-point of the exit edge p1–p3.
    pub fn exit_mid(&self) -> Vec2 {
        (self.p[0] + self.p[2]) / 2.0
    }
}

/// Which part of the road boundary a wall is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallKind {
    /// Barrier line p2→p1 of its segment (j = 21).
    Side21,
    /// Barrier line p4→p3 of its segment (j = 43).
    Side43,
    /// The closed entry edge p2–p4 of the first segment.
    EntryCap,
    /// The closed exit edge p1–p3 of the last segment.
    ExitCap,
    /// Edge `k` of a network's cell that no other cell shares (`segment` is the cell).
    Edge(usize),
}

/// A finite wall `[a, b]` of the road boundary with its unit normal pointing into the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// Line point `p̃_{i(j)₂}` (p1 for j = 21, p3 for j = 43; an end point for caps).
    pub a: Vec2,
    /// The other end point (p2 for j = 21, p4 for j = 43).
    pub b: Vec2,
    /// Unit normal n̂_in pointing into the segment the wall bounds.
    pub n_in: Vec2,
    /// Index of the segment this wall bounds.
    pub segment: usize,
    /// Which edge of the segment it is.
    pub kind: WallKind,
}

impl Wall {
    /// Builds the wall `[a, b]` of `quad` (segment `segment`), orienting n̂_in towards the quad's centroid.
    pub fn new(a: Vec2, b: Vec2, quad: &Quad, segment: usize, kind: WallKind) -> Self {
        let e = (b - a).normalize();
        let mut n_in = Vec2::new(-e.y, e.x);
        if n_in.dot(&(quad.centroid() - a)) < 0.0 {
            n_in = -n_in;
        }
        Self { a, b, n_in, segment, kind }
    }

    /// Signed distance `s = n̂_inᵀ(x − a)` to the wall's infinite line, positive on the road side.
    #[inline]
    pub fn signed_distance(&self, x: &Vec2) -> f64 {
        self.n_in.dot(&(x - self.a))
    }

    /// Nearest point of the finite wall to `x` and the segment parameter t ∈ [0, 1] (0 at a, 1 at b).
    #[inline]
    pub fn nearest(&self, x: &Vec2) -> (Vec2, f64) {
        nearest_on_segment(&self.a, &self.b, x)
    }
}

/// Nearest point to `x` on the segment `[a, b]`, with its parameter t ∈ [0, 1].
#[inline]
pub fn nearest_on_segment(a: &Vec2, b: &Vec2, x: &Vec2) -> (Vec2, f64) {
    let e = b - a;
    let len2 = e.norm_squared();
    let t = if len2 > 0.0 { ((x - a).dot(&e) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (a + e * t, t)
}

/// True when the closed segments `[p, q]` and `[a, b]` share a point (touching counts).
pub fn segments_intersect(p: &Vec2, q: &Vec2, a: &Vec2, b: &Vec2) -> bool {
    let d1 = cross(&(b - a), &(p - a));
    let d2 = cross(&(b - a), &(q - a));
    let d3 = cross(&(q - p), &(a - p));
    let d4 = cross(&(q - p), &(b - p));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |a: &Vec2, b: &Vec2, x: &Vec2, d: f64| {
        d == 0.0 && x.x >= a.x.min(b.x) && x.x <= a.x.max(b.x) && x.y >= a.y.min(b.y) && x.y <= a.y.max(b.y)
    };
    on(a, b, p, d1) || on(a, b, q, d2) || on(p, q, a, d3) || on(p, q, b, d4)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_square() -> Quad {
        // p1 (1,0), p2 (0,0), p3 (1,1), p4 (0,1): walls y = 0 and y = 1, entry x = 0, exit x = 1.
        Quad { p: [Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)] }
    }

    #[test]
    fn margin_is_signed_distance_to_nearest_edge() {
        let q = unit_square();
        assert!((q.margin(&Vec2::new(0.5, 0.2)) - 0.2).abs() < 1e-12);
        assert!((q.margin(&Vec2::new(0.5, -0.3)) + 0.3).abs() < 1e-12);
        assert!(q.contains(&Vec2::new(1.0, 1.0), 0.0));
        // Mirrored labels (clockwise cyclic order) give the same margins.
        let m = Quad { p: q.p.map(|v| Vec2::new(v.x, -v.y)) };
        assert!((m.margin(&Vec2::new(0.5, -0.2)) - 0.2).abs() < 1e-12);
    }

    #[test]
    fn wall_normal_points_inside() {
        let q = unit_square();
        let w = Wall::new(q.p[0], q.p[1], &q, 0, WallKind::Side21);
        assert!((w.n_in - Vec2::new(0.0, 1.0)).norm() < 1e-12);
        assert!((w.signed_distance(&Vec2::new(0.3, 0.4)) - 0.4).abs() < 1e-12);
        let (c, t) = w.nearest(&Vec2::new(2.0, 0.5));
        assert_eq!((c, t), (Vec2::new(1.0, 0.0), 0.0));
    }

    #[test]
    fn intersections_count_touching() {
        let (a, b) = (Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0));
        assert!(segments_intersect(&Vec2::new(0.5, -1.0), &Vec2::new(0.5, 1.0), &a, &b));
        assert!(segments_intersect(&Vec2::new(1.0, -1.0), &Vec2::new(1.0, 0.0), &a, &b));
        assert!(!segments_intersect(&Vec2::new(1.5, -1.0), &Vec2::new(1.5, 1.0), &a, &b));
        assert!(!segments_intersect(&Vec2::new(0.0, 0.5), &Vec2::new(1.0, 0.5), &a, &b));
    }
}
