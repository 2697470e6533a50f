//! Hot standby of a region (`serve --standby-for NAME`; docs/regions.md, ARCHITECTURE.md
//! "Failover"): who owns a region is told by Zenoh liveliness tokens, and what the standby needs
//! to fly on is the owner's *mirror*, its UAVs' full records after every tick.
//!
//! Tokens, under `PREFIX/region/NAME/`: the owner holds `owner/EPOCH/INCARNATION`, each standby
//! `standby/INCARNATION`. A token disappears when its server closes its session, dies (its TCP
//! connections close) or stops answering for Zenoh's lease. Rules ([`decide`]):
//! - A standby that has seen an owner takes over when no owner token is left and it is the first
//!   of the standbys (by incarnation): it declares `owner/E+1/...`, E the highest epoch it saw,
//!   before its loop adopts the mirror's UAVs.
//! - An owner that sees another owner's token of a higher (epoch, incarnation) gives way: its loop
//!   drops its fleet and it becomes a standby. At most one owner stays, enforced by every owner.
//! - `serve --region NAME` started while an owner's token is alive joins as its standby.
//!
//! The loop never waits on any of this: it reads atomic flags between ticks.

use super::messages::{Message, UavRecord};
use engine::snapshot::Snapshot;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// How long a server started with `--region` listens for a live owner before it claims the region.
pub const CLAIM_SETTLE: Duration = Duration::from_millis(600);
/// A release seen on Zenoh is remembered this long (it keeps the UAV out of a takeover).
pub const RELEASE_MEMORY: Duration = Duration::from_secs(10);

/// One owner token: `owner/EPOCH/INCARNATION`; ordered by epoch, then incarnation.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct OwnerToken {
    /// Raised by one at each takeover.
    pub epoch: u64,
    /// The owning server's incarnation.
    pub incarnation: String,
}

/// A region's live tokens.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tokens {
    /// The owners' tokens (one, but for a moment after a partition or a double start).
    pub owners: BTreeSet<OwnerToken>,
    /// The standbys' incarnations.
    pub standbys: BTreeSet<String>,
    /// The highest epoch ever seen.
    pub max_epoch: u64,
    /// An owner was ever seen (a standby takes over only what it has seen owned).
    pub seen_owner: bool,
}

impl Tokens {
    /// Applies one liveliness sample for the key `suffix` (after `PREFIX/region/NAME/`); false for
    /// a key that is not a token of this scheme.
    pub fn apply(&mut self, suffix: &str, alive: bool) -> bool {
        let parts: Vec<&str> = suffix.split('/').collect();
        match parts.as_slice() {
            ["owner", epoch, incarnation] => {
                let Ok(epoch) = epoch.parse::<u64>() else { return false };
                let token = OwnerToken { epoch, incarnation: (*incarnation).to_string() };
                self.max_epoch = self.max_epoch.max(epoch);
                if alive {
                    self.seen_owner = true;
                    self.owners.insert(token);
                } else {
                    self.owners.remove(&token);
                }
                true
            }
            ["standby", incarnation] => {
                if alive {
                    self.standbys.insert((*incarnation).to_string());
                } else {
                    self.standbys.remove(*incarnation);
                }
                true
            }
            _ => false,
        }
    }
}

/// What a server must do after a change of its region's tokens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decision {
    /// Nothing.
    Stay,
    /// Take the region over as owner with this epoch.
    TakeOver(u64),
    /// Give way to a higher owner: become a standby.
    GiveWay,
}

/// The rules of the module's doc for the server `me`, owner with token `mine` or a standby (None).
pub fn decide(tokens: &Tokens, me: &str, mine: Option<&OwnerToken>) -> Decision {
    match mine {
        Some(mine) if tokens.owners.iter().any(|t| t > mine) => Decision::GiveWay,
        Some(_) => Decision::Stay,
        None => {
            let first_standby = tokens.standbys.iter().next().is_none_or(|s| s.as_str() >= me);
            if tokens.seen_owner && tokens.owners.is_empty() && first_standby {
                Decision::TakeOver(tokens.max_epoch + 1)
            } else {
                Decision::Stay
            }
        }
    }
}

/// A region's UAVs as its owner flew them at one tick (JSON on the key of [`super::tokens::RegionKeys::mirror`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mirror {
    /// The region.
    pub region: String,
    /// The owner's epoch.
    pub epoch: u64,
    /// The owner's tick.
    pub tick: u64,
    /// The owner's road version (its own counter: a standby takes the road when it changes).
    #[serde(default)]
    pub road_version: u64,
    /// Its UAVs.
    pub uavs: Vec<MirrorUav>,
}

/// One UAV of a mirror.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MirrorUav {
    /// Its id.
    pub id: String,
    /// Everything needed to fly it on.
    pub uav: UavRecord,
}

impl Mirror {
    /// The mirror of `snapshot` for `region` at `epoch`, with the UAVs `leaving` (released, their
    /// links still closing: a standby that takes over before their release flies them on).
    pub fn of(region: &str, epoch: u64, snapshot: &Snapshot, leaving: &[MirrorUav]) -> Self {
        let uavs = snapshot
            .uavs
            .iter()
            .map(|u| MirrorUav { id: u.id.to_string(), uav: UavRecord::of_snapshot(u) })
            .chain(leaving.iter().cloned())
            .collect();
        Self { region: region.into(), epoch, tick: snapshot.tick, road_version: snapshot.road_version, uavs }
    }
}

/// What the fleet loop and the Zenoh side share about the region's ownership.
#[derive(Debug)]
pub struct Failover {
    /// This server's incarnation (orders standbys, breaks ties between owners).
    pub incarnation: String,
    owner: AtomicBool,
    epoch: AtomicU64,
    takeover: AtomicBool,
    give_way: AtomicBool,
    takeovers: AtomicU64,
    given_way: AtomicU64,
    mirror: Mutex<Option<(Arc<Mirror>, Instant)>>,
    released_away: Mutex<HashMap<String, Instant>>,
    /// The records of the fleet this server last gave way with, and when.
    given_away: Mutex<Option<(Records, Instant)>>,
}

/// UAV records by id.
pub type Records = Vec<(String, UavRecord)>;

/// A fresh incarnation: the wall clock's nanoseconds and the process id, as 24 hex digits (ordered
/// by start time, distinct between processes).
pub fn new_incarnation() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    format!("{nanos:016x}{:08x}", std::process::id())
}

impl Default for Failover {
    fn default() -> Self {
        Self::new()
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Plain data replaced in single steps: a panic elsewhere cannot leave it half-written.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Failover {
    /// The shared side of a server, a standby until [`super::tokens::claim`] says otherwise.
    pub fn new() -> Self {
        Self {
            incarnation: new_incarnation(),
            owner: AtomicBool::new(false),
            epoch: AtomicU64::new(0),
            takeover: AtomicBool::new(false),
            give_way: AtomicBool::new(false),
            takeovers: AtomicU64::new(0),
            given_way: AtomicU64::new(0),
            mirror: Mutex::new(None),
            released_away: Mutex::new(HashMap::new()),
            given_away: Mutex::new(None),
        }
    }

    /// This server commands the region's UAVs.
    pub fn is_owner(&self) -> bool {
        self.owner.load(SeqCst)
    }

    /// The epoch of this server's ownership (0 before it owned).
    pub fn epoch(&self) -> u64 {
        self.epoch.load(SeqCst)
    }

    /// The Zenoh side made this server the owner at `epoch`: the loop adopts the mirror next gap.
    pub fn became_owner(&self, epoch: u64, take_over: bool) {
        self.epoch.store(epoch, SeqCst);
        self.owner.store(true, SeqCst);
        if take_over {
            self.takeovers.fetch_add(1, SeqCst);
            self.takeover.store(true, SeqCst);
        }
    }

    /// The Zenoh side saw a higher owner: this server stops commanding at once (the publisher
    /// checks [`Failover::is_owner`]) and its loop drops its fleet next gap.
    pub fn became_standby(&self) {
        self.owner.store(false, SeqCst);
        self.given_way.fetch_add(1, SeqCst);
        self.give_way.store(true, SeqCst);
    }

    /// Keeps the records of the fleet this server gave way with: if the owner ahead of it leaves no
    /// mirror (it was never real, or died first), a later takeover flies them on.
    pub fn keep_given_away(&self, records: Records, at: Instant) {
        *lock(&self.given_away) = Some((records, at));
    }

    /// The records given away, unless a mirror came after them (then the mirror is newer); taken
    /// once.
    pub fn take_given_away(&self) -> Records {
        let kept = lock(&self.given_away).take();
        match (kept, self.mirror()) {
            (Some((records, at)), mirror) if mirror.as_ref().is_none_or(|(_, m)| *m < at) => records,
            _ => Vec::new(),
        }
    }

    /// For the loop: adopt the mirror now (once per takeover).
    pub fn take_takeover(&self) -> bool {
        self.takeover.swap(false, SeqCst)
    }

    /// For the loop: drop the fleet now (once per giving way).
    pub fn take_give_way(&self) -> bool {
        self.give_way.swap(false, SeqCst)
    }

    /// Keeps a mirror received from the owner (a newer epoch, or a later tick of the same).
    pub fn keep_mirror(&self, mirror: Mirror, at: Instant) {
        let mut kept = lock(&self.mirror);
        let newer = kept.as_ref().is_none_or(|(m, _)| (mirror.epoch, mirror.tick) > (m.epoch, m.tick));
        if newer {
            *kept = Some((Arc::new(mirror), at));
        }
    }

    /// The last mirror received and when.
    pub fn mirror(&self) -> Option<(Arc<Mirror>, Instant)> {
        lock(&self.mirror).clone()
    }

    /// Notes a handover message seen on a neighbour's key: a release from this region means the
    /// UAV is the neighbour's even if the mirror still lists it.
    pub fn saw_handover(&self, own: &str, message: &Message, at: Instant) {
        if let Message::Release { from, id, .. } = message
            && from == own
        {
            let mut released = lock(&self.released_away);
            released.retain(|_, t| at.saturating_duration_since(*t) < RELEASE_MEMORY);
            released.insert(id.clone(), at);
        }
    }

    /// UAV `id` was released to a neighbour within [`RELEASE_MEMORY`] of `now`.
    pub fn released_away(&self, id: &str, now: Instant) -> bool {
        lock(&self.released_away).get(id).is_some_and(|t| now.saturating_duration_since(*t) < RELEASE_MEMORY)
    }

    /// `GET /api/metrics` `region.failover`.
    pub fn report(&self, now: Instant) -> FailoverReport {
        let mirror = self.mirror();
        FailoverReport {
            role: if self.is_owner() { "owner" } else { "standby" },
            epoch: self.epoch(),
            incarnation: self.incarnation.clone(),
            takeovers: self.takeovers.load(SeqCst),
            given_way: self.given_way.load(SeqCst),
            mirror_uavs: mirror.as_ref().map(|(m, _)| m.uavs.len()),
            mirror_age_s: mirror.as_ref().map(|(_, at)| now.saturating_duration_since(*at).as_secs_f64()),
        }
    }
}

/// `region.failover` of `GET /api/metrics`.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct FailoverReport {
    /// `owner` or `standby`.
    pub role: &'static str,
    /// The owner's epoch this server knows.
    pub epoch: u64,
    /// This server's incarnation.
    pub incarnation: String,
    /// Takeovers made.
    pub takeovers: u64,
    /// Times this server gave way to another owner.
    pub given_way: u64,
    /// UAVs in the owner's last mirror (a standby's).
    pub mirror_uavs: Option<usize>,
    /// How old that mirror is (s).
    pub mirror_age_s: Option<f64>,
}

#[cfg(test)]
#[path = "failover_tests.rs"]
mod tests;
