//! How old the foreign states are when the fleet uses them (`GET /api/metrics` `region.foreign_age_ms`,
//! `bench regions`): a histogram of 1 ms buckets the loop fills once per tick, with every foreign
//! UAV's age at that tick, read by the metrics without a lock.

use fleet::ForeignUav;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Buckets of 1 ms; older states fall in the last one.
pub const AGE_BUCKETS: usize = 2_000;

/// The histogram (atomics: the loop adds, readers read).
#[derive(Debug)]
pub struct AgeHistogram {
    counts: Vec<AtomicU64>,
    max_ms: AtomicU64,
}

impl Default for AgeHistogram {
    fn default() -> Self {
        Self { counts: (0..AGE_BUCKETS).map(|_| AtomicU64::new(0)).collect(), max_ms: AtomicU64::new(0) }
    }
}

impl AgeHistogram {
    /// Adds the ages of the foreign UAVs used this tick.
    pub fn record(&self, used: &[ForeignUav]) {
        let mut max = 0;
        for u in used {
            let ms = (u.age_s * 1e3).clamp(0.0, (AGE_BUCKETS - 1) as f64) as usize;
            self.counts[ms].fetch_add(1, Relaxed);
            max = max.max(ms as u64);
        }
        self.max_ms.fetch_max(max, Relaxed);
    }

    /// `{samples, p50, p99, max}` in ms (bucket upper edges), nulls before any sample.
    pub fn report(&self) -> AgeReport {
        let counts: Vec<u64> = self.counts.iter().map(|c| c.load(Relaxed)).collect();
        let samples: u64 = counts.iter().sum();
        let quantile = |q: f64| {
            let rank = (q * samples as f64).ceil().max(1.0) as u64;
            let mut seen = 0;
            counts.iter().position(|&c| {
                seen += c;
                seen >= rank
            })
        };
        let edge = |b: Option<usize>| b.filter(|_| samples > 0).map(|b| b + 1);
        AgeReport {
            samples,
            p50: edge(quantile(0.5)),
            p99: edge(quantile(0.99)),
            max: (samples > 0).then(|| self.max_ms.load(Relaxed) + 1),
        }
    }
}

/// `region.foreign_age_ms` of `GET /api/metrics` (ms, bucket upper edges; None before any sample).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
pub struct AgeReport {
    /// Foreign states used.
    pub samples: u64,
    /// Their median age.
    pub p50: Option<usize>,
    /// Their 99th percentile age.
    pub p99: Option<usize>,
    /// The oldest.
    pub max: Option<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use uav::UavState;

    fn aged(ages_ms: &[f64]) -> Vec<ForeignUav> {
        let state = UavState::at_rest(uav::Vec2::zeros());
        ages_ms.iter().map(|&a| ForeignUav { id: "f".into(), state, age_s: a / 1e3 }).collect()
    }

    #[test]
    fn quantiles_are_bucket_edges_and_old_ages_land_in_the_last_bucket() {
        let h = AgeHistogram::default();
        assert_eq!(h.report().p99, None);
        let mut ages: Vec<f64> = (0..99).map(|_| 10.5).collect();
        ages.push(60_000.0);
        h.record(&aged(&ages));
        let r = h.report();
        assert_eq!((r.samples, r.p50, r.p99), (100, Some(11), Some(11)));
        assert_eq!(r.max, Some(AGE_BUCKETS as u64));
        h.record(&aged(&[30.0; 100]));
        assert_eq!(h.report().p99, Some(31));
    }
}
