//! Neighbour search: a sweep over UAVs sorted by x, with scratch buffers reused every tick.

use uav::Vec2;

/// Finds all pairs of points closer than a radius; buffers are kept between calls.
#[derive(Debug, Default)]
pub struct NeighbourSearch {
    order: Vec<usize>,
    /// `lists[k]`: indices of the UAVs within the radius of UAV k.
    pub lists: Vec<Vec<usize>>,
}

impl NeighbourSearch {
    /// Recomputes `lists` for `positions` and `radius` (m). Non-finite positions get no neighbours.
    pub fn update(&mut self, positions: &[Vec2], radius: f64) {
        let n = positions.len();
        self.lists.resize_with(n, Vec::new);
        self.lists.iter_mut().for_each(Vec::clear);
        self.order.clear();
        self.order.extend((0..n).filter(|&k| uav::is_finite(&positions[k])));
        self.order.sort_by(|&a, &b| positions[a].x.total_cmp(&positions[b].x));
        let r2 = radius * radius;
        for (i, &k) in self.order.iter().enumerate() {
            for &d in &self.order[i + 1..] {
                if positions[d].x - positions[k].x > radius {
                    break;
                }
                if (positions[d] - positions[k]).norm_squared() <= r2 {
                    self.lists[k].push(d);
                    self.lists[d].push(k);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_finds_exactly_the_pairs_within_the_radius() {
        let pts: Vec<Vec2> =
            (0..60).map(|i| Vec2::new(((i * 37) % 23) as f64 * 0.7, ((i * 11) % 13) as f64 * 0.9)).collect();
        let mut s = NeighbourSearch::default();
        s.update(&pts, 2.0);
        for k in 0..pts.len() {
            let mut brute: Vec<usize> =
                (0..pts.len()).filter(|&d| d != k && (pts[d] - pts[k]).norm() <= 2.0).collect();
            let mut got = s.lists[k].clone();
            brute.sort();
            got.sort();
            assert_eq!(got, brute);
        }
    }
}
