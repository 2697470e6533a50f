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

/// Cosine of the sharpest turn (about 150°) at which [`CenterLine::lane_corner`] still answers: the
/// corner lies lateral/cos(turn/2) from the vertex, which grows without bound towards a U-turn.
pub const MAX_LANE_CORNER_TURN_COS: f64 = 0.87;

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
        self.beside_on(self.piece_at(s), s, lateral)
    }

    /// [`CenterLine::point_beside`] with the piece it lies on, found from piece `hint` (a UAV's
    /// tracked segment: piece i runs through segment i) by [`CenterLine::piece_near`].
    pub fn point_beside_near(&self, s: f64, lateral: f64, hint: usize) -> (Vec2, usize) {
        let k = self.piece_near(s, hint);
        (self.beside_on(k, s, lateral), k)
    }

    /// The point at arc length `s` and lateral offset `lateral` when `k` is `piece_at(s)`: the
    /// same arithmetic as [`CenterLine::point_at`] plus [`CenterLine::normal_at`] times `lateral`.
    fn beside_on(&self, k: usize, s: f64, lateral: f64) -> Vec2 {
        let t = (self.points[k + 1] - self.points[k]).normalize();
        // `point_at` looks the piece up at s clamped to the line: the same piece on it.
        let on_line = (0.0..=self.length()).contains(&s);
        let at = if on_line { k } else { self.piece_at(s.clamp(0.0, self.length())) };
        self.point_on(at, s) + Vec2::new(-t.y, t.x) * lateral
    }

    /// Index of the piece containing arc length `s` (clamped).
    pub fn piece_at(&self, s: f64) -> usize {
        self.arc.partition_point(|&a| a <= s).saturating_sub(1).min(self.points.len().saturating_sub(2))
    }

    /// [`CenterLine::piece_at`], found by walking from piece `hint` (a few steps when `s` lies near
    /// it, as a UAV's candidate targets do its tracked piece) instead of a binary search over the
    /// whole line; the same piece for any hint.
    pub fn piece_near(&self, s: f64, hint: usize) -> usize {
        /// Beyond this many pieces from the hint, the binary search is cheaper.
        const MAX_WALK: usize = 16;
        let last = self.points.len().saturating_sub(2);
        if s.is_nan() {
            return self.piece_at(s);
        }
        let mut k = hint.min(last);
        let mut steps = 0;
        while k > 0 && self.arc[k] > s {
            k -= 1;
            steps += 1;
            if steps > MAX_WALK {
                return self.piece_at(s);
            }
        }
        while k < last && self.arc[k + 1] <= s {
            k += 1;
            steps += 1;
            if steps > MAX_WALK {
                return self.piece_at(s);
            }
        }
        k
    }

    /// The number of vertices whose arc length satisfies `before` (a predicate true on a prefix of
    /// the vertices, such as `a <= s`): `arc().partition_point(before)`, found by walking from vertex
    /// `hint` when the answer is near it (a few steps), else by the binary search.
    pub fn vertices_near(&self, hint: usize, before: impl Fn(f64) -> bool) -> usize {
        /// Beyond this many vertices from the hint, the binary search is cheaper.
        const MAX_WALK: usize = 16;
        let arc = &self.arc;
        let mut i = hint.min(arc.len());
        for _ in 0..MAX_WALK {
            if i > 0 && !before(arc[i - 1]) {
                i -= 1;
            } else if i < arc.len() && before(arc[i]) {
                i += 1;
            } else {
                return i;
            }
        }
        arc.partition_point(|&a| before(a))
    }

    /// [`CenterLine::tangent_at`] with the piece found from piece `hint` ([`CenterLine::piece_near`]).
    pub fn tangent_near(&self, s: f64, hint: usize) -> Vec2 {
        let k = self.piece_near(s, hint);
        (self.points[k + 1] - self.points[k]).normalize()
    }

    /// Where the lines at lateral offset `lateral` beside the two pieces meeting at interior vertex
    /// `k` cross (the corner of a lane through that bend); `None` at the ends and at turns sharper
    /// than [`MAX_LANE_CORNER_TURN_COS`] allows.
    pub fn lane_corner(&self, k: usize, lateral: f64) -> Option<Vec2> {
        let (before, after) = (*self.points.get(k.checked_sub(1)?)?, *self.points.get(k + 1)?);
        let v = self.points[k];
        let left = |t: Vec2| Vec2::new(-t.y, t.x);
        let (n0, n1) = (left((v - before).try_normalize(0.0)?), left((after - v).try_normalize(0.0)?));
        let cos = n0.dot(&n1);
        (cos > -MAX_LANE_CORNER_TURN_COS).then(|| v + (n0 + n1) * (lateral / (1.0 + cos)))
    }

    /// The point at arc length `s` (clamped to the line).
    pub fn point_at(&self, s: f64) -> Vec2 {
        self.point_on(self.piece_at(s.clamp(0.0, self.length())), s)
    }

    /// The point at arc length `s` (clamped to the line) on piece `k`, `piece_at(s)`.
    fn point_on(&self, k: usize, s: f64) -> Vec2 {
        let s = s.clamp(0.0, self.length());
        let (a, b) = (self.points[k], self.points[k + 1]);
        let len = self.arc[k + 1] - self.arc[k];
        if len <= 0.0 { a } else { a + (b - a) * ((s - self.arc[k]) / len) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Road, RoadLayout};

    /// Distance of `x` from the infinite line through `a` and `b`.
    fn line_distance(a: Vec2, b: Vec2, x: Vec2) -> f64 {
        uav::cross(&(b - a).normalize(), &(x - a)).abs()
    }

    proptest::proptest! {
        /// The walk from any hint finds the piece of the binary search, and the point beside the line
        /// found with it is the one `point_beside` gives, at arc lengths on, before and past the line.
        #[test]
        fn the_hinted_piece_and_point_are_the_binary_searchs(
            lengths in proptest::collection::vec(0.5f64..4.0, 1..40),
            turns in proptest::collection::vec(-0.3f64..0.3, 40),
            s_share in -0.2f64..1.2,
            hint in 0usize..50,
            lateral in -1.0f64..1.0,
        ) {
            let (mut points, mut heading, mut at) = (vec![[0.0, 0.0]], 0.0f64, Vec2::zeros());
            for (len, turn) in lengths.iter().zip(&turns) {
                heading += turn;
                at += Vec2::new(heading.cos(), heading.sin()) * *len;
                points.push([at.x, at.y]);
            }
            let widths = vec![1.0; points.len()];
            let road = Road::new(RoadLayout::from_centerline(&points, &widths));
            proptest::prop_assume!(road.is_ok(), "a valid road");
            let road = road.expect("assumed valid");
            let line = road.centerline();
            for s in [s_share * line.length(), line.arc()[hint.min(line.arc().len() - 1)], f64::NAN] {
                proptest::prop_assert_eq!(line.piece_near(s, hint), line.piece_at(s));
                let (p, piece) = line.point_beside_near(s, lateral, hint);
                proptest::prop_assert_eq!(piece, line.piece_at(s));
                let expected = line.point_at(s) + line.normal_at(s) * lateral;
                proptest::prop_assert!(p == expected || (p.x.is_nan() && expected.x.is_nan()), "{p:?} {expected:?}");
                proptest::prop_assert!(line.point_beside(s, lateral) == p || p.x.is_nan());
                let t = line.tangent_near(s, hint);
                proptest::prop_assert!(t == line.tangent_at(s) || t.x.is_nan());
                for before in [|a: f64, s: f64| a <= s, |a: f64, s: f64| a < s] {
                    let expected = line.arc().partition_point(|&a| before(a, s));
                    proptest::prop_assert_eq!(line.vertices_near(hint, |a| before(a, s)), expected);
                }
            }
        }
    }

    #[test]
    fn a_lane_corner_is_as_far_from_both_pieces_as_the_lane() {
        for (turn_deg, lateral) in [(30.0f64, 0.4), (90.0, -0.4), (120.0, 0.3), (-120.0, 0.3), (140.0, -0.25)]
        {
            let t = turn_deg.to_radians();
            let far = Vec2::new(10.0 + 10.0 * t.cos(), 10.0 * t.sin());
            let road =
                Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [10.0, 0.0], [far.x, far.y]], &[3.0; 3]))
                    .unwrap();
            let line = road.centerline();
            let (p, k) = (line.points(), 1);
            let corner = line.lane_corner(k, lateral).expect("an interior vertex");
            for (a, b) in [(p[0], p[1]), (p[1], p[2])] {
                let d = line_distance(a, b, corner);
                assert!((d - lateral.abs()).abs() < 1e-9, "{turn_deg}°: {d} from a piece, lane at {lateral}");
            }
            // On the lane's side of both pieces (left for a positive offset).
            for (a, b) in [(p[0], p[1]), (p[1], p[2])] {
                assert!(uav::cross(&(b - a), &(corner - a)) * lateral > 0.0, "{turn_deg}°: wrong side");
            }
            assert_eq!(line.lane_corner(0, lateral), None);
            assert_eq!(line.lane_corner(p.len() - 1, lateral), None);
        }
    }
}
