//! Reservations of conflict zones. A zone is a part of the road that UAVs from different entries may
//! not use at the same time: today a single-file section (entries: its two ends), later a junction
//! or a merge (entries: its arms). The ground station sees every UAV, so it admits UAVs from one
//! entry at a time: the zone opens to the entry whose first UAV has waited longest, admits from it
//! until another entry has waited [`MAX_WAIT_S`] during this phase or [`MAX_BATCH`] went in while
//! others wait, and
//! once everyone admitted has left, opens to the longest waiting of the other entries (round robin:
//! with equal waits, the entry that just had its phase would otherwise win every tie, and a side
//! whose UAVs waited as long as a crowd on the other side never got in), or to the same entry when
//! nobody else waits. Invariants: UAVs from two entries never hold grants of one zone at once, and
//! a waiting UAV is admitted after at most one batch from each other entry (no starvation), given
//! that admitted UAVs leave. Admitted UAVs go in one after another: the next is admitted once the
//! previous one is clear of the entry.

/// Most UAVs admitted from one entry in a row while another entry has UAVs waiting (a crossing of
/// a long section costs up to 30 s; batches of 6 and waits of 20 s alternated so often that groups
/// of 30 each way could not swap ends in time: `headon` 278 -> 283 of 300 with `pd`, BENCHMARKS.md).
pub const MAX_BATCH: u32 = 20;

/// Longest wait (s) at one entry, counted from the start of the current phase, before the zone
/// stops admitting from the others.
pub const MAX_WAIT_S: f64 = 60.0;

/// Longest time (s) a fleet leaves a free zone to another region's UAVs waiting at another entry
/// when none of them comes in (a UAV hovering at a hold point may be parked there, not waiting).
pub const FOREIGN_TURN_WAIT_S: f64 = 5.0;

/// The state of one zone.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Zone {
    /// The entry admitted in the current phase, while the zone is in use.
    open: Option<usize>,
    /// UAVs admitted in the current phase.
    admitted: u32,
    /// No more admissions in this phase: another entry has waited long enough.
    closed: bool,
    /// Grants held now (UAVs inside or on their way in), counted each tick.
    held: u32,
    /// The entry grants are held for (all holders share it).
    held_entry: Option<usize>,
    /// Holders not yet clear of their entry (the next UAV waits for them).
    entering: u32,
    /// The entry of the last phase that ended: the next phase prefers the others.
    last_open: Option<usize>,
    /// When the current phase opened (s).
    opened_at: f64,
    /// Entries (bit `1 << entry`) from which UAVs of another region are inside or on their way in
    /// this tick ([`crate::traffic::foreign`]), reported after [`Reservations::begin`].
    foreign: u32,
    /// Entries (bit `1 << entry`) at which UAVs of another region wait or come to wait this tick.
    foreign_waiting: u32,
    /// Since when (s) this fleet leaves the free zone to another region's waiting UAVs.
    yielding_since: Option<f64>,
}

/// A UAV that asks to enter a zone from one of its entries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Request {
    /// Index of the zone.
    pub zone: usize,
    /// Its entry.
    pub entry: usize,
    /// When it started waiting (s): another entry's oldest wait closes the open entry.
    pub since: f64,
    /// Its place in the queue of its entry, lower first (the caller's order: how far along it is).
    pub order: f64,
    /// Tie break, lower first (the UAV's index in id order, for determinism).
    pub rank: usize,
    /// Who asks (the caller's index).
    pub who: usize,
    /// It is already past the place where it should have waited (pushed, or too fast to stop):
    /// admitted at once if its entry is open (or the zone free), since sending it back would put it
    /// in the way of those admitted behind it; the caller lines such UAVs up (they follow each other).
    pub past_hold: bool,
    /// It is already inside the zone: it cannot wait there, so it is admitted at once if its entry
    /// is open (or the zone free).
    pub inside: bool,
}

/// The reservations of every zone.
#[derive(Debug, Clone, Default)]
pub struct Reservations {
    zones: Vec<Zone>,
}

impl Reservations {
    /// Reservations of `zones` zones, all free.
    pub fn new(zones: usize) -> Self {
        Self { zones: vec![Zone::default(); zones] }
    }

    /// The entry `zone` admits from now, if it is in use.
    pub fn open(&self, zone: usize) -> Option<usize> {
        self.zones[zone].open
    }

    /// Number of zones.
    pub fn len(&self) -> usize {
        self.zones.len()
    }

    /// True with no zone.
    pub fn is_empty(&self) -> bool {
        self.zones.is_empty()
    }

    /// Starts a tick: the caller then reports every grant still held with [`Reservations::held`].
    pub fn begin(&mut self) {
        for z in &mut self.zones {
            (z.held, z.held_entry, z.entering, z.foreign, z.foreign_waiting) = (0, None, 0, 0, 0);
        }
    }

    /// UAVs of another region use `zone` from `entry` (0 or 1) this tick: its fleet admitted them,
    /// this one cannot send them back, so it admits only from that entry, and only once its own
    /// UAVs from the other entry are out (from neither while they use it from both).
    pub fn foreign_inside(&mut self, zone: usize, entry: usize) {
        self.zones[zone].foreign |= 1 << entry.min(31);
    }

    /// UAVs of another region wait at `zone`'s `entry` (or come to wait there) this tick: when this
    /// fleet's UAVs wait at another entry of the free zone, the two regions take turns, each
    /// reading the same rule (the entry of the last phase waits, and entry 0 goes first when there
    /// was none), so they do not open it to opposite entries at once.
    pub fn foreign_waiting(&mut self, zone: usize, entry: usize) {
        self.zones[zone].foreign_waiting |= 1 << entry.min(31);
    }

    /// A UAV still holds its grant to `zone` from `entry`: on its way in (`entering`), or inside.
    pub fn held(&mut self, zone: usize, entry: usize, entering: bool) {
        let z = &mut self.zones[zone];
        z.held += 1;
        z.held_entry = Some(entry);
        z.entering += u32::from(entering);
    }

    /// Decides this tick's `requests` at time `now` and calls `grant` with each one admitted.
    /// `requests` is sorted in place (zone, then waiting time, then rank).
    pub fn decide(&mut self, requests: &mut [Request], now: f64, mut grant: impl FnMut(&Request)) {
        requests.sort_by(|a, b| {
            (a.zone, a.since, a.rank)
                .partial_cmp(&(b.zone, b.since, b.rank))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        for z in &mut self.zones {
            if z.held == 0 {
                // Everyone admitted has left: the phase is over.
                z.last_open = z.open.or(z.last_open);
                (z.open, z.admitted, z.closed) = (None, 0, false);
                // Only another region's UAVs inside, from one entry: a phase of theirs.
                if z.foreign.count_ones() == 1 {
                    z.open = Some(z.foreign.trailing_zeros() as usize);
                    z.yielding_since = None;
                }
            } else if z.open.is_none() {
                // Grants held without a phase (a UAV that started inside): their entry is open.
                z.open = z.held_entry;
                z.opened_at = now;
            }
        }
        let mut start = 0;
        while start < requests.len() {
            let zone = requests[start].zone;
            let end = start + requests[start..].iter().take_while(|r| r.zone == zone).count();
            self.decide_zone(&requests[start..end], now, &mut grant);
            start = end;
        }
    }

    fn decide_zone(&mut self, requests: &[Request], now: f64, grant: &mut impl FnMut(&Request)) {
        let z = &mut self.zones[requests[0].zone];
        // A free zone opens to the entry of a UAV already inside it (it cannot wait there; sending
        // it back out to queue cost one in `mixed` seed 68 a flight of 8 m back and 25 s), else to
        // the longest waiting request, from another entry than the last phase's if one waits.
        let again = |r: &Request| Some(r.entry) == z.last_open;
        let first = requests.iter().min_by(|a, b| {
            (!a.inside)
                .cmp(&!b.inside)
                .then(again(a).cmp(&again(b)))
                .then(a.since.total_cmp(&b.since))
                .then(a.rank.cmp(&b.rank))
        });
        // Another region's UAVs wait at another entry of the free zone: take turns with them.
        let waiting = z.foreign_waiting;
        let theirs = move |entry: usize| waiting & !(1u32 << entry.min(31)) != 0;
        if z.open.is_none()
            && let Some(r) = first.filter(|r| !r.inside && theirs(r.entry))
            && !turn_of(r.entry, z.last_open)
            && now - *z.yielding_since.get_or_insert(now) < FOREIGN_TURN_WAIT_S
        {
            return;
        }
        z.yielding_since = None;
        if z.open.is_none() {
            z.opened_at = now;
        }
        // Another region's UAVs inside: a new phase is theirs; a phase from another entry admits no
        // more (its holders leave, then theirs begins).
        let foreign = (z.foreign.count_ones() == 1).then(|| z.foreign.trailing_zeros() as usize);
        let open = *z.open.get_or_insert(foreign.or(first.map(|r| r.entry)).unwrap_or(requests[0].entry));
        if z.foreign != 0 && foreign != Some(open) {
            z.closed = true;
        }
        // The other entries' wait counts from the start of this phase: a wait that began before it
        // (while the phase before ran) would close every later phase after one UAV once both
        // entries had waited MAX_WAIT_S, and the zone would pass one UAV per crossing time (`headon`
        // seed 89 with `rl`: 16 s per UAV, 4 of 36 still waiting at t_max).
        let oldest_other = requests
            .iter()
            .filter(|r| r.entry != open)
            .map(|r| now - r.since.max(z.opened_at))
            .max_by(f64::total_cmp);
        // A phase admits at least one UAV: closing a fresh one would hand the zone to nobody when
        // both sides have waited MAX_WAIT_S (each would close the other's phase at once).
        let others_wait = oldest_other.is_some() || theirs(open);
        if z.admitted > 0
            && (oldest_other.is_some_and(|w| w >= MAX_WAIT_S) || (others_wait && z.admitted >= MAX_BATCH))
        {
            z.closed = true;
        }
        for r in requests.iter().filter(|r| r.entry == open && r.inside) {
            z.admitted += 1;
            z.held += 1;
            grant(r);
        }
        for r in requests.iter().filter(|r| r.entry == open && r.past_hold && !r.inside) {
            z.admitted += 1;
            z.held += 1;
            z.entering += 1;
            grant(r);
        }
        // One at a time: the first UAV waiting at the open entry's hold point, once the previous one
        // is in.
        let queue = requests
            .iter()
            .filter(|r| r.entry == open && !r.inside && !r.past_hold)
            .min_by(|a, b| a.order.total_cmp(&b.order).then(a.rank.cmp(&b.rank)));
        if let Some(r) = queue.filter(|_| !z.closed && z.entering == 0) {
            z.admitted += 1;
            z.held += 1;
            z.entering += 1;
            grant(r);
            if others_wait && z.admitted >= MAX_BATCH {
                z.closed = true;
            }
        }
    }
}

/// True when `entry` may open a free zone that UAVs of another region wait for at another entry:
/// the entry of the last phase (`last_open`, theirs or ours) waits; entry 0 goes first after none.
/// Both regions read the same phases, so they agree.
fn turn_of(entry: usize, last_open: Option<usize>) -> bool {
    last_open.map_or(entry == 0, |last| last != entry)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(entry: usize, since: f64, who: usize) -> Request {
        Request { zone: 0, entry, since, order: since, rank: who, who, past_hold: false, inside: false }
    }

    /// Simulates a zone that each admitted UAV leaves `stay` ticks after its grant.
    fn simulate(arrivals: &[(usize, usize)], stay: usize, ticks: usize) -> (Vec<Option<usize>>, usize) {
        simulate_clearing(arrivals, 1, stay, ticks)
    }

    /// [`simulate`] with admitted UAVs clear of their entry `clear` ticks after their grant.
    fn simulate_clearing(
        arrivals: &[(usize, usize)],
        clear: usize,
        stay: usize,
        ticks: usize,
    ) -> (Vec<Option<usize>>, usize) {
        let mut zone = Reservations::new(1);
        let mut granted_at: Vec<Option<usize>> = vec![None; arrivals.len()];
        let mut max_concurrent_entries = 0;
        for t in 0..ticks {
            zone.begin();
            let mut entries = std::collections::BTreeSet::new();
            for (who, g) in granted_at.iter().enumerate() {
                if let Some(g) = g.filter(|g| t < g + stay) {
                    zone.held(0, arrivals[who].1, t < g + clear);
                    entries.insert(arrivals[who].1);
                }
            }
            max_concurrent_entries = max_concurrent_entries.max(entries.len());
            let mut requests: Vec<Request> = arrivals
                .iter()
                .enumerate()
                .filter(|(who, (arrive, _))| *arrive <= t && granted_at[*who].is_none())
                .map(|(who, (arrive, entry))| request(*entry, *arrive as f64, who))
                .collect();
            zone.decide(&mut requests, t as f64, |r| granted_at[r.who] = Some(t));
        }
        (granted_at, max_concurrent_entries)
    }

    #[test]
    fn a_free_zone_admits_even_when_both_sides_waited_longer_than_the_maximum() {
        // Both sides have waited longer than MAX_WAIT_S when the zone becomes free.
        let arrivals = [(0, 0), (0, 0), (0, 1), (0, 1)];
        let mut zone = Reservations::new(1);
        let mut requests: Vec<Request> =
            arrivals.iter().enumerate().map(|(who, &(_, entry))| request(entry, 0.0, who)).collect();
        let mut granted = Vec::new();
        zone.decide(&mut requests, MAX_WAIT_S + 10.0, |r| granted.push(r.who));
        assert_eq!(granted, vec![0], "the longest waiting (then lowest rank) goes in");
        // And the zone keeps admitting until everyone is through.
        let (granted, entries) = simulate(&[(0, 0), (0, 0), (0, 1), (0, 1)], 3, 200);
        assert_eq!(entries, 1);
        assert!(granted.iter().all(Option::is_some), "{granted:?}");
    }

    #[test]
    fn a_free_zone_opens_to_a_uav_inside_it_before_longer_waits_outside() {
        // Entry 0 has waited since t = 0 and ranks first; a UAV of entry 1 is already inside (it
        // started there) and cannot wait there.
        let mut zone = Reservations::new(1);
        let inside = Request { inside: true, ..request(1, 5.0, 2) };
        let mut requests = vec![request(0, 0.0, 0), request(0, 0.0, 1), inside];
        let mut granted = Vec::new();
        zone.decide(&mut requests, 6.0, |r| granted.push(r.who));
        assert_eq!(granted, vec![2]);
        assert_eq!(zone.open(0), Some(1));
    }

    #[test]
    fn one_direction_at_a_time_in_batches_and_nobody_starves() {
        // 2·MAX_BATCH UAVs keep arriving at entry 0, one per tick; 3 wait at entry 1 from tick 2.
        let n = 2 * MAX_BATCH as usize;
        let mut arrivals: Vec<(usize, usize)> = (0..n).map(|t| (t, 0)).collect();
        arrivals.extend([(2, 1), (2, 1), (3, 1)]);
        let (granted, entries) = simulate(&arrivals, 4, 400);
        assert_eq!(entries, 1, "two entries held grants at once");
        assert!(granted.iter().all(Option::is_some), "{granted:?}");
        // Entry 1 went in after at most one batch from entry 0.
        let first_from_1 = granted[n..].iter().flatten().min().copied().unwrap();
        let before = granted[..n].iter().flatten().filter(|&&g| g < first_from_1).count();
        assert!(before <= MAX_BATCH as usize, "{before} went first");
    }

    #[test]
    fn after_a_phase_the_other_side_goes_first_when_both_waited_as_long() {
        // A crowd at entry 0 and two UAVs at entry 1, all waiting since t = 0; entry 0's UAVs rank
        // first and win every tie of waiting times. Each crossing takes longer than MAX_WAIT_S, so
        // entry 1 has waited that long whenever the zone comes free.
        let n = MAX_BATCH as usize + 10;
        let mut arrivals: Vec<(usize, usize)> = (0..n).map(|_| (0, 0)).collect();
        arrivals.extend([(0, 1), (0, 1)]);
        let stay = MAX_WAIT_S as usize + 10;
        let (granted, entries) = simulate(&arrivals, stay, 4 * stay * MAX_BATCH as usize);
        assert_eq!(entries, 1, "two entries held grants at once");
        let first_from_1 = granted[n..].iter().flatten().min().copied().expect("entry 1 got in");
        let before = granted[..n].iter().flatten().filter(|&&g| g < first_from_1).count();
        assert!(before <= MAX_BATCH as usize, "{before} went first");
        assert!(granted.iter().all(Option::is_some), "{granted:?}");
    }

    #[test]
    fn crowds_that_both_waited_long_still_go_in_batches() {
        // MAX_BATCH UAVs waiting at each entry since t = 0, each clear of its entry 8 ticks after its
        // grant and through after 70 (longer than MAX_WAIT_S): every phase after the first used to
        // close after one UAV (the other side's wait counted from t = 0), one UAV per crossing. Now
        // each phase admits for MAX_WAIT_S of its own: all cross in a few phases.
        let n = MAX_BATCH as usize;
        let arrivals: Vec<(usize, usize)> = (0..2 * n).map(|k| (0, k / n)).collect();
        let (granted, entries) = simulate_clearing(&arrivals, 8, 70, 2000);
        assert_eq!(entries, 1, "two entries held grants at once");
        assert!(granted.iter().all(Option::is_some), "{granted:?}");
        // Phases: runs of grants from one entry in the order of granting.
        let mut order: Vec<(usize, usize)> =
            granted.iter().enumerate().map(|(w, g)| (g.unwrap(), arrivals[w].1)).collect();
        order.sort_unstable();
        let phases = 1 + order.windows(2).filter(|w| w[0].1 != w[1].1).count();
        assert!(phases <= 6, "{phases} phases for {} UAVs: {order:?}", 2 * n);
    }
}
