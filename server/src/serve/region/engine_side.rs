//! The fleet loop's handover step between two ticks (`--region`; the protocol is in `handover`):
//! releases the UAVs another region accepted, adopts the UAVs released to this one, and makes new
//! offers. Only plain data moves here; nothing waits.

use super::handover::{FleetChange, UavRecord, record};
use super::ownership::{OwnershipLog, wall_now};
use crate::serve::engine::Engine;
use std::sync::PoisonError;
use std::time::Instant;
use uav::Vec2;

impl Engine {
    /// One handover step (nothing without `--region`).
    pub(crate) fn hand_over(&mut self) {
        let Some(mut handover) = self.handover.take() else { return };
        let now = Instant::now();
        let standby = self.fail_over(&mut handover, now);
        self.owns_region = !standby;
        if standby {
            // Nothing to offer or answer.
            self.handover = Some(handover);
            return;
        }
        handover.expire(now);
        for change in handover.receive(&self.fleet, self.max_uavs, now) {
            match change {
                FleetChange::Release { id, to, seq } => {
                    let Ok(mut uav) = self.fleet.remove(&id) else { continue };
                    // Its last command went out in the last tick: the link's state now is where
                    // the new owner takes it on.
                    let state = uav.link.state().filter(|s| s.is_finite()).unwrap_or(uav.state);
                    uav.state = state;
                    let rec = record(&uav);
                    handover.ownership.close(&id, wall_now(), "handover");
                    handover.released(id, to, seq, rec, now);
                }
                FleetChange::Adopt { id, uav } => {
                    if self.adopt(&id, uav, &handover.ownership, "handover") {
                        handover.adopted(&id, now);
                    }
                }
            }
        }
        handover.offer(&self.fleet, self.road_version, now);
        if let Some(region) = &self.region {
            *region.handover_counts.lock().unwrap_or_else(PoisonError::into_inner) = handover.counts;
        }
        self.handover = Some(handover);
    }

    /// Adds UAV `id` from its record (a handover or a takeover; `came` says which) and opens its
    /// ownership; false when its link is not one this server may open (the same rules as a link
    /// given over REST). The caller makes sure the id is new here.
    pub(crate) fn adopt(&mut self, id: &str, uav: UavRecord, log: &OwnershipLog, came: &'static str) -> bool {
        if let Some(Err(reason)) = uav.link.as_deref().map(|l| links::check_link_with(l, &self.link_rules)) {
            tracing::warn!("UAV `{id}`: link {:?} refused ({reason}); not adopted", uav.link);
            return false;
        }
        let state = uav.state();
        let policy = if self.fleet.policy_names().any(|n| n == uav.policy) {
            uav.policy
        } else {
            self.default_policy.clone()
        };
        let goal =
            uav.goal.map(|g| Vec2::new(g[0], g[1])).filter(|g| self.fleet.check_goal(*g, "goal").is_ok());
        let link = self.links.make(id, uav.link.as_deref(), state, self.fleet.config.params.dt);
        self.fleet.add(id.to_string(), policy, link, state, goal);
        log.open(id, wall_now(), came);
        true
    }
}
