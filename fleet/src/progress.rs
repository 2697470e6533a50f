//! Progress along the route and stalls: a UAV with a goal that has not come
//! [`PROGRESS_STEP_M`] closer to it (in road coordinates, [`roads::RoutePosition::remaining`]) for
//! [`STALL_AFTER_S`] is stalled, from its last progress on. Stall time is what METRICS.json reports
//! (`stall_s`, `max_stall_s`) and what the deadlock rule ([`crate::traffic`]) reads.

/// How much closer (m) a UAV must come to its goal to count as progress.
pub const PROGRESS_STEP_M: f64 = 0.05;

/// A UAV without progress for this long (s) is stalled.
pub const STALL_AFTER_S: f64 = 1.0;

/// What a tick adds to a stall total for a UAV stalled `stall_s` seconds now (0 when it is not):
/// the whole time since its last progress on its first stalled tick, one `dt` after that.
pub fn stall_time_added(stall_s: f64, dt: f64) -> f64 {
    match stall_s {
        s if s <= 0.0 => 0.0,
        s if s < STALL_AFTER_S + dt / 2.0 => s,
        _ => dt,
    }
}

/// One UAV's progress towards its current goal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// The distance left at the last progress (∞ before the first observation).
    best: f64,
    /// Time (s) of the last progress, or when tracking (re)started.
    since: f64,
    /// It is tracked (a goal, not arrived, flying) as of the last update.
    active: bool,
}

impl Default for Progress {
    fn default() -> Self {
        Self { best: f64::INFINITY, since: 0.0, active: false }
    }
}

impl Progress {
    /// Records what is left to fly at time `now`: `Some(remaining)` while the UAV flies towards a
    /// goal, None otherwise (no goal, arrived, not flying, held by the operator): tracking restarts.
    pub fn update(&mut self, remaining: Option<f64>, now: f64) {
        match remaining {
            // `best` stays at the distance of the last progress, so slow steady progress counts too.
            Some(left) if self.active => {
                if left <= self.best - PROGRESS_STEP_M {
                    (self.best, self.since) = (left, now);
                }
            }
            Some(left) => *self = Self { best: left, since: now, active: true },
            None => *self = Self::default(),
        }
    }

    /// Time (s) without progress at `now` (0 while not tracked).
    pub fn without_progress(&self, now: f64) -> f64 {
        if self.active { (now - self.since).max(0.0) } else { 0.0 }
    }

    /// The length (s) of the stall the UAV is in at `now`, if it is stalled.
    pub fn stalled_for(&self, now: f64) -> Option<f64> {
        let idle = self.without_progress(now);
        (idle >= STALL_AFTER_S).then_some(idle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stall_starts_at_the_last_progress_and_ends_with_progress() {
        let mut p = Progress::default();
        p.update(Some(10.0), 0.0);
        p.update(Some(9.0), 0.5);
        // Hovering, with jitter smaller than the progress step: stalled 1 s after the last progress.
        for (k, left) in [9.01, 8.97, 9.02, 8.99].iter().enumerate() {
            p.update(Some(*left), 1.0 + k as f64 * 0.2);
        }
        assert_eq!(p.stalled_for(1.4), None);
        assert_eq!(p.stalled_for(1.5), Some(1.0));
        assert_eq!(p.stalled_for(3.5), Some(3.0));
        p.update(Some(8.9), 3.6);
        assert_eq!(p.stalled_for(3.6), None);
        // A new goal, arrival or landing restarts tracking.
        p.update(None, 4.0);
        assert_eq!(p.without_progress(10.0), 0.0);
    }

    #[test]
    fn a_stall_adds_up_to_its_length() {
        // Last progress at t = 0, detected at t = 1, last stalled tick at t = 2.45: the total is
        // the stall's length at its last tick, as `max_stall_s` reports it.
        let dt = 0.05;
        let total: f64 = (20..50).map(|k| stall_time_added(k as f64 * dt, dt)).sum();
        assert!((total - 2.45).abs() < 1e-9, "{total}");
        assert_eq!(stall_time_added(0.0, dt), 0.0);
    }
}
