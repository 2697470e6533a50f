//! The fleet loop's handover step between two ticks (`--region`; the protocol is in `handover`):
//! releases the UAVs another region accepted, adopts the UAVs released to this one, and makes new
//! offers. Only plain data moves here; nothing waits.

use super::handover::{FleetChange, UavRecord};
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
        self.release_detached(&mut handover);
        let rules = self.link_rules.clone();
        let table = self.region.as_ref().map(|r| r.foreign.clone());
        let commanded_elsewhere = || table.as_ref().map(|t| t.commanded_by()).unwrap_or_default();
        for change in handover.receive(&self.fleet, self.max_uavs, &rules, now, &commanded_elsewhere) {
            match change {
                FleetChange::Release { id, to, seq } => {
                    let Ok(uav) = self.fleet.remove(&id) else { continue };
                    handover.ownership.close(&id, wall_now(), "handover");
                    self.release(&mut handover, uav, to, seq);
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

    /// What this region's message adds to the snapshot: how long each silent UAV has not been
    /// heard from (its neighbours' reach disks grow with it, as this fleet's do) and the ghosts.
    pub(crate) fn unheard(&self, now: Instant) -> super::wire::Unheard {
        let dt = self.fleet.config.params.dt;
        let silent = (self.fleet.uavs().iter().enumerate())
            .filter(|(_, u)| u.stale_ticks > 0)
            .map(|(k, u)| (k as u32, super::wire::saturating_ms(f64::from(u.stale_ticks) * dt)))
            .collect();
        let ghosts = self.handover.as_ref().map(|h| h.ghost_records(now)).unwrap_or_default();
        super::wire::Unheard { silent, ghosts }
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
        let added = self.fleet.add(id.to_string(), policy, link, state, goal);
        if uav.airborne {
            // A Crazyflie's new link connects first: meanwhile it is avoided as lost.
            added.mark_airborne();
        }
        log.open(id, wall_now(), came);
        true
    }
}
