//! The messages a region reads between ticks ([`Handover::receive`]): offers answered after the
//! checks of [`super::checks`], accepts that release a UAV, refusals, and releases that adopt one.

use super::{
    FleetChange, Handover, MAX_MESSAGES_PER_GAP, MAX_OFFERS_PER_SENDER_PER_GAP, Message, RETRY_AFTER,
    Reservation,
};
use crate::screen::PeerRefusals;
use fleet::Fleet;
use links::LinkRules;
use std::collections::HashMap;
use std::time::Instant;

impl Handover {
    /// Reads up to [`MAX_MESSAGES_PER_GAP`] messages: answers offers (checked against `fleet`, which
    /// may hold at most `max_uavs`, and the links this server may open, `rules`), and returns what
    /// the loop must do to the fleet now.
    /// `commanded_elsewhere` gives, per UAV id the other regions command, the region (asked at
    /// most once, at the first offer).
    pub fn receive(
        &mut self,
        fleet: &Fleet,
        max_uavs: usize,
        rules: &LinkRules,
        now: Instant,
        commanded_elsewhere: &dyn Fn() -> HashMap<String, String>,
    ) -> Vec<FleetChange> {
        let mut changes = Vec::new();
        let mut listed: Option<HashMap<String, String>> = None;
        let mut offers_from: HashMap<String, usize> = HashMap::new();
        for _ in 0..MAX_MESSAGES_PER_GAP {
            let Ok(message) = self.inbox.try_recv() else { break };
            if message.to() != self.own || message.from() == self.own {
                self.counts.dropped += 1;
                continue;
            }
            match message {
                Message::Offer { from, id, seq, uav, .. } => {
                    let read = offers_from.entry(from.clone()).or_default();
                    *read += 1;
                    if *read > MAX_OFFERS_PER_SENDER_PER_GAP {
                        PeerRefusals::count(&self.screen.refused.too_many_offers);
                        self.counts.dropped += 1;
                        continue;
                    }
                    let checked = self.check_offer(fleet, max_uavs, rules, &from, &id, &uav).and_then(|()| {
                        let listed = listed.get_or_insert_with(commanded_elsewhere);
                        match listed.get(&id) {
                            Some(region) if *region != from => {
                                PeerRefusals::count(&self.screen.refused.unsafe_uav);
                                Err(format!("UAV `{id}` is flown by region `{region}`"))
                            }
                            _ => Ok(()),
                        }
                    });
                    let answer = match checked {
                        Ok(()) => {
                            let reservation = Reservation { from: from.clone(), seq, accepted: now };
                            self.reservations.insert(id.clone(), reservation);
                            Message::Accept { from: self.own.clone(), to: from, id, seq }
                        }
                        Err(reason) => {
                            self.counts.refused += 1;
                            Message::Refuse { from: self.own.clone(), to: from, id, seq, reason }
                        }
                    };
                    self.send(answer);
                }
                Message::Accept { from, id, seq, .. } => {
                    let answered = self.offers.get(&id).is_some_and(|o| o.to == from && o.seq == seq);
                    // Released only with room to send the release (only this thread sends, so the
                    // room is still there when it is sent); otherwise the offer times out.
                    if answered && self.outbox.capacity() > 0 && fleet.uav(&id).is_some() {
                        self.offers.remove(&id);
                        changes.push(FleetChange::Release { id, to: from, seq });
                    }
                }
                Message::Refuse { from, id, seq, .. } => {
                    if self.offers.get(&id).is_some_and(|o| o.to == from && o.seq == seq) {
                        self.offers.remove(&id);
                        self.retry_at.insert(id, now + RETRY_AFTER);
                    }
                }
                Message::Release { from, id, seq, uav, .. } => {
                    // Only the release of an offer this region accepted, from its sender, for that
                    // id (the reservation outlives the offer, so an honest release finds it); its
                    // safety here was checked with the offer.
                    let answers = self.reservations.get(&id).is_some_and(|r| r.from == from && r.seq == seq);
                    if !answers {
                        PeerRefusals::count(&self.screen.refused.unrequested_release);
                        self.counts.dropped += 1;
                        continue;
                    }
                    self.reservations.remove(&id);
                    if fleet.uav(&id).is_none() && uav.state().is_finite() {
                        changes.push(FleetChange::Adopt { id, uav });
                    } else {
                        PeerRefusals::count(&self.screen.refused.unsafe_uav);
                        self.counts.dropped += 1;
                    }
                }
            }
        }
        changes
    }
}
