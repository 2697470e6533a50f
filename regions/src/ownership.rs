//! Who owned which UAV when (`GET /api/region/ownership`): each region records, per UAV, the
//! intervals in which its fleet loop commanded it, on the wall clock (seconds since the Unix epoch),
//! so a test or an operator can put the regions' logs side by side: they must never overlap, and a
//! handover's gap (release to adoption) stays under `handover::MAX_UNOWNED_S`.

use serde::Serialize;
use std::collections::{HashMap, VecDeque};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Closed intervals kept (the oldest are forgotten first; open ones are bounded by the fleet).
pub const MAX_CLOSED_INTERVALS: usize = 10_000;

/// One interval of ownership.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct Interval {
    /// The UAV.
    pub id: String,
    /// When this region started commanding it (s since the Unix epoch).
    pub from: f64,
    /// When it stopped (None: it still does).
    pub to: Option<f64>,
    /// How it came: `start` (with the server), `handover`, `failover` (a takeover) or `added` (over REST).
    pub came: &'static str,
    /// How it left: `handover`, `gave_way` (to another owner) or `removed` (None while owned).
    pub left: Option<&'static str>,
}

#[derive(Debug, Default)]
struct Log {
    open: HashMap<String, (f64, &'static str)>,
    closed: VecDeque<Interval>,
    forgotten: u64,
}

/// The ownership intervals of one region.
#[derive(Debug, Default)]
pub struct OwnershipLog {
    log: Mutex<Log>,
}

pub use engine::fleet_loop::wall_now;

impl OwnershipLog {
    fn lock(&self) -> MutexGuard<'_, Log> {
        // Plain data changed in single steps: a panic elsewhere cannot leave it half-written.
        self.log.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// This region commands `id` from `at` on (`came`: how it got it).
    pub fn open(&self, id: &str, at: f64, came: &'static str) {
        self.lock().open.insert(id.to_string(), (at, came));
    }

    /// This region stopped commanding `id` at `at` (`left`: how); nothing if it was not open.
    pub fn close(&self, id: &str, at: f64, left: &'static str) {
        let mut log = self.lock();
        if let Some((from, came)) = log.open.remove(id) {
            if log.closed.len() >= MAX_CLOSED_INTERVALS {
                log.closed.pop_front();
                log.forgotten += 1;
            }
            log.closed.push_back(Interval { id: id.to_string(), from, to: Some(at), came, left: Some(left) });
        }
    }

    /// Closes every open interval at `at` (the fleet was replaced).
    pub fn close_all(&self, at: f64, left: &'static str) {
        let ids: Vec<String> = self.lock().open.keys().cloned().collect();
        for id in ids {
            self.close(&id, at, left);
        }
    }

    /// Every interval kept, closed ones first (oldest first), then the open ones by id; and how many
    /// closed ones were forgotten.
    pub fn intervals(&self) -> (Vec<Interval>, u64) {
        let log = self.lock();
        let mut out: Vec<Interval> = log.closed.iter().cloned().collect();
        let mut open: Vec<Interval> = log
            .open
            .iter()
            .map(|(id, &(from, came))| Interval { id: id.clone(), from, to: None, came, left: None })
            .collect();
        open.sort_by(|a, b| a.id.cmp(&b.id));
        out.extend(open);
        (out, log.forgotten)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_close_once_and_the_oldest_are_forgotten_beyond_the_bound() {
        let log = OwnershipLog::default();
        log.open("a", 1.0, "start");
        log.open("b", 1.5, "handover");
        log.close("a", 2.0, "handover");
        log.close("a", 3.0, "removed"); // not open any more: nothing
        let (all, forgotten) = log.intervals();
        assert_eq!(forgotten, 0);
        assert_eq!(all.len(), 2);
        assert_eq!((all[0].id.as_str(), all[0].to, all[0].left), ("a", Some(2.0), Some("handover")));
        assert_eq!((all[1].id.as_str(), all[1].to, all[1].came), ("b", None, "handover"));
        for k in 0..MAX_CLOSED_INTERVALS + 5 {
            log.open("c", k as f64, "added");
            log.close("c", k as f64 + 0.5, "removed");
        }
        let (all, forgotten) = log.intervals();
        assert_eq!(forgotten, 6);
        assert_eq!(all.len(), MAX_CLOSED_INTERVALS + 1);
        log.close_all(9.0, "removed");
        assert!(log.intervals().0.iter().all(|i| i.to.is_some()));
    }
}
