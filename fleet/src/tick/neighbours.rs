//! Neighbour search on a uniform grid of rows: the plane is cut into horizontal bands as tall as
//! the radius, every UAV is sorted by (band, x, index), and each UAV looks at its own band and the
//! two beside it within x ± radius, found with pointers that only move forward along each band. Every
//! pair closer than the radius is in such a window (its y differs by less than one band; the window
//! is widened by a few ulps, and reaches the next band but one where rounding in y / r puts a pair
//! exactly r apart two bands apart, so that the exact distance test alone decides), the work is
//! O(N log N) for the sort plus O(N + candidates) at bounded density, whichever way the road runs (a
//! sweep along x alone degenerated on roads running north–south), and each UAV's list comes out
//! ordered by x, then index (the hits of its windows, each in that order, put together). Each
//! sort starts from the last one's order: UAVs move little in a tick, and an insertion sort finishes
//! it in about one pass. The lists share one buffer ([`Ragged`]) reused every tick. Large fleets
//! search the two halves of the sorted UAVs at once (and sort on both cores when the order is new).
//!
//! Foreign UAVs (flown by another region, [`crate::ForeignUav`]) go into the same sort: points from
//! index `own` on get no list of their own, and each own UAV's foreign neighbours come out in a
//! second list ([`NeighbourSearch::foreign`], indices counted from `own`), so the search stays
//! bounded by the same windows whatever their number.

use crate::ragged::Ragged;
use rayon::prelude::*;
use uav::Vec2;

/// Band numbers are clamped to ±this, so that a neighbour band's number never overflows; points
/// beyond it (absurdly far out) share the border bands, which costs time, never a pair.
const MAX_BAND: i64 = 1 << 52;

/// Finds all pairs of points closer than a radius; buffers are kept between calls.
#[derive(Debug, Default)]
pub struct NeighbourSearch {
    /// (band, x, UAV index) of every finite point, sorted.
    by_band: Vec<(i64, f64, u32)>,
    /// How many points (finite or not) `by_band` was sorted for.
    sorted_for: usize,
    /// `lists[k]`: indices of the UAVs within the radius of UAV k, by x, then index.
    pub lists: Ragged<usize>,
    /// `foreign[k]`: indices (from 0, i.e. point `own + f` is `f`) of the foreign points within the
    /// radius of UAV k, by x, then index.
    pub foreign: Ragged<usize>,
    /// The lists found by each half of the sorted UAVs (searched on both cores for large fleets).
    halves: [Found; 2],
}

/// The lists one run of bands gives, end to end, before they go into the [`Ragged`]s.
#[derive(Debug, Default)]
struct Found {
    /// Own neighbours of every UAV searched, one list after the other.
    own: Vec<usize>,
    /// Foreign neighbours likewise.
    foreign: Vec<usize>,
    /// Per UAV searched: its index and the ends of its two lists in `own` and `foreign`.
    ends: Vec<(usize, usize, usize)>,
    /// One UAV's neighbours as found, with their x (reused from UAV to UAV).
    hits: Vec<(f64, u32)>,
}

/// Most moves an entry may take on average in the insertion sort of a nearly sorted order before
/// the sort gives up (to a quicksort): a tick's order is some 1 % off the last one's.
const SHIFTS_PER_ENTRY: usize = 8;

/// Sorts `entries` by [`order`] with an insertion sort, unless that takes more than `budget`
/// moves: then returns false, with `entries` a permutation of what they were.
fn insertion_sort_within(entries: &mut [(i64, f64, u32)], mut budget: usize) -> bool {
    for i in 1..entries.len() {
        let mut j = i;
        while j > 0 && order(&entries[j - 1], &entries[j]) == std::cmp::Ordering::Greater {
            if budget == 0 {
                return false;
            }
            budget -= 1;
            entries.swap(j - 1, j);
            j -= 1;
        }
    }
    true
}

/// The order of the sorted entries: band, then x, then index.
fn order(a: &(i64, f64, u32), b: &(i64, f64, u32)) -> std::cmp::Ordering {
    a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2))
}

impl NeighbourSearch {
    /// Recomputes `lists` for `positions` and `radius` (m), none of them foreign (the tests' form of
    /// [`NeighbourSearch::update_with_foreign`]).
    #[cfg(test)]
    pub fn update(&mut self, positions: &[Vec2], radius: f64) {
        self.update_with_foreign(positions, positions.len(), radius);
    }

    /// Recomputes `lists` for `positions` and `radius` (m), where `positions[own..]` are foreign
    /// points: they get no list, and appear in the own UAVs' [`NeighbourSearch::foreign`] lists
    /// instead. Non-finite positions get no neighbours; a radius that is not a positive finite number
    /// puts every point in one band. Large fleets are sorted and searched on all cores (two halves
    /// of the sorted points), with the same lists as one thread.
    pub fn update_with_foreign(&mut self, positions: &[Vec2], own: usize, radius: f64) {
        let n = positions.len();
        let own = own.min(n);
        let finite_radius = radius.is_finite() && radius > 0.0;
        let band =
            |y: f64| if finite_radius { ((y / radius).floor() as i64).clamp(-MAX_BAND, MAX_BAND) } else { 0 };
        // The last call's order, when it holds the same points (the finite ones of as many): UAVs
        // move little in a tick, so it is nearly sorted still and an insertion sort finishes it in
        // about one pass (a UAV that changed band moves one band's length).
        let finite = positions.iter().filter(|p| uav::is_finite(p)).count();
        let same_points = self.sorted_for == n
            && self.by_band.len() == finite
            && self.by_band.iter().all(|e| uav::is_finite(&positions[e.2 as usize]));
        if same_points {
            for e in &mut self.by_band {
                let p = positions[e.2 as usize];
                *e = (band(p.y), p.x, e.2);
            }
        } else {
            self.by_band.clear();
            self.by_band.extend(
                (0..n)
                    .filter(|&k| uav::is_finite(&positions[k]))
                    // Fleets are far below 2³² UAVs (the server admits at most a few hundred thousand).
                    .map(|k| (band(positions[k].y), positions[k].x, k as u32)),
            );
        }
        self.sorted_for = n;
        // A total order (the index breaks ties): the same sorted entries whatever the order they
        // start in, on any number of threads.
        let wide = crate::tick::parallel(n);
        let budget = SHIFTS_PER_ENTRY * self.by_band.len();
        if !(same_points && insertion_sort_within(&mut self.by_band, budget)) {
            if wide { self.by_band.par_sort_unstable_by(order) } else { self.by_band.sort_unstable_by(order) }
        }
        let entries = &self.by_band;
        // The halves split in the middle, inside a band or not (each UAV's search reads whole bands
        // whichever half it is in): a band can hold much of a road running along it.
        let split = if wide { entries.len() / 2 } else { entries.len() };
        let [first, second] = &mut self.halves;
        let search = (positions, own, radius, &band);
        if wide {
            rayon::join(
                || find(entries, 0..split, search, first),
                || find(entries, split..entries.len(), search, second),
            );
        } else {
            find(entries, 0..split, search, first);
            second.ends.clear();
        }
        self.lists.reset(own);
        self.foreign.reset(own);
        // Each half's lists copied in one piece (its UAVs' lists follow one another).
        for half in &self.halves {
            let starts =
                std::iter::once((0, 0)).chain(half.ends.iter().map(|&(_, own, foreign)| (own, foreign)));
            let spans = half.ends.iter().zip(starts);
            let own_spans = spans.clone().map(|(&(a, own_end, _), (own_start, _))| (a, own_start, own_end));
            self.lists.extend_lists(&half.own, own_spans);
            let foreign_spans =
                spans.map(|(&(a, _, foreign_end), (_, foreign_start))| (a, foreign_start, foreign_end));
            self.foreign.extend_lists(&half.foreign, foreign_spans);
        }
    }
}

/// The neighbour lists of the own UAVs among `entries[range]` (which may start or end inside a
/// band: each UAV's windows are the whole runs of its bands), into `out`.
fn find(
    entries: &[(i64, f64, u32)],
    range: std::ops::Range<usize>,
    (positions, own, radius, band): (&[Vec2], usize, f64, &(impl Fn(f64) -> i64 + Sync)),
    out: &mut Found,
) {
    out.own.clear();
    out.foreign.clear();
    out.ends.clear();
    let hits = &mut out.hits;
    let r2 = radius * radius;
    let mut start = range.start;
    while start < range.end {
        // Bands are clamped to ±MAX_BAND (2⁵²), so b ± 2 does not overflow.
        let b = entries[start].0;
        let end = (start + entries[start..].partition_point(|e| e.0 == b)).min(range.end);
        // The runs of bands b − 2 to b + 2 (empty where no UAV is), with window pointers: a UAV
        // looks at b − 1 to b + 1, and at b ± 2 as well when y ∓ r (widened as x ± r below) falls
        // there, which rounding in y / r can make happen for a pair exactly r apart.
        let run = |band: i64| {
            let lo = entries.partition_point(|e| e.0 < band);
            (lo, lo + entries[lo..].partition_point(|e| e.0 == band))
        };
        let runs = [run(b - 2), run(b - 1), run(b), run(b + 1), run(b + 2)];
        let mut from = runs.map(|(lo, _)| lo);
        for &(_, x, a) in &entries[start..end] {
            let (a, p) = (a as usize, positions[a as usize]);
            if a >= own {
                continue;
            }
            // Each window: the entries of a run with x in [x − r, x + r]; its points within the
            // radius are kept with their x, then the windows' hits are put in (x, index)
            // order (each window is in that order already: a sort of a few short runs).
            hits.clear();
            // The window is widened by a few ulps of its bounds, so that rounding in x ± r never
            // leaves out a point the distance test below keeps (a pair 1.0324927 m apart with
            // that radius was found from one side only), and the lists stay symmetric.
            let slack = (x.abs() + radius) * 4.0 * f64::EPSILON;
            let (x_lo, x_hi) = (x - radius - slack, x + radius + slack);
            let slack_y = (p.y.abs() + radius) * 4.0 * f64::EPSILON;
            let below = usize::from(band(p.y - radius - slack_y) < b - 1);
            let above = usize::from(band(p.y + radius + slack_y) > b + 1);
            for w in 1 - below..4 + above {
                while from[w] < runs[w].1 && entries[from[w]].1 < x_lo {
                    from[w] += 1;
                }
                // The window's end first (x alone, in order), then its points written one after
                // the other with the count moved on only for those within the radius: whether a
                // point is within it is as good as random, and a branch on it was mispredicted.
                let window = &entries[from[w]..runs[w].1];
                let window = &window[..window.iter().take_while(|e| e.1 <= x_hi).count()];
                let mut n = hits.len();
                hits.resize(n + window.len(), (0.0, 0));
                for &(_, xd, d) in window {
                    hits[n] = (xd, d);
                    let within = d as usize != a && (positions[d as usize] - p).norm_squared() <= r2;
                    n += usize::from(within);
                }
                hits.truncate(n);
            }
            hits.sort_unstable_by(|u, w| u.0.total_cmp(&w.0).then(u.1.cmp(&w.1)));
            if own == positions.len() {
                // No foreign points (a fleet alone): the hits in one `extend`, not a push each (two
                // filtered `extend`s for both cases measured 7 % slower on the whole search).
                out.own.extend(hits.iter().map(|&(_, d)| d as usize));
            } else {
                for &(_, d) in hits.iter() {
                    let d = d as usize;
                    if d < own { out.own.push(d) } else { out.foreign.push(d - own) }
                }
            }
            out.ends.push((a, out.own.len(), out.foreign.len()));
        }
        start = end;
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

    /// The lists of a search, one vector each.
    fn lists(s: &NeighbourSearch) -> Vec<Vec<usize>> {
        (0..s.lists.len()).map(|k| s.lists[k].to_vec()).collect()
    }

    /// Pairs exactly the radius apart where rounding once hid them (each case failed before its
    /// fix): x + r rounding below the farther one's x (found by the property test below), and
    /// y / r rounding to bands two apart (a tiny negative y in band −1, the other at r in band 1).
    /// Each is in the other's list.
    #[test]
    fn pairs_exactly_the_radius_apart_are_found_from_both_sides() {
        let across_x = (
            1.0324927022956785,
            [
                Vec2::new(-0.9911929942038513, 24.779824855096283),
                Vec2::new(0.041299708091827175, 24.779824855096283),
            ],
        );
        let across_bands = (3.45463424658999, [Vec2::new(0.0, -1e-17), Vec2::new(0.0, 3.45463424658999)]);
        for (radius, pts) in [across_x, across_bands] {
            assert!((pts[1] - pts[0]).norm_squared() <= radius * radius);
            let mut s = NeighbourSearch::default();
            s.update(&pts, radius);
            assert_eq!(lists(&s), vec![vec![1], vec![0]], "{pts:?} with radius {radius}");
            assert_eq!(lists(&s), brute(&pts, radius));
        }
    }

    #[test]
    fn grid_finds_exactly_the_pairs_within_the_radius() {
        let pts: Vec<Vec2> =
            (0..60).map(|i| Vec2::new(((i * 37) % 23) as f64 * 0.7, ((i * 11) % 13) as f64 * 0.9)).collect();
        let mut s = NeighbourSearch::default();
        s.update(&pts, 2.0);
        assert_eq!(lists(&s), brute(&pts, 2.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// The grid's lists equal the all-pairs search: clusters, points on cell borders (multiples of
        /// the radius, or a hair below), negative and far-out coordinates, non-finite points, repeated
        /// points.
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
                    // On a band's edge, or a hair below it: pairs exactly r apart across two edges.
                    4 => Vec2::new(i as f64 * radius, j as f64 * radius - f * 1e-15),
                    _ => Vec2::new(i as f64 * 0.1 + f, j as f64 * 0.1 - f),
                })
                .collect();
            let mut s = NeighbourSearch::default();
            s.update(&pts, radius);
            prop_assert_eq!(lists(&s), brute(&pts, radius));
            // Reused buffers: a second, smaller update gives the same as a fresh search.
            let fewer = &pts[..pts.len() / 2];
            s.update(fewer, radius);
            prop_assert_eq!(lists(&s), brute(fewer, radius));
            // As many points again, then moved a little (the last order is reused), then a finite
            // point and a non-finite one swapped (the same count, other points: sorted afresh).
            s.update(&pts, radius);
            let step = |i: usize| Vec2::new((i % 5) as f64 * 0.37 - 0.7, (i % 3) as f64 * 0.45 - 0.45) * radius;
            let moved: Vec<Vec2> = pts.iter().enumerate().map(|(i, p)| p + step(i)).collect();
            s.update(&moved, radius);
            prop_assert_eq!(lists(&s), brute(&moved, radius));
            let mut swapped = moved.clone();
            if let (Some(a), Some(b)) = (
                swapped.iter().position(uav::is_finite),
                swapped.iter().position(|p| !uav::is_finite(p)),
            ) {
                swapped.swap(a, b);
            }
            s.update(&swapped, radius);
            prop_assert_eq!(lists(&s), brute(&swapped, radius));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// With foreign points, each own UAV's two lists are the all-pairs list split at `own`, and
        /// foreign points get no list.
        #[test]
        fn foreign_points_are_split_off(
            raw in proptest::collection::vec((-30i32..30, -30i32..30), 0..80),
            own_share in 0.0f64..=1.0,
            radius in 0.1f64..4.0,
        ) {
            let pts: Vec<Vec2> = raw.iter().map(|&(i, j)| Vec2::new(i as f64 * 0.2, j as f64 * 0.2)).collect();
            let own = (pts.len() as f64 * own_share) as usize;
            let mut s = NeighbourSearch::default();
            s.update_with_foreign(&pts, own, radius);
            let all = brute(&pts, radius);
            prop_assert_eq!(s.lists.len(), own);
            prop_assert_eq!(s.foreign.len(), own);
            for (k, list) in all.iter().enumerate().take(own) {
                let mine: Vec<usize> = list.iter().copied().filter(|&d| d < own).collect();
                let foreign: Vec<usize> = list.iter().filter(|&&d| d >= own).map(|&d| d - own).collect();
                prop_assert_eq!(s.lists[k].to_vec(), mine);
                prop_assert_eq!(s.foreign[k].to_vec(), foreign);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        /// Fleets large enough to be searched in two halves on both cores, lying along a few bands
        /// (a road running along x), so the halves split inside a band: the lists, own and foreign,
        /// equal the all-pairs search.
        #[test]
        fn halves_split_inside_a_band_find_every_pair(
            raw in proptest::collection::vec((0.0f64..60.0, -1.5f64..1.5), crate::tick::PARALLEL_FROM_UAVS..400),
            foreign in 0usize..30,
            radius in 0.3f64..3.0,
        ) {
            let pts: Vec<Vec2> = raw.iter().map(|&(x, y)| Vec2::new(x, y)).collect();
            let own = pts.len() - foreign.min(pts.len());
            let all = brute(&pts, radius);
            let mut s = NeighbourSearch::default();
            s.update_with_foreign(&pts, own, radius);
            for (k, list) in all.iter().enumerate().take(own) {
                let mine: Vec<usize> = list.iter().copied().filter(|&d| d < own).collect();
                let foreign: Vec<usize> = list.iter().filter(|&&d| d >= own).map(|&d| d - own).collect();
                prop_assert_eq!(s.lists[k].to_vec(), mine);
                prop_assert_eq!(s.foreign[k].to_vec(), foreign);
            }
        }
    }

    proptest! {
        /// The insertion sort sorts within its budget, and otherwise says so and keeps every entry.
        #[test]
        fn the_insertion_sort_sorts_or_gives_up_keeping_the_entries(
            raw in proptest::collection::vec((-3i64..3, -5i32..5), 0..60),
            budget in 0usize..400,
        ) {
            let mut entries: Vec<(i64, f64, u32)> =
                raw.iter().enumerate().map(|(i, &(b, x))| (b, x as f64 * 0.5, i as u32)).collect();
            let mut sorted = entries.clone();
            sorted.sort_unstable_by(order);
            if insertion_sort_within(&mut entries, budget) {
                prop_assert_eq!(&entries, &sorted);
            } else {
                entries.sort_unstable_by(order);
                prop_assert_eq!(&entries, &sorted);
            }
        }
    }

    #[test]
    fn an_infinite_radius_makes_everyone_a_neighbour() {
        let pts = [Vec2::new(0.0, 0.0), Vec2::new(1e9, -1e9), Vec2::new(f64::NAN, 0.0)];
        let mut s = NeighbourSearch::default();
        s.update(&pts, f64::INFINITY);
        assert_eq!(lists(&s), vec![vec![1], vec![0], vec![]]);
    }
}
