//! What the UAVs add to the loop's statistics in one tick ([`TickCounts`]): stalls, QP counters,
//! fallbacks, stale states and the links' reports. A large fleet is counted per chunk of
//! [`CHUNK_UAVS`] consecutive UAVs on all cores, the chunks added in order: the same sums on any
//! number of threads.

use crate::snapshot::UavSnapshot;
use fleet::Uav;
use rayon::prelude::*;

/// UAVs per chunk of a large fleet (fixed, so the order of the sums does not depend on the threads).
const CHUNK_UAVS: usize = 4_096;

/// The UAVs' share of one tick's statistics.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct TickCounts {
    /// UAV-seconds of stall added this tick (as METRICS.json counts them).
    pub stall_s: f64,
    /// UAVs stalled now.
    pub stalled_uavs: u64,
    /// The longest stall going on (s).
    pub longest_stall_s: f64,
    /// QPs solved.
    pub solves: u64,
    /// Solves with a slack above 1e-6.
    pub slack_used: u64,
    /// Largest slack.
    pub max_slack: f64,
    /// Failed solves.
    pub failures: u64,
    /// Policies that gave no finite action.
    pub policy_fallbacks: u64,
    /// UAVs without a fresh state.
    pub stale_states: u64,
    /// Stops and landings given up on without confirmation, over the links.
    pub unconfirmed_commands: u64,
    /// UAVs flown over a Crazyflie link.
    pub crazyflies: u64,
    /// Links whose last error is set.
    pub with_error: u64,
    /// Crazyflies whose supervisor says locked.
    pub locked: u64,
    /// Crazyflies whose supervisor says tumbled or crashed.
    pub tumbled_or_crashed: u64,
    /// The lowest battery voltage reported.
    pub min_battery_v: Option<f64>,
    /// The lowest link quality reported.
    pub min_link_quality: Option<f64>,
}

/// The smaller of two optional values (either when the other is None).
pub(crate) fn min_opt(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

impl TickCounts {
    /// What `uavs` add in a tick of `dt` s, each with its entry of the tick's snapshot (which read
    /// each link's description and error once: an error is a string behind the session's lock).
    pub fn of(uavs: &[Uav], entries: &[UavSnapshot], dt: f64) -> Self {
        Self::in_chunks(uavs, entries, dt, CHUNK_UAVS)
    }

    /// [`TickCounts::of`] in chunks of `chunk` UAVs.
    pub(crate) fn in_chunks(uavs: &[Uav], entries: &[UavSnapshot], dt: f64, chunk: usize) -> Self {
        if uavs.len() < fleet::PARALLEL_FROM_UAVS {
            return Self::of_chunk(uavs, entries, dt);
        }
        let chunks = uavs.par_chunks(chunk).zip(entries.par_chunks(chunk));
        let counts: Vec<Self> = chunks.map(|(uavs, entries)| Self::of_chunk(uavs, entries, dt)).collect();
        counts.iter().fold(Self::default(), |all, chunk| all.merge(chunk))
    }

    fn of_chunk(uavs: &[Uav], entries: &[UavSnapshot], dt: f64) -> Self {
        let mut c = Self::default();
        for (u, entry) in uavs.iter().zip(entries) {
            let l = &u.last;
            c.stall_s += fleet::progress::stall_time_added(l.stall_s, dt);
            c.stalled_uavs += u64::from(l.stall_s > 0.0);
            c.longest_stall_s = c.longest_stall_s.max(l.stall_s);
            c.solves += u64::from(l.solved);
            c.slack_used += u64::from(l.max_slack > 1e-6);
            c.max_slack = c.max_slack.max(l.max_slack);
            c.failures += u64::from(l.failed);
            c.policy_fallbacks += u64::from(l.policy_fallback);
            c.stale_states += u64::from(u.stale_ticks > 0);
            c.unconfirmed_commands += u.link.unconfirmed_commands();
            c.crazyflies += u64::from(*entry.link != *links::SIM_LINK);
            c.with_error += u64::from(entry.link_error.is_some());
            if let Some(f) = &entry.firmware {
                c.locked += u64::from(f.locked);
                c.tumbled_or_crashed += u64::from(f.tumbled || f.crashed);
                c.min_battery_v = min_opt(c.min_battery_v, f.battery_v);
                c.min_link_quality = min_opt(c.min_link_quality, f.link_quality);
            }
        }
        c
    }

    /// These counts and `other`'s together.
    fn merge(self, other: &Self) -> Self {
        Self {
            stall_s: self.stall_s + other.stall_s,
            stalled_uavs: self.stalled_uavs + other.stalled_uavs,
            longest_stall_s: self.longest_stall_s.max(other.longest_stall_s),
            solves: self.solves + other.solves,
            slack_used: self.slack_used + other.slack_used,
            max_slack: self.max_slack.max(other.max_slack),
            failures: self.failures + other.failures,
            policy_fallbacks: self.policy_fallbacks + other.policy_fallbacks,
            stale_states: self.stale_states + other.stale_states,
            unconfirmed_commands: self.unconfirmed_commands + other.unconfirmed_commands,
            crazyflies: self.crazyflies + other.crazyflies,
            with_error: self.with_error + other.with_error,
            locked: self.locked + other.locked,
            tumbled_or_crashed: self.tumbled_or_crashed + other.tumbled_or_crashed,
            min_battery_v: min_opt(self.min_battery_v, other.min_battery_v),
            min_link_quality: min_opt(self.min_link_quality, other.min_link_quality),
        }
    }
}
