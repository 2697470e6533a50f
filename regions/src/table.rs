//! The latest message of each neighbouring region, shared between the Zenoh subscriber (which
//! replaces a region's entry) and the fleet loop (which copies every entry out before each tick).
//! The lock is held only to replace an entry or to copy the UAVs out, never across I/O, so the loop
//! never waits on the network.

use super::wire::RegionStates;
use fleet::ForeignUav;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::Instant;
use uav::{UavState, Vec2};

/// Added to every foreign state's age: the time a message spends between the sender's `put` and its
/// arrival, which neither clock measures alone (loopback and LAN take well under this).
pub const TRANSIT_ALLOWANCE_S: f64 = 0.01;

/// A region's last message as received.
#[derive(Debug)]
struct Heard {
    /// When it arrived (this process's monotonic clock).
    received: Instant,
    /// How old its states were when sent (the sender's measure).
    age_at_send_s: f64,
    /// Its UAVs.
    uavs: Vec<HeardUav>,
}

/// One UAV of a region's last message.
#[derive(Debug)]
struct HeardUav {
    id: String,
    state: UavState,
    /// How long before the message's tick it was last heard (s).
    unheard_s: f64,
    /// Released by that region, which no longer commands it.
    ghost: bool,
}

/// The latest message per neighbouring region, and counters for `GET /api/metrics`.
#[derive(Debug)]
pub struct ForeignTable {
    /// This server's region (messages naming it are refused).
    own: String,
    regions: Mutex<HashMap<String, Heard>>,
    /// Messages accepted.
    received: AtomicU64,
    /// Messages refused (undecodable, or naming another region than their key).
    refused: AtomicU64,
}

impl ForeignTable {
    /// An empty table for the server of region `own`.
    pub fn new(own: &str) -> Self {
        Self {
            own: own.into(),
            regions: Mutex::default(),
            received: AtomicU64::new(0),
            refused: AtomicU64::new(0),
        }
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<String, Heard>> {
        // The table holds plain data replaced whole: a panic elsewhere cannot leave it half-written.
        self.regions.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Replaces the entry of the region `states` comes from (received at `at`); each message lists
    /// all of a region's UAVs, so UAVs it no longer lists are forgotten. A message from `expected`'s
    /// key that names another region, or this server's own, is refused.
    pub fn accept(&self, expected: &str, states: RegionStates, at: Instant) -> bool {
        if states.region != expected || states.region == self.own {
            self.refuse();
            return false;
        }
        let uavs = states
            .uavs
            .into_iter()
            .map(|u| {
                let (p, v) = (
                    Vec2::new(f64::from(u.p[0]), f64::from(u.p[1])),
                    Vec2::new(f64::from(u.v[0]), f64::from(u.v[1])),
                );
                let (unheard_s, ghost) = (f64::from(u.unheard_ms) / 1000.0, u.ghost());
                HeardUav { id: u.id, state: UavState { p, v }, unheard_s, ghost }
            })
            .collect();
        let heard = Heard { received: at, age_at_send_s: f64::from(states.age_at_send_s), uavs };
        self.lock().insert(states.region, heard);
        self.received.fetch_add(1, Relaxed);
        true
    }

    /// Counts a message that could not be used.
    pub fn refuse(&self) {
        self.refused.fetch_add(1, Relaxed);
    }

    /// Every foreign UAV into `out` with its age at `now`: how long before its message's tick it
    /// was last heard, plus the sender's age at sending, plus the time since the message arrived,
    /// plus [`TRANSIT_ALLOWANCE_S`]. Reuses `out`'s strings.
    pub fn copy_into(&self, now: Instant, out: &mut Vec<ForeignUav>) {
        let regions = self.lock();
        let mut n = 0;
        for heard in regions.values() {
            let age_s = heard.age_at_send_s
                + now.saturating_duration_since(heard.received).as_secs_f64()
                + TRANSIT_ALLOWANCE_S;
            for u in &heard.uavs {
                let age_s = age_s + u.unheard_s;
                if let Some(slot) = out.get_mut(n) {
                    slot.id.clone_from(&u.id);
                    (slot.state, slot.age_s) = (u.state, age_s);
                } else {
                    out.push(ForeignUav { id: u.id.clone(), state: u.state, age_s });
                }
                n += 1;
            }
        }
        out.truncate(n);
    }

    /// The UAVs the neighbours command now, with the region that commands each.
    pub fn commanded_by(&self) -> HashMap<String, String> {
        let regions = self.lock();
        regions
            .iter()
            .flat_map(|(name, h)| {
                h.uavs.iter().filter(|u| !u.ghost).map(move |u| (u.id.clone(), name.clone()))
            })
            .collect()
    }

    /// The UAVs the neighbours command now (their last messages' records that are not ghosts).
    pub fn commanded_ids(&self) -> std::collections::HashSet<String> {
        let regions = self.lock();
        regions.values().flat_map(|h| h.uavs.iter().filter(|u| !u.ghost).map(|u| u.id.clone())).collect()
    }

    /// `GET /api/metrics` `region`: its name, the foreign UAVs known (`foreign_uavs`), per
    /// neighbouring region heard from the UAVs of its last message and that message's age at
    /// `now`, and the counts of messages accepted and refused.
    pub fn report(&self, now: Instant) -> TableReport {
        let regions = self.lock();
        let heard = regions
            .iter()
            .map(|(name, h)| {
                let age_s = h.age_at_send_s + now.saturating_duration_since(h.received).as_secs_f64();
                (name.clone(), HeardReport { uavs: h.uavs.len(), age_s })
            })
            .collect();
        TableReport {
            name: self.own.clone(),
            foreign_uavs: regions.values().map(|h| h.uavs.len()).sum::<usize>(),
            heard,
            messages: self.received.load(Relaxed),
            refused: self.refused.load(Relaxed),
        }
    }
}

/// The neighbours' table in `region` of `GET /api/metrics`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, schemars::JsonSchema)]
pub struct TableReport {
    /// This server's region.
    pub name: String,
    /// The foreign UAVs known.
    pub foreign_uavs: usize,
    /// Per neighbouring region heard from, its last message.
    pub heard: std::collections::BTreeMap<String, HeardReport>,
    /// State messages accepted.
    pub messages: u64,
    /// State messages refused.
    pub refused: u64,
}

/// A neighbour's last state message.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, schemars::JsonSchema)]
pub struct HeardReport {
    /// The UAVs it listed.
    pub uavs: usize,
    /// Its age now (s).
    pub age_s: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{self, WireUav};
    use std::time::Duration;

    fn states(region: &str, ids: &[&str]) -> RegionStates {
        let uav = |id: &&str| WireUav {
            id: id.to_string(),
            p: [1.0, 2.0],
            v: [0.5, 0.0],
            u: [0.0; 2],
            target: [0.0; 2],
            status: 0,
            flags: 0,
            unheard_ms: 0,
        };
        RegionStates {
            region: region.into(),
            tick: 1,
            time: 0.05,
            age_at_send_s: 0.02,
            uavs: ids.iter().map(uav).collect(),
        }
    }

    #[test]
    fn ages_count_from_arrival_and_a_new_message_replaces_the_region() {
        let table = ForeignTable::new("west");
        let t0 = Instant::now();
        assert!(table.accept("east", states("east", &["a", "b"]), t0));
        let mut out = Vec::new();
        table.copy_into(t0 + Duration::from_millis(100), &mut out);
        assert_eq!(out.len(), 2);
        let expected = 0.02 + 0.1 + TRANSIT_ALLOWANCE_S;
        assert!(out.iter().all(|f| (f.age_s - expected).abs() < 1e-6), "{out:?}");
        assert_eq!(out[0].state.p, Vec2::new(1.0, 2.0));
        assert!(table.accept("east", states("east", &["b"]), t0 + Duration::from_millis(150)));
        table.copy_into(t0 + Duration::from_millis(150), &mut out);
        assert_eq!(out.iter().map(|f| f.id.as_str()).collect::<Vec<_>>(), ["b"]);
        assert_eq!(table.report(t0).foreign_uavs, 1);
    }

    #[test]
    fn a_silent_uav_or_a_ghost_is_older_by_its_unheard_time_and_ghosts_are_not_commanded() {
        let table = ForeignTable::new("west");
        let t0 = Instant::now();
        let mut message = states("east", &["a", "lost", "ghost"]);
        message.uavs[1].unheard_ms = 400;
        (message.uavs[2].unheard_ms, message.uavs[2].flags) = (150, wire::UAV_GHOST);
        assert!(table.accept("east", message, t0));
        let mut out = Vec::new();
        table.copy_into(t0, &mut out);
        let base = 0.02 + TRANSIT_ALLOWANCE_S;
        let ages: Vec<f64> = out.iter().map(|f| f.age_s - base).collect();
        assert!((ages[0]).abs() < 1e-9 && (ages[1] - 0.4).abs() < 1e-9 && (ages[2] - 0.15).abs() < 1e-9);
        let mut commanded: Vec<String> = table.commanded_ids().into_iter().collect();
        commanded.sort();
        assert_eq!(commanded, ["a", "lost"]);
    }

    #[test]
    fn a_message_naming_another_region_or_this_one_is_refused() {
        let table = ForeignTable::new("west");
        let t0 = Instant::now();
        assert!(!table.accept("east", states("north", &["a"]), t0));
        assert!(!table.accept("west", states("west", &["a"]), t0));
        let mut out = Vec::new();
        table.copy_into(t0, &mut out);
        assert!(out.is_empty());
        assert_eq!(table.report(t0).refused, 2);
    }
}
