//! A fixed-size histogram of positive durations with 1 % relative resolution: the solve-time
//! percentiles of a run in constant memory however long it runs (a server may run for days).

/// Relative width of a bucket: values in bucket k lie in [BASE·GROWTH^k, BASE·GROWTH^(k+1)).
const GROWTH: f64 = 1.01;
/// Lower edge (µs) of the first bucket; smaller values (and zero) count in it.
const BASE_US: f64 = 1e-3;
/// Buckets: from 1 ns to beyond 10⁷ µs (10 s); larger values count in the last one.
const BUCKETS: usize = 2_320;

/// Counts of durations (µs) in logarithmic buckets, with the exact smallest and largest.
#[derive(Debug, Clone)]
pub struct DurationHistogram {
    counts: Box<[u64; BUCKETS]>,
    total: u64,
    min: f64,
    max: f64,
}

impl Default for DurationHistogram {
    fn default() -> Self {
        Self { counts: Box::new([0; BUCKETS]), total: 0, min: f64::INFINITY, max: f64::NEG_INFINITY }
    }
}

fn bucket(us: f64) -> usize {
    if us.is_nan() || us <= BASE_US {
        return 0;
    }
    ((us / BASE_US).ln() / GROWTH.ln()).floor().min((BUCKETS - 1) as f64) as usize
}

impl DurationHistogram {
    /// Counts one duration (µs); NaN counts as 0.
    pub fn record(&mut self, us: f64) {
        let us = if us.is_nan() { 0.0 } else { us };
        self.counts[bucket(us)] += 1;
        self.total += 1;
        self.min = self.min.min(us);
        self.max = self.max.max(us);
    }

    /// Forgets every duration recorded (keeping its buckets' memory).
    pub fn clear(&mut self) {
        if self.total > 0 {
            self.counts.fill(0);
        }
        (self.total, self.min, self.max) = (0, f64::INFINITY, f64::NEG_INFINITY);
    }

    /// Adds the durations `other` recorded, as if recorded here.
    pub fn merge(&mut self, other: &DurationHistogram) {
        if other.total == 0 {
            return;
        }
        for (mine, theirs) in self.counts.iter_mut().zip(other.counts.iter()) {
            *mine += theirs;
        }
        self.total += other.total;
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    /// Number of durations recorded.
    pub fn len(&self) -> u64 {
        self.total
    }

    /// True when nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.total == 0
    }

    /// The q-quantile (0 ≤ q ≤ 1) by nearest rank (rank round((n − 1)·q) from 0), as the middle of
    /// its bucket clamped to the smallest and largest value seen: within 1 % (or 1 ns) of the exact
    /// order statistic. 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        if self.total == 0 {
            return 0.0;
        }
        let rank = ((self.total - 1) as f64 * q.clamp(0.0, 1.0)).round() as u64;
        let mut seen = 0;
        for (k, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen > rank {
                if k == BUCKETS - 1 {
                    return self.max; // the last bucket is open-ended
                }
                // The first bucket also holds everything below BASE_US, down to 0.
                let middle = if k == 0 { BASE_US / 2.0 } else { BASE_US * GROWTH.powf(k as f64 + 0.5) };
                return middle.clamp(self.min, self.max);
            }
        }
        self.max
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// Every quantile is within 1 % of the exact nearest-rank order statistic.
        #[test]
        fn quantiles_are_within_one_percent(
            values in proptest::collection::vec(prop_oneof![0.0f64..1e-3, 1e-3f64..10.0, 10.0f64..1e5], 1..400),
            q in 0.0f64..=1.0,
        ) {
            let mut h = DurationHistogram::default();
            values.iter().for_each(|&v| h.record(v));
            let mut sorted = values.clone();
            sorted.sort_by(f64::total_cmp);
            let exact = sorted[((sorted.len() - 1) as f64 * q).round() as usize];
            let got = h.quantile(q);
            let bound = 0.01 * exact + BASE_US;
            prop_assert!((got - exact).abs() <= bound, "q {}: {} vs exact {}", q, got, exact);
        }

        /// Histograms of the parts of a series, merged (after a clear, as a reused one is), answer
        /// every quantile as the histogram of the whole series.
        #[test]
        fn merged_parts_answer_as_the_whole(
            values in proptest::collection::vec(prop_oneof![0.0f64..1e-3, 1e-3f64..10.0, 10.0f64..1e5], 0..300),
            cut in 0usize..300,
            q in 0.0f64..=1.0,
        ) {
            let cut = cut.min(values.len());
            let (mut whole, mut merged, mut part) =
                (DurationHistogram::default(), DurationHistogram::default(), DurationHistogram::default());
            values.iter().for_each(|&v| whole.record(v));
            part.record(123.0);
            for chunk in [&values[..cut], &values[cut..]] {
                part.clear();
                chunk.iter().for_each(|&v| part.record(v));
                merged.merge(&part);
            }
            prop_assert_eq!(merged.len(), whole.len());
            prop_assert_eq!(merged.quantile(q), whole.quantile(q));
        }
    }

    #[test]
    fn empty_and_extreme_values() {
        let mut h = DurationHistogram::default();
        assert_eq!(h.quantile(0.5), 0.0);
        h.record(f64::NAN);
        h.record(1e12);
        assert_eq!(h.len(), 2);
        assert!(h.quantile(0.0) <= BASE_US);
        assert_eq!(h.quantile(1.0), 1e12);
    }
}
