//! Where the UAVs on a route are along the road, by direction of travel ([`TrafficAlong`]): the
//! arc lengths of each direction in buckets of fixed length along the road (a counting sort, linear
//! in the fleet), so that "is a UAV flying the other way within r_s ahead" scans a bucket or two
//! instead of a binary search over the whole fleet (a log factor that grew at 100,000 UAVs).

use crate::member::Uav;
use crate::traffic::foreign::ForeignView;
use roads::RoutePosition;
use uav::Vec2;

/// At most this many buckets per arc length bucketed (plus a few), so the index stays linear in the
/// fleet however long the road or short the range.
const BUCKETS_PER_UAV: usize = 4;

/// What [`crate::traffic::following::follow`] reads of every UAV, copied once per tick (a UAV's link
/// is not shared across threads, so the UAVs themselves are not).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Seen {
    /// Where it is on its route (None off one).
    pub route: Option<RoutePosition>,
    /// Position.
    pub p: Vec2,
    /// Velocity.
    pub v: Vec2,
}

/// Arc lengths bucketed along the road: bucket b holds the values s with ⌊s / width⌋ = b (clamped
/// to the first and last bucket), in `values[starts[b]..starts[b + 1]]`.
#[derive(Debug, Default)]
struct Buckets {
    width: f64,
    starts: Vec<usize>,
    values: Vec<f64>,
}

impl Buckets {
    /// The bucket of arc length `s` (monotone in `s`; NaN in the first).
    fn of(&self, s: f64) -> usize {
        // Saturating float-to-int cast: negative and NaN give 0, the clamp bounds the rest.
        ((s / self.width).floor() as usize).min(self.starts.len().saturating_sub(2))
    }

    /// Buckets `values` (taken, its buffer kept for the next tick) by `width` over `length` m.
    fn fill(&mut self, values: &mut Vec<f64>, length: f64, width: f64) {
        let cap = BUCKETS_PER_UAV * values.len() + 2;
        let width = width.max(length / cap as f64);
        self.width = if width > 0.0 && width.is_finite() { width } else { f64::INFINITY };
        let buckets =
            if self.width.is_finite() { ((length / self.width).ceil() as usize).min(cap) + 1 } else { 1 };
        // A counting sort: each bucket's count, its start, then each value at its bucket's cursor.
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        for &s in values.iter() {
            let b = self.of(s);
            self.starts[b + 1] += 1;
        }
        for b in 1..self.starts.len() {
            self.starts[b] += self.starts[b - 1];
        }
        self.values.clear();
        self.values.resize(values.len(), 0.0);
        for &s in values.iter() {
            let b = self.of(s);
            self.values[self.starts[b]] = s;
            self.starts[b] += 1;
        }
        // Each cursor now stands at its bucket's end, the next one's start: shifted back by one.
        for b in (1..self.starts.len()).rev() {
            self.starts[b] = self.starts[b - 1];
        }
        self.starts[0] = 0;
        values.clear();
    }

    /// True when some value lies in [lo, hi]: exact, scanning the buckets of lo to hi.
    fn any_within(&self, lo: f64, hi: f64) -> bool {
        if self.values.is_empty() || lo.is_nan() || hi.is_nan() || lo > hi {
            return false;
        }
        let (first, last) = (self.of(lo), self.of(hi));
        self.values[self.starts[first]..self.starts[last + 1]].iter().any(|&s| lo <= s && s <= hi)
    }
}

/// Where the UAVs on a route are along the road, by direction of travel (rebuilt each tick into
/// buffers kept between ticks).
#[derive(Debug, Default)]
pub struct TrafficAlong {
    /// Towards increasing s.
    forward: Buckets,
    /// Towards decreasing s.
    backward: Buckets,
    /// The arc length (m) ahead that [`TrafficAlong::oncoming_within`] looks over (the buckets'
    /// length).
    range: f64,
    /// Scratch: each direction's arc lengths before bucketing.
    scratch: [Vec<f64>; 2],
    /// Every UAV as `follow` reads it, by index.
    pub(crate) seen: Vec<Seen>,
}

impl TrafficAlong {
    /// Buckets the UAVs on a route and the `foreign` ones moving along the road by direction, on a
    /// road `length` m long, for queries over `range` m of arc length.
    pub(crate) fn update(&mut self, uavs: &[Uav], foreign: &[ForeignView], length: f64, range: f64) {
        self.range = range;
        let seen = |u: &Uav| Seen { route: u.traffic.route, p: u.state.p, v: u.state.v };
        crate::tick::map_into(uavs, seen, &mut self.seen);
        let [forward, backward] = &mut self.scratch;
        // From the plain copies just made, not the records again.
        let routes =
            self.seen.iter().filter_map(|u| u.route).chain(foreign.iter().filter_map(|f| f.flying_along()));
        for pos in routes {
            if pos.direction() > 0.0 { forward.push(pos.s) } else { backward.push(pos.s) }
        }
        self.forward.fill(forward, length, range);
        self.backward.fill(backward, length, range);
    }

    /// True when a UAV flying the other way is within the `range` of the last update ahead of `me`.
    pub(crate) fn oncoming_within(&self, me: &RoutePosition) -> bool {
        let range = self.range;
        if me.direction() > 0.0 {
            self.backward.any_within(me.s, me.s + range)
        } else {
            self.forward.any_within(me.s - range, me.s)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// The buckets answer exactly as a scan of every value, whatever the road's length, the
        /// bucket width and values off the road (before it, past it, not finite).
        #[test]
        fn buckets_answer_as_a_scan_of_every_value(
            values in prop::collection::vec(prop_oneof![
                8 => -10.0f64..110.0,
                1 => Just(f64::NAN),
                1 => Just(f64::INFINITY),
                1 => Just(f64::NEG_INFINITY),
            ], 0..60),
            length in prop_oneof![Just(0.0), 0.5f64..200.0],
            width in prop_oneof![Just(0.0), 0.01f64..50.0],
            queries in prop::collection::vec((-20.0f64..120.0, 0.0f64..30.0), 1..20),
        ) {
            let mut buckets = Buckets::default();
            let mut scratch = values.clone();
            buckets.fill(&mut scratch, length, width);
            prop_assert!(scratch.is_empty());
            prop_assert!(buckets.starts.len() <= BUCKETS_PER_UAV * values.len() + 4);
            for (lo, range) in queries {
                let hi = lo + range;
                let scan = values.iter().any(|&s| lo <= s && s <= hi);
                prop_assert_eq!(buckets.any_within(lo, hi), scan, "[{}, {}]", lo, hi);
            }
        }
    }
}
