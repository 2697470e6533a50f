//! Lanes: the road's clearance on each side of its centre line, road coordinates (arc length s and
//! lateral offset ℓ, positive to the left of increasing s) and the clearance test of a straight path
//! against the walls along the route (docs/traffic.md).

use crate::centerline::CenterLine;
use crate::geometry::{Wall, WallKind, nearest_on_segment, segments_intersect};
use uav::Vec2;

/// Spacing (m) of the clearance profile's samples along the centre line.
pub const PROFILE_STEP_M: f64 = 0.25;

/// Clearance from the centre line to the side walls on its right and on its left, sampled every
/// [`PROFILE_STEP_M`] of arc length (right and left of the direction of increasing s).
#[derive(Debug, Clone, PartialEq)]
pub struct ClearanceProfile {
    right: Vec<f64>,
    left: Vec<f64>,
}

impl ClearanceProfile {
    /// Samples the clearance of `line` against the side walls of each piece's segment and its
    /// neighbours (`walls` as the road orders them: side walls 2i and 2i + 1 bound segment i).
    pub(crate) fn new(line: &CenterLine, walls: &[Wall], segments: usize) -> Self {
        let samples = (line.length() / PROFILE_STEP_M).ceil() as usize + 1;
        let (mut right, mut left) = (Vec::with_capacity(samples), Vec::with_capacity(samples));
        for k in 0..samples {
            let s = (k as f64 * PROFILE_STEP_M).min(line.length());
            let (c, piece) = (line.point_at(s), line.piece_at(s));
            let n = line.normal_at(s);
            let (mut r, mut l) = (f64::INFINITY, f64::INFINITY);
            for w in side_walls(walls, piece.saturating_sub(1), (piece + 1).min(segments - 1)) {
                let q = w.nearest(&c).0;
                let d = (q - c).norm();
                if n.dot(&(q - c)) > 0.0 { l = l.min(d) } else { r = r.min(d) }
            }
            right.push(r);
            left.push(l);
        }
        Self { right, left }
    }

    /// (right, left) clearance at arc length `s`: the smaller of the two samples around it.
    pub fn at(&self, s: f64) -> (f64, f64) {
        let last = self.right.len() - 1;
        // A cast truncates, which for s ≥ 0 is the floor (NaN is 0 by `max`): no call to `floor`.
        let k = ((s.max(0.0) / PROFILE_STEP_M) as usize).min(last);
        let j = (k + 1).min(last);
        (self.right[k].min(self.right[j]), self.left[k].min(self.left[j]))
    }

    /// The smallest width (right + left clearance) over the arc-length interval [s0, s1].
    pub fn min_width(&self, s0: f64, s1: f64) -> f64 {
        let (lo, hi) = (s0.min(s1).max(0.0), s0.max(s1).max(0.0));
        let last = self.right.len() - 1;
        let k0 = ((lo / PROFILE_STEP_M) as usize).min(last);
        let k1 = ((hi / PROFILE_STEP_M).ceil() as usize).min(last);
        (k0..=k1).map(|k| self.right[k] + self.left[k]).fold(f64::INFINITY, f64::min)
    }

    /// The width (right + left clearance) of every sample, in order of increasing s.
    pub fn widths(&self) -> impl ExactSizeIterator<Item = f64> + '_ {
        self.right.iter().zip(&self.left).map(|(r, l)| r + l)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.right.len()
    }

    /// True when the profile has no sample (never, for a valid road).
    pub fn is_empty(&self) -> bool {
        self.right.is_empty()
    }
}

/// The side walls of segments `lo..=hi` (walls 2i and 2i + 1 bound segment i).
fn side_walls(walls: &[Wall], lo: usize, hi: usize) -> impl Iterator<Item = &Wall> {
    walls[2 * lo..2 * hi + 2].iter()
}

/// The walls along a route through segments `lo..=hi`: the side walls of segments lo − 1 ..= hi + 1,
/// and the entry and exit caps when the first or last segment is among them.
pub(crate) fn route_walls(
    walls: &[Wall],
    segments: usize,
    lo: usize,
    hi: usize,
) -> impl Iterator<Item = &Wall> {
    let (from, to) = (lo.saturating_sub(1), (hi + 1).min(segments - 1));
    let caps = walls[2 * segments..].iter().filter(move |w| match w.kind {
        WallKind::EntryCap => from == 0,
        WallKind::ExitCap => to == segments - 1,
        _ => false,
    });
    side_walls(walls, from, to).chain(caps)
}

/// Distance between the closed segments [p, q] and [a, b].
pub fn segment_distance(p: &Vec2, q: &Vec2, a: &Vec2, b: &Vec2) -> f64 {
    if segments_intersect(p, q, a, b) {
        return 0.0;
    }
    let to_ab = |x: &Vec2| (nearest_on_segment(a, b, x).0 - x).norm();
    let to_pq = |x: &Vec2| (nearest_on_segment(p, q, x).0 - x).norm();
    to_ab(p).min(to_ab(q)).min(to_pq(a)).min(to_pq(b))
}

/// True when the straight path `p → q` comes no closer to any of `walls` than `need`, or than the
/// nearer of its two ends already is to that wall (a path may run along a wall it starts or ends
/// close to, but never cuts past a vertex, nor crosses a wall).
pub(crate) fn path_clear<'a>(p: &Vec2, q: &Vec2, need: f64, walls: impl Iterator<Item = &'a Wall>) -> bool {
    let (lo, hi) = (p.inf(q), p.sup(q));
    // Both ends on one side of a wall's line, each at least `need` (and a hair) from it: the whole
    // path is, so it is from the wall too (as the test below would find, whose rounding is far
    // below the hair). The usual case for the walls along a route: two dot products. (Not for a
    // NaN `need`, which the test below reads as the ends' distance: `far` is then NaN, and no
    // comparison with it holds.)
    let far = if need.is_nan() { f64::NAN } else { need.max(0.0) + LINE_CULL_M };
    walls.into_iter().all(|w| {
        let (d_p, d_q) = (w.signed_distance(p), w.signed_distance(q));
        if (d_p >= far && d_q >= far) || (d_p <= -far && d_q <= -far) {
            return true;
        }
        // A wall whose bounding box is farther than `need` from the path's cannot be too close.
        let gap = (w.a.inf(&w.b) - hi).sup(&(lo - w.a.sup(&w.b))).sup(&Vec2::zeros());
        if gap.norm_squared() > need * need {
            return true;
        }
        path_keeps_clear_of(p, q, need, w)
    })
}

/// Margin (m) beyond `need` from a wall's line from which [`path_clear`] passes the wall without
/// measuring the path's distance to it.
const LINE_CULL_M: f64 = 1e-6;

/// The test of one wall that [`path_clear`] applies when no cull settles it: the path does not
/// touch the wall and comes no closer to it than `need` or than the nearer of its ends.
fn path_keeps_clear_of(p: &Vec2, q: &Vec2, need: f64, w: &Wall) -> bool {
    let ends = (w.nearest(p).0 - p).norm().min((w.nearest(q).0 - q).norm());
    let along = segment_distance(p, q, &w.a, &w.b);
    along > 0.0 && along >= need.min(ends) - 1e-9
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Quad;
    use crate::{Road, RoadLayout};
    use proptest::prelude::*;

    fn l_bend() -> Road {
        // 2 m wide: east along y = 0 to x = 6, then north to y = 6. The inner vertex is (5, 1).
        Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [6.0, 0.0], [6.0, 6.0]], &[2.0, 2.0, 2.0]))
            .unwrap()
    }

    #[test]
    fn profile_measures_each_side() {
        let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [10.0, 0.0]], &[2.0, 2.0])).unwrap();
        let (r, l) = road.profile().at(5.0);
        assert!((r - 1.0).abs() < 1e-9 && (l - 1.0).abs() < 1e-9, "{r} {l}");
        assert!((road.profile().min_width(0.0, 10.0) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_path_past_the_inner_vertex_needs_clearance() {
        let road = l_bend();
        let (p, around) = (Vec2::new(4.0, 0.6), Vec2::new(6.3, 1.5));
        // Visible (it crosses no wall) but it passes 8 mm from the inner vertex (5, 1).
        assert!(road.visible(&p, &around));
        assert!(road.path_clear(&p, 0, &around, 1, 0.0));
        assert!(!road.path_clear(&p, 0, &around, 1, 0.3));
        // Straight along the wall it already hugs: allowed whatever the clearance asked.
        assert!(road.path_clear(&Vec2::new(1.0, 0.8), 0, &Vec2::new(4.0, 0.8), 0, 0.5));
        // Through a wall: never.
        assert!(!road.path_clear(&p, 0, &Vec2::new(4.0, 3.0), 0, 0.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(5000))]

        /// The culls of `path_clear` change no answer: it agrees with the test of every wall, for
        /// paths and walls anywhere (along, across, touching, degenerate, far off), any clearance.
        #[test]
        fn path_clear_answers_as_the_test_of_every_wall(
            ends in prop::array::uniform4(prop_oneof![4 => -6.0f64..6.0, 1 => Just(0.0), 1 => Just(1.0)]),
            wall in prop::array::uniform4(prop_oneof![4 => -6.0f64..6.0, 1 => Just(0.0), 1 => Just(1.0)]),
            offset in prop_oneof![Just(0.0), -1e4f64..1e4],
            need in prop_oneof![Just(0.0), 0.0f64..3.0, -1.0f64..0.0, Just(f64::NAN)],
        ) {
            let at = |x: f64, y: f64| Vec2::new(x + offset, y - offset);
            let (p, q) = (at(ends[0], ends[1]), at(ends[2], ends[3]));
            let (a, b) = (at(wall[0], wall[1]), at(wall[2], wall[3]));
            let quad = Quad { p: [b, a, b + Vec2::new(1.0, 1.0), a + Vec2::new(1.0, 1.0)] };
            let w = Wall::new(a, b, &quad, 0, WallKind::Side21);
            prop_assume!(w.n_in.iter().all(|x| x.is_finite()));
            prop_assert_eq!(path_clear(&p, &q, need, std::iter::once(&w)), path_keeps_clear_of(&p, &q, need, &w));
        }
    }
}
