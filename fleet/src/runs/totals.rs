//! What the UAVs add to a run's metrics tick by tick ([`Totals`]): the smallest margins, the
//! counts, the stall time and the solve-time histogram. A large fleet adds them per chunk of
//! [`CHUNK_UAVS`] consecutive UAVs on all cores, each chunk into its own totals, merged in chunk
//! order: the same figures on any number of threads.

use crate::member::Uav;
use crate::progress::stall_time_added;
use crate::runs::histogram::DurationHistogram;
use crate::runs::margins::UavMargins;

/// UAVs per chunk of a large fleet (fixed, so the chunks and the order of their sums do not depend
/// on the number of threads).
pub(crate) const CHUNK_UAVS: usize = 4_096;

/// One stall of one UAV, by the UAV's index (the id is looked up when the stalls are read: no
/// string copied per stall).
#[derive(Debug, Clone, Copy)]
pub(crate) struct StallRecord {
    /// The UAV's index in the fleet.
    pub uav: usize,
    /// When its last progress was (s of the run).
    pub start_s: f64,
    /// How long it lasted (s).
    pub duration_s: f64,
    /// Where the UAV was when it was detected.
    pub at: [f64; 2],
}

/// Accumulated metrics of UAVs over ticks (a run's, or one chunk's in one tick).
#[derive(Debug)]
pub(crate) struct Totals {
    /// Smallest S_kd over the neighbour pairs (None before any pair).
    pub min_collision: Option<f64>,
    /// Smallest distance between two neighbours (None before any pair).
    pub min_separation: Option<f64>,
    /// Smallest S_kij to the finite walls.
    pub min_road: f64,
    /// Smallest distance of a UAV to a wall.
    pub min_wall: f64,
    /// UAV-ticks outside the road.
    pub outside: u64,
    /// QPs solved.
    pub solves: u64,
    /// Solves with a slack above 1e-6.
    pub slack_used: u64,
    /// Largest slack.
    pub max_slack: f64,
    /// Solves that failed.
    pub failures: u64,
    /// Policy outputs replaced by braking.
    pub policy_fallbacks: u64,
    /// Filter time per solve (µs).
    pub solve_us: DurationHistogram,
    /// UAV-seconds stalled.
    pub stall_s: f64,
    /// The longest single stall (s).
    pub max_stall_s: f64,
    /// The longest wait at the head of a line (s).
    pub max_wait_s: f64,
    /// Stalls that ended, in the order they ended (UAV order within a tick).
    pub ended: Vec<StallRecord>,
}

impl Default for Totals {
    fn default() -> Self {
        Self {
            min_collision: None,
            min_separation: None,
            min_road: f64::INFINITY,
            min_wall: f64::INFINITY,
            outside: 0,
            solves: 0,
            slack_used: 0,
            max_slack: 0.0,
            failures: 0,
            policy_fallbacks: 0,
            solve_us: DurationHistogram::default(),
            stall_s: 0.0,
            max_stall_s: 0.0,
            max_wait_s: 0.0,
            ended: Vec::new(),
        }
    }
}

fn min_opt(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

impl Totals {
    /// Back to no observation, keeping the memory of the histogram and the ended stalls.
    pub fn clear(&mut self) {
        // Field by field (a `Default` would allocate a histogram only to drop it, once per chunk and
        // tick), destructured so that a new field cannot be forgotten.
        let Self {
            min_collision,
            min_separation,
            min_road,
            min_wall,
            outside,
            solves,
            slack_used,
            max_slack,
            failures,
            policy_fallbacks,
            solve_us,
            stall_s,
            max_stall_s,
            max_wait_s,
            ended,
        } = self;
        solve_us.clear();
        ended.clear();
        (*min_collision, *min_separation) = (None, None);
        (*min_road, *min_wall) = (f64::INFINITY, f64::INFINITY);
        (*outside, *solves, *slack_used, *failures, *policy_fallbacks) = (0, 0, 0, 0, 0);
        (*max_slack, *stall_s, *max_stall_s, *max_wait_s) = (0.0, 0.0, 0.0, 0.0);
    }

    /// Adds UAV k (`u`, its margins `m`) at time `t` of ticks `dt` long: its stall going on
    /// (`ongoing`) and its first arrival (`arrival`) are updated.
    pub fn add(
        &mut self,
        (k, u, m): (usize, &Uav, UavMargins),
        (t, dt): (f64, f64),
        ongoing: &mut Option<StallRecord>,
        arrival: &mut Option<f64>,
    ) {
        self.min_wall = self.min_wall.min(m.wall);
        self.outside += u64::from(m.wall < 0.0);
        self.min_road = self.min_road.min(m.road_margin);
        if let Some((collision, separation)) = m.closest {
            self.min_collision = min_opt(self.min_collision, Some(collision));
            self.min_separation = min_opt(self.min_separation, Some(separation));
        }
        let last = &u.last;
        self.stall_s += stall_time_added(last.stall_s, dt);
        self.max_stall_s = self.max_stall_s.max(last.stall_s);
        if let Some(since) = u.traffic.front_since {
            self.max_wait_s = self.max_wait_s.max(t - since);
        }
        match (&mut *ongoing, last.stall_s > 0.0) {
            (Some(stall), true) => stall.duration_s = last.stall_s,
            (slot @ None, true) => {
                let at = [u.state.p.x, u.state.p.y];
                *slot = Some(StallRecord { uav: k, start_s: t - last.stall_s, duration_s: last.stall_s, at });
            }
            (slot @ Some(_), false) => self.ended.extend(slot.take()),
            (None, false) => {}
        }
        if last.solved {
            self.solves += 1;
            self.solve_us.record(last.solve_us);
        }
        self.slack_used += u64::from(last.max_slack > 1e-6);
        self.max_slack = self.max_slack.max(last.max_slack);
        self.failures += u64::from(last.failed);
        self.policy_fallbacks += u64::from(last.policy_fallback);
        if u.nav.arrived && arrival.is_none() {
            *arrival = Some(t);
        }
    }

    /// Adds what `other` accumulated (its ended stalls after these).
    pub fn merge(&mut self, other: &Totals) {
        self.min_collision = min_opt(self.min_collision, other.min_collision);
        self.min_separation = min_opt(self.min_separation, other.min_separation);
        self.min_road = self.min_road.min(other.min_road);
        self.min_wall = self.min_wall.min(other.min_wall);
        self.outside += other.outside;
        self.solves += other.solves;
        self.slack_used += other.slack_used;
        self.max_slack = self.max_slack.max(other.max_slack);
        self.failures += other.failures;
        self.policy_fallbacks += other.policy_fallbacks;
        self.solve_us.merge(&other.solve_us);
        self.stall_s += other.stall_s;
        self.max_stall_s = self.max_stall_s.max(other.max_stall_s);
        self.max_wait_s = self.max_wait_s.max(other.max_wait_s);
        self.ended.extend_from_slice(&other.ended);
    }
}
