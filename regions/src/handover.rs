//! Handover of a UAV between two regions (docs/regions.md, ARCHITECTURE.md
//! "Handover"): when a UAV's tracked segment lies in a neighbouring region, its owner A offers it
//! to that region B with the whole UAV record; B reserves the id and accepts; A, at its next gap
//! between ticks, removes the UAV from its fleet (its last command was the tick before) and releases
//! it with the state its link gives now; B, at its next gap, adds it with that state and commands it
//! from its next tick.
//!
//! Invariants: A commands the UAV until it releases it and never after (the UAV has left A's
//! fleet); B commands it only after the release arrived, so two regions never command one UAV. The
//! UAV is unowned from the release to B's next gap: at most one tick plus the message's transit
//! ([`MAX_UNOWNED_S`]). Meanwhile A keeps the released UAV as a foreign UAV of its own fleet (a
//! *ghost* whose reach disk grows from the release) until B's messages list it, and B leaves out of
//! A's messages any UAV it has just adopted, so no UAV disappears from its neighbours' view or
//! becomes a neighbour of itself.
//!
//! All of this runs on the fleet loop between ticks and never waits: messages come in through a
//! bounded channel the Zenoh subscriber fills and go out through one a task empties.

pub use super::messages::{Message, UavRecord};
use super::ownership::OwnershipLog;
use super::screen::Screen;
use fleet::{Condition, Fleet, ForeignUav};
use roads::Airspace;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};
use uav::UavState;

/// The bound on a UAV's unowned time during a handover (s): one tick and the transit (stated in
/// docs/regions.md and ARCHITECTURE.md; `tests/server_regions.rs` checks it on loopback).
pub const MAX_UNOWNED_S: f64 = 0.25;
/// The bound on a Crazyflie's unowned time in a handover (s): the close of its old link (at most
/// the session's 0.5 s disconnect wait), then one tick and the transit, as for [`MAX_UNOWNED_S`].
pub const MAX_UNOWNED_LINK_S: f64 = 1.0;
/// An offer not answered in this time is dropped (and made again later).
pub const OFFER_TIMEOUT: Duration = Duration::from_secs(1);
/// An accepted offer whose release has not come in this time is forgotten. Longer than
/// [`OFFER_TIMEOUT`] plus a tick, so a release sent for an accept always finds its reservation.
pub const RESERVATION_TIMEOUT: Duration = Duration::from_secs(3);
/// After a refusal, the same UAV is not offered again for this long.
pub const RETRY_AFTER: Duration = Duration::from_secs(1);
/// A ghost (a released UAV the new owner's messages do not list yet) is kept at most this long.
pub const GHOST_TTL: Duration = Duration::from_secs(2);
/// Most handover messages read per gap (the rest wait for the next one).
pub const MAX_MESSAGES_PER_GAP: usize = 256;
/// A release held by a standby (`hold_releases`) is kept this long.
pub const HELD_RELEASE_TTL: Duration = Duration::from_secs(2);
/// Largest handover message accepted (bytes).
pub const MAX_MESSAGE_BYTES: usize = 16 << 10;
/// Offers one region may have accepted here and not released yet; more are refused.
pub const MAX_RESERVATIONS_PER_SENDER: usize = 64;
/// Offers from one region read per gap (each costs a check against the fleet); more are dropped
/// unanswered and made again by their sender.
pub const MAX_OFFERS_PER_SENDER_PER_GAP: usize = 32;

/// An offer made and not answered yet.
#[derive(Debug)]
struct Offer {
    to: String,
    seq: u64,
    sent: Instant,
}

/// An accepted offer waiting for its release.
#[derive(Debug)]
struct Reservation {
    from: String,
    seq: u64,
    accepted: Instant,
}

/// A released UAV that the new owner's messages do not list yet.
#[derive(Debug)]
struct Ghost {
    state: UavState,
    released: Instant,
}

/// What the loop does with the fleet for a handover (applied by the engine, which owns the links).
#[derive(Debug, Clone, PartialEq)]
pub enum FleetChange {
    /// Remove UAV `id` and release it to `to` (offer `seq`).
    Release {
        /// The UAV.
        id: String,
        /// The new owner.
        to: String,
        /// The accepted offer.
        seq: u64,
    },
    /// Add UAV `id` with this record.
    Adopt {
        /// The UAV.
        id: String,
        /// What it is.
        uav: UavRecord,
    },
}

/// Counters for `GET /api/metrics` `region.handover`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct HandoverCounts {
    /// Offers made.
    pub offered: u64,
    /// UAVs released to another region.
    pub released: u64,
    /// UAVs adopted from another region.
    pub adopted: u64,
    /// Offers refused by this region.
    pub refused: u64,
    /// Messages dropped (malformed, not for this region, or the inbox full).
    pub dropped: u64,
}

/// The loop's side of the handover protocol.
#[derive(Debug)]
pub struct Handover {
    own: String,
    inbox: Receiver<Message>,
    outbox: tokio::sync::mpsc::Sender<Message>,
    next_seq: u64,
    offers: HashMap<String, Offer>,
    reservations: HashMap<String, Reservation>,
    retry_at: HashMap<String, Instant>,
    ghosts: HashMap<String, Ghost>,
    /// UAVs adopted lately: their old owner's messages may still list them.
    adopted: HashMap<String, Instant>,
    /// Each segment's (road) or cell's (network) region, when it is a neighbour of this one (by
    /// the road's version).
    segment_owner: Vec<Option<String>>,
    road_version: Option<u64>,
    /// Releases to this region read while it was a standby, with when.
    held: HashMap<String, (UavRecord, Instant)>,
    /// Who owned what when.
    pub ownership: Arc<OwnershipLog>,
    /// What happened so far.
    pub counts: HandoverCounts,
    /// The checks of other regions' messages, whose refusal counts this shares.
    screen: Arc<Screen>,
}

impl Handover {
    /// The protocol for region `own`, reading `inbox` and writing `outbox`.
    pub fn new(
        own: &str,
        inbox: Receiver<Message>,
        outbox: tokio::sync::mpsc::Sender<Message>,
        ownership: Arc<OwnershipLog>,
        screen: Arc<Screen>,
    ) -> Self {
        Self {
            own: own.into(),
            inbox,
            outbox,
            next_seq: 0,
            offers: HashMap::new(),
            reservations: HashMap::new(),
            retry_at: HashMap::new(),
            ghosts: HashMap::new(),
            adopted: HashMap::new(),
            segment_owner: Vec::new(),
            road_version: None,
            held: HashMap::new(),
            ownership,
            counts: HandoverCounts::default(),
            screen,
        }
    }

    /// Queues `message` for the Zenoh task; a full queue drops it (counted): offers and answers are
    /// made again, and a release is only made when the queue has room for it.
    fn send(&mut self, message: Message) {
        if self.outbox.try_send(message).is_err() {
            self.counts.dropped += 1;
        }
    }

    /// A message can be queued now (only the loop sends, so the room stays until it does).
    pub fn can_send(&self) -> bool {
        self.outbox.capacity() > 0
    }

    /// Offers every UAV of `fleet` whose tracked cell lies in a neighbouring region to that region
    /// (one offer at a time per UAV): on a road its tracked segment, on a network the cell it is
    /// in; `road_version` tells when to recompute the cells' regions. Only UAVs flying their
    /// policy on a fresh state are offered (a Crazyflie taking off, landing or lost stays with its
    /// owner until it flies again).
    pub fn offer(&mut self, fleet: &Fleet, road_version: u64, now: Instant) {
        let space = fleet.airspace();
        if self.road_version != Some(road_version) {
            self.road_version = Some(road_version);
            let neighbours = super::neighbours_of(space, &self.own).unwrap_or_default();
            self.segment_owner = (0..space.cell_count())
                .map(|c| {
                    space
                        .region_of(c)
                        .filter(|n| neighbours.iter().any(|m| m.as_str() == *n))
                        .map(String::from)
                })
                .collect();
        }
        for u in fleet.uavs() {
            let cell = match space {
                Airspace::Road(_) => u.nav.tracker.current,
                Airspace::Network(net) => net.locate(&u.state.p),
            };
            let Some(Some(to)) = cell.and_then(|c| self.segment_owner.get(c)) else {
                continue;
            };
            if self.offers.contains_key(&u.id)
                || self.retry_at.get(&u.id).is_some_and(|t| now < *t)
                || u.condition != Condition::Cooperating
                || !u.state.is_finite()
            {
                continue;
            }
            self.next_seq += 1;
            let (to, seq) = (to.clone(), self.next_seq);
            let offer = Message::Offer {
                from: self.own.clone(),
                to: to.clone(),
                id: u.id.clone(),
                seq,
                uav: record(u),
            };
            self.offers.insert(u.id.clone(), Offer { to, seq, sent: now });
            self.counts.offered += 1;
            self.send(offer);
        }
    }

    /// UAV `id` has left the fleet in `state` and its link is closing (a Crazyflie, released once
    /// the link is closed): it is kept as a ghost from now on.
    pub fn detaching(&mut self, id: &str, state: UavState, now: Instant) {
        self.adopted.remove(id);
        self.ghosts.insert(id.to_string(), Ghost { state, released: now });
    }

    /// UAV `id` has left the fleet as `uav` (and its link is closed): releases it to `to` and keeps
    /// it as a ghost (aged from when it left, if it was detaching).
    pub fn released(&mut self, id: String, to: String, seq: u64, uav: UavRecord, now: Instant) {
        self.counts.released += 1;
        self.adopted.remove(&id);
        self.ghosts.entry(id.clone()).or_insert(Ghost { state: uav.state(), released: now });
        self.send(Message::Release { from: self.own.clone(), to, id, seq, uav });
    }

    /// As a standby: reads the inbox, answers nothing, and keeps the releases to this region for
    /// [`HELD_RELEASE_TTL`] (an owner that dies between a release and its adoption leaves them to
    /// the standby that takes over).
    pub fn hold_releases(&mut self, now: Instant) {
        for _ in 0..MAX_MESSAGES_PER_GAP {
            let Ok(message) = self.inbox.try_recv() else { break };
            if let Message::Release { to, id, uav, .. } = message
                && to == self.own
            {
                self.held.insert(id, (uav, now));
            }
        }
        self.held.retain(|_, (_, at)| now.saturating_duration_since(*at) < HELD_RELEASE_TTL);
    }

    /// The releases held as a standby (taken at a takeover).
    pub fn take_held(&mut self) -> Vec<(String, UavRecord)> {
        self.held.drain().map(|(id, (uav, _))| (id, uav)).collect()
    }

    /// Forgets every offer, reservation, ghost and adoption (this server gave way to another owner).
    pub fn forget_all(&mut self) {
        self.offers.clear();
        self.reservations.clear();
        self.retry_at.clear();
        self.ghosts.clear();
        self.adopted.clear();
    }

    /// UAV `id` has joined the fleet from another region.
    pub fn adopted(&mut self, id: &str, now: Instant) {
        self.counts.adopted += 1;
        self.ghosts.remove(id);
        self.adopted.insert(id.to_string(), now);
    }

    /// Forgets what has waited too long: unanswered offers (made again after [`RETRY_AFTER`]),
    /// reservations, ghosts and the adopted list.
    pub fn expire(&mut self, now: Instant) {
        let retry = &mut self.retry_at;
        self.offers.retain(|id, o| {
            let keep = now.saturating_duration_since(o.sent) < OFFER_TIMEOUT;
            if !keep {
                retry.insert(id.clone(), now + RETRY_AFTER);
            }
            keep
        });
        self.retry_at.retain(|_, t| now < *t);
        self.reservations.retain(|_, r| now.saturating_duration_since(r.accepted) < RESERVATION_TIMEOUT);
        self.ghosts.retain(|_, g| now.saturating_duration_since(g.released) < GHOST_TTL);
        self.adopted.retain(|_, t| now.saturating_duration_since(*t) < GHOST_TTL);
    }

    /// The ghosts, for this region's messages: id, last state, ms since they left.
    pub fn ghost_records(&self, now: Instant) -> Vec<(String, UavState, u16)> {
        let ms =
            |g: &Ghost| super::wire::saturating_ms(now.saturating_duration_since(g.released).as_secs_f64());
        self.ghosts.iter().map(|(id, g)| (id.clone(), g.state, ms(g))).collect()
    }

    /// Corrects the foreign UAVs of the next tick: leaves out the UAVs this region has just adopted
    /// (their old owner's last messages may still list them) and adds the ghosts their new owner
    /// does not list yet, aged from their release.
    pub fn adjust_foreign(&mut self, foreign: &mut Vec<ForeignUav>, now: Instant) {
        if !self.adopted.is_empty() {
            foreign.retain(|f| !self.adopted.contains_key(&f.id));
        }
        if !self.ghosts.is_empty() {
            for f in foreign.iter() {
                self.ghosts.remove(&f.id);
            }
            for (id, ghost) in &self.ghosts {
                let age_s = now.saturating_duration_since(ghost.released).as_secs_f64();
                foreign.push(ForeignUav { id: id.clone(), state: ghost.state, age_s });
            }
        }
    }
}

/// The record of a UAV flown here.
pub fn record(u: &fleet::Uav) -> UavRecord {
    let link = u.link.describe();
    UavRecord {
        p: [u.state.p.x, u.state.p.y],
        v: [u.state.v.x, u.state.v.y],
        goal: u.nav.goal().map(|g| [g.x, g.y]),
        policy: u.policy.to_string(),
        link: (link != links::SIM_LINK).then(|| link.to_string()),
        airborne: u.condition.in_the_air(),
    }
}

#[path = "handover_checks.rs"]
mod checks;

#[path = "handover_receive.rs"]
mod receive;

#[cfg(test)]
#[path = "handover_tests.rs"]
mod tests;
