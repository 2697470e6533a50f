//! Neighbour search: a uniform grid of square cells as wide as the radius, so every pair closer than
//! the radius lies in the same or in adjacent cells. The UAVs are sorted by cell once per tick and
//! each occupied cell is compared with itself and four of its eight neighbours (the other four
//! compare with it): O(N) distance tests for a fleet of bounded density, wherever the road runs
//! (a sweep along x degenerated on roads running north–south). Buffers are reused every tick.

use uav::Vec2;

/// Cell coordinates are clamped to ±this, so that a neighbour's coordinate never overflows; points
/// beyond it (absurdly far out) share the border cells, which costs time, never a pair.
const MAX_CELL: i64 = (i32::MAX - 2) as i64;

/// Finds all pairs of points closer than a radius; buffers are kept between calls.
#[derive(Debug, Default)]
pub struct NeighbourSearch {
    /// (cell key, UAV index), sorted.
    by_cell: Vec<(u64, u32)>,
    /// `lists[k]`: indices of the UAVs within the radius of UAV k, by x, then index.
    pub lists: Vec<Vec<usize>>,
}

/// The key of cell (x, y): both coordinates offset into u32 and packed, so that sorting by key sorts
/// by x, then y.
fn key(x: i64, y: i64) -> u64 {
    let offset = |c: i64| (c.clamp(-MAX_CELL, MAX_CELL) + i64::from(i32::MAX)) as u64;
    (offset(x) << 32) | offset(y)
}

/// The cell coordinates of key `k` (inverse of [`key`]).
fn coords(k: u64) -> (i64, i64) {
    ((k >> 32) as i64 - i64::from(i32::MAX), (k & 0xffff_ffff) as i64 - i64::from(i32::MAX))
}

impl NeighbourSearch {
    /// Recomputes `lists` for `positions` and `radius` (m). Non-finite positions get no neighbours;
    /// a radius that is not a positive finite number puts every point in one cell.
    pub fn update(&mut self, positions: &[Vec2], radius: f64) {
        let n = positions.len();
        self.lists.resize_with(n, Vec::new);
        self.lists.truncate(n);
        self.lists.iter_mut().for_each(Vec::clear);
        let cell = if radius.is_finite() && radius > 0.0 { radius } else { f64::INFINITY };
        let coordinate = |x: f64| if cell.is_finite() { (x / cell).floor() as i64 } else { 0 };
        self.by_cell.clear();
        self.by_cell.extend(
            (0..n)
                .filter(|&k| uav::is_finite(&positions[k]))
                // Fleets are far below 2³² UAVs (the server admits at most a few hundred thousand).
                .map(|k| (key(coordinate(positions[k].x), coordinate(positions[k].y)), k as u32)),
        );
        self.by_cell.sort_unstable();
        let r2 = radius * radius;
        let within = |a: usize, b: usize| (positions[a] - positions[b]).norm_squared() <= r2;
        let mut start = 0;
        while start < self.by_cell.len() {
            let here = self.by_cell[start].0;
            let end = start + self.by_cell[start..].partition_point(|e| e.0 == here);
            for i in start..end {
                let a = self.by_cell[i].1 as usize;
                for &(_, b) in &self.by_cell[i + 1..end] {
                    if within(a, b as usize) {
                        self.lists[a].push(b as usize);
                        self.lists[b as usize].push(a);
                    }
                }
            }
            let (x, y) = coords(here);
            for (dx, dy) in [(0, 1), (1, -1), (1, 0), (1, 1)] {
                let other = key(x + dx, y + dy);
                if other == here {
                    continue; // clamped at the border: the same cell, already done
                }
                let lo = self.by_cell.partition_point(|e| e.0 < other);
                let hi = lo + self.by_cell[lo..].partition_point(|e| e.0 == other);
                for i in start..end {
                    let a = self.by_cell[i].1 as usize;
                    for &(_, b) in &self.by_cell[lo..hi] {
                        if within(a, b as usize) {
                            self.lists[a].push(b as usize);
                            self.lists[b as usize].push(a);
                        }
                    }
                }
            }
            start = end;
        }
        // Each list in the order of x, then index: independent of the grid, and the order in which
        // the traffic rules and the filter met neighbours when they were measured (a sweep along x),
        // which matters (distance keeping applies neighbour after neighbour).
        let by_x = |a: &usize, b: &usize| positions[*a].x.total_cmp(&positions[*b].x).then(a.cmp(b));
        self.lists.iter_mut().for_each(|l| l.sort_unstable_by(by_x));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(pts: &[Vec2], radius: f64) -> Vec<Vec<usize>> {
        (0..pts.len())
            .map(|k| {
                if !uav::is_finite(&pts[k]) {
                    return Vec::new();
                }
                let mut list: Vec<usize> = (0..pts.len())
                    .filter(|&d| {
                        d != k
                            && uav::is_finite(&pts[d])
                            && (pts[d] - pts[k]).norm_squared() <= radius * radius
                    })
                    .collect();
                list.sort_by(|a, b| pts[*a].x.total_cmp(&pts[*b].x).then(a.cmp(b)));
                list
            })
            .collect()
    }

    #[test]
    fn grid_finds_exactly_the_pairs_within_the_radius() {
        let pts: Vec<Vec2> =
            (0..60).map(|i| Vec2::new(((i * 37) % 23) as f64 * 0.7, ((i * 11) % 13) as f64 * 0.9)).collect();
        let mut s = NeighbourSearch::default();
        s.update(&pts, 2.0);
        assert_eq!(s.lists, brute(&pts, 2.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// The grid's lists equal the all-pairs search: clusters, points on cell borders (multiples of
        /// the radius), negative and far-out coordinates, non-finite points, repeated points.
        #[test]
        fn grid_equals_all_pairs(
            raw in proptest::collection::vec((0u8..8, -50i32..50, -50i32..50, 0.0f64..1.0), 0..120),
            radius in prop_oneof![Just(1.0), 0.05f64..5.0],
        ) {
            let pts: Vec<Vec2> = raw
                .iter()
                .map(|&(kind, i, j, f)| match kind {
                    0 => Vec2::new(i as f64 * radius, j as f64 * radius),
                    1 => Vec2::new(f64::NAN, j as f64),
                    2 => Vec2::new(i as f64 * 1e12, j as f64 * 1e12),
                    3 => Vec2::new(1.0, 1.0),
                    _ => Vec2::new(i as f64 * 0.1 + f, j as f64 * 0.1 - f),
                })
                .collect();
            let mut s = NeighbourSearch::default();
            s.update(&pts, radius);
            prop_assert_eq!(&s.lists, &brute(&pts, radius));
            // Reused buffers: a second, smaller update gives the same as a fresh search.
            let fewer = &pts[..pts.len() / 2];
            s.update(fewer, radius);
            prop_assert_eq!(&s.lists, &brute(fewer, radius));
        }
    }

    #[test]
    fn an_infinite_radius_makes_everyone_a_neighbour() {
        let pts = [Vec2::new(0.0, 0.0), Vec2::new(1e9, -1e9), Vec2::new(f64::NAN, 0.0)];
        let mut s = NeighbourSearch::default();
        s.update(&pts, f64::INFINITY);
        assert_eq!(s.lists, vec![vec![1], vec![0], vec![]]);
    }
}
