//! The centre line: the polyline through the mid-points of the passable edges, with arc length.

use crate::geometry::{Quad, nearest_on_segment};
use uav::Vec2;

/// Centre line of a road: point k is the mid-point of segment k's entry edge (k < M) or of the last
/// exit edge (k = M); piece i (points i → i+1) runs through segment i.
#[derive(Debug, Clone, PartialEq)]
pub struct CenterLine {
    points: Vec<Vec2>,
    /// Arc length (m) at each point; `arc[0] = 0`.
    arc: Vec<f64>,
    /// Sine of the turn at each point towards increasing s (positive: left; 0 at both ends).
    turns: Vec<f64>,
}

impl CenterLine {
    /// Builds the centre line of a chain of segments.
    pub fn new(quads: &[Quad]) -> Self {
        let mut points = Vec::with_capacity(quads.len() + 1);
        if let Some(first) = quads.first() {
            points.push(first.entry_mid());
        }
        points.extend(quads.iter().map(Quad::exit_mid));
        let mut arc = Vec::with_capacity(points.len());
        let mut s = 0.0;
        for (k, p) in points.iter().enumerate() {
            if k > 0 {
                s += (p - points[k - 1]).norm();
            }
            arc.push(s);
        }
        let turns = (0..points.len())
            .map(|k| match (k.checked_sub(1).map(|j| points[j]), points.get(k + 1)) {
                (Some(before), Some(after)) => {
                    let v = points[k];
                    uav::cross(&(v - before).normalize(), &(after - v).normalize())
                }
                _ => 0.0,
            })
            .collect();
        Self { points, arc, turns }
    }

    /// Sine of the turn at each vertex towards increasing s (positive: a left bend; 0 at both ends).
    pub fn turns(&self) -> &[f64] {
        &self.turns
    }

    /// The polyline's vertices.
    pub fn points(&self) -> &[Vec2] {
        &self.points
    }

    /// Arc length at each vertex.
    pub fn arc(&self) -> &[f64] {
        &self.arc
    }

    /// Total length (m).
    pub fn length(&self) -> f64 {
        self.arc.last().copied().unwrap_or(0.0)
    }

    /// Arc length of the point of piece `segment` nearest to `x`.
    pub fn project_on_piece(&self, segment: usize, x: &Vec2) -> f64 {
        let (a, b) = (self.points[segment], self.points[segment + 1]);
        let (_, t) = nearest_on_segment(&a, &b, x);
        self.arc[segment] + t * (self.arc[segment + 1] - self.arc[segment])
    }

    /// Unit tangent (direction of increasing arc length) at arc length `s`.
    pub fn tangent_at(&self, s: f64) -> Vec2 {
        let k = self.piece_at(s);
        (self.points[k + 1] - self.points[k]).normalize()
    }

    /// Unit normal to the left of the direction of increasing arc length at `s`.
    pub fn normal_at(&self, s: f64) -> Vec2 {
        let t = self.tangent_at(s);
        Vec2::new(-t.y, t.x)
    }

    /// Lateral offset ℓ of `x` from piece `segment` (positive to the left of increasing s).
    pub fn lateral(&self, segment: usize, x: &Vec2) -> f64 {
        let (a, b) = (self.points[segment], self.points[segment + 1]);
        let t = (b - a).normalize();
        Vec2::new(-t.y, t.x).dot(&(x - a))
    }

    /// The point at arc length `s` and lateral offset `lateral` (road coordinates to the plane).
    pub fn point_beside(&self, s: f64, lateral: f64) -> Vec2 {
        self.point_at(s) + self.normal_at(s) * lateral
    }

    /// Index of the piece containing arc length `s` (clamped).
    pub fn piece_at(&self, s: f64) -> usize {
        self.arc.partition_point(|&a| a <= s).saturating_sub(1).min(self.points.len().saturating_sub(2))
    }

    /// The point at arc length `s` (clamped to the line).
    pub fn point_at(&self, s: f64) -> Vec2 {
        let s = s.clamp(0.0, self.length());
        let k = self.piece_at(s);
        let (a, b) = (self.points[k], self.points[k + 1]);
        let len = self.arc[k + 1] - self.arc[k];
        if len <= 0.0 { a } else { a + (b - a) * ((s - self.arc[k]) / len) }
    }
}
