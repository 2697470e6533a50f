//! The region's side of the fleet loop ([`RegionLoop`], the loop's [`LoopHook`]; the protocols are
//! in `handover` and `failover`): between two ticks it releases the UAVs another region accepted,
//! adopts the UAVs released to this one and makes new offers; before a tick it gives the fleet the
//! neighbours' UAVs; after one it hands the snapshot to the publishing task. Only plain data moves
//! here; nothing waits.

use super::handover::{FleetChange, UavRecord};
use super::ownership::wall_now;
use super::{Handover, RegionShared};
use engine::command::{ChangeError, Command};
use engine::fleet_loop::next_wall_boundary;
use engine::hook::{Arrival, LoopEdits, LoopHook, Ownership};
use engine::snapshot::Snapshot;
use fleet::{Fleet, ForeignUav};
use roads::Airspace;
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant};
use uav::Vec2;

/// What a region server adds to its fleet loop.
pub struct RegionLoop {
    /// What the loop shares with the Zenoh side and the HTTP handlers.
    pub(super) shared: RegionShared,
    /// The loop's side of the handover protocol.
    pub(super) handover: Handover,
    /// Crazyflies released to another region whose links are closing (`detach`).
    pub(super) detaching: Vec<super::detach::Detaching>,
    /// This loop flies its region (false while a standby, and until a takeover's UAVs are in).
    owns_region: bool,
    /// The foreign UAVs of the next tick (buffer reused).
    foreign: Vec<ForeignUav>,
    /// Which links this server may open (`--allow-link-host`): an offer whose link is not one is refused.
    link_rules: Arc<links::LinkRules>,
}

impl RegionLoop {
    /// The loop's side of region `shared`; None when its handover protocol was taken already (one
    /// loop per region side).
    pub fn new(shared: RegionShared, link_rules: Arc<links::LinkRules>) -> Option<Self> {
        let handover = shared.take_handover()?;
        Some(Self {
            shared,
            handover,
            detaching: Vec::new(),
            owns_region: false,
            foreign: Vec::new(),
            link_rules,
        })
    }

    /// Adds UAV `id` from its record (a handover or a takeover; `came` says which) through the
    /// loop's edit path, and opens its ownership; false when it was not adopted.
    pub(crate) fn adopt(
        edits: &mut dyn LoopEdits,
        id: &str,
        uav: UavRecord,
        came: &'static str,
        log: &super::OwnershipLog,
    ) -> bool {
        let arrival = Arrival {
            id: id.to_string(),
            state: uav.state(),
            goal: uav.goal.map(|g| Vec2::new(g[0], g[1])),
            policy: uav.policy,
            link: uav.link,
            airborne: uav.airborne,
        };
        let adopted = edits.adopt(arrival);
        if adopted {
            log.open(id, wall_now(), came);
        }
        adopted
    }

    /// What this region's message adds to the snapshot: how long each silent UAV has not been
    /// heard from (its neighbours' reach disks grow with it, as this fleet's do) and the ghosts.
    fn unheard(&self, fleet: &Fleet, now: Instant) -> super::wire::Unheard {
        let dt = fleet.config.params.dt;
        let silent = (fleet.uavs().iter().enumerate())
            .filter(|(_, u)| u.stale_ticks > 0)
            .map(|(k, u)| (k as u32, super::wire::saturating_ms(f64::from(u.stale_ticks) * dt)))
            .collect();
        let ghosts = self.handover.ghost_records(now);
        super::wire::Unheard { silent, ghosts }
    }
}

impl LoopHook for RegionLoop {
    fn between_ticks(&mut self, edits: &mut dyn LoopEdits) {
        let now = Instant::now();
        let standby = self.fail_over(edits, now);
        self.owns_region = !standby;
        if standby {
            // Nothing to offer or answer.
            return;
        }
        self.handover.expire(now);
        self.release_detached();
        let table = self.shared.foreign.clone();
        let commanded_elsewhere = || table.commanded_by();
        let changes = self.handover.receive(
            edits.fleet(),
            edits.max_uavs(),
            &self.link_rules,
            now,
            &commanded_elsewhere,
        );
        for change in changes {
            match change {
                FleetChange::Release { id, to, seq } => {
                    let Some(uav) = edits.release(&id) else { continue };
                    self.handover.ownership.close(&id, wall_now(), "handover");
                    self.release(uav, to, seq);
                }
                FleetChange::Adopt { id, uav } => {
                    if Self::adopt(edits, &id, uav, "handover", &self.handover.ownership) {
                        self.handover.adopted(&id, now);
                    }
                }
            }
        }
        self.handover.offer(edits.fleet(), edits.road_version(), now);
        *self.shared.handover_counts.lock().unwrap_or_else(PoisonError::into_inner) = self.handover.counts;
    }

    fn before_tick(&mut self, fleet: &mut Fleet) {
        // A copy under a short lock: the loop never waits on Zenoh.
        let now = Instant::now();
        self.shared.foreign.copy_into(now, &mut self.foreign);
        self.handover.adjust_foreign(&mut self.foreign, now);
        fleet.set_foreign(&self.foreign);
        self.shared.foreign_ages.record(&self.foreign);
    }

    fn after_tick(&mut self, snapshot: &Arc<Snapshot>, fleet: &Fleet, read_at: Instant) {
        let published = super::Published {
            snapshot: snapshot.clone(),
            read_at,
            owned: self.owns_region,
            unheard: self.unheard(fleet, Instant::now()),
            leaving: self.leaving(),
        };
        self.shared.published.send_replace(Some(published));
    }

    fn road_changed(&mut self, road: &Airspace) {
        // The other regions' messages are checked against the road flown.
        self.shared.screen.set_road(road);
    }

    fn admits(&self, command: &Command) -> Result<(), ChangeError> {
        // A standby takes only its owner's road (it flies nothing, so any road is safe for it).
        let follows = matches!(command, Command::FollowRoad(_));
        if self.shared.failover.is_owner() || follows {
            Ok(())
        } else {
            Err(ChangeError::Standby(self.shared.name.clone()))
        }
    }

    fn ownership(&self, change: Ownership<'_>) {
        let (log, at) = (&self.shared.ownership, wall_now());
        match change {
            Ownership::Opened { id, how } => log.open(id, at, how),
            Ownership::Closed { id, how } => log.close(id, at, how),
            Ownership::ClosedAll => log.close_all(at, "removed"),
        }
    }

    fn next_tick(&self, _next: Instant, period: Duration) -> Instant {
        // Regions tick on the wall clock's multiples of dt, so that a change deployed to every
        // region for one instant is applied at the same tick boundary everywhere.
        next_wall_boundary(period)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::UavRecord;
    use engine::hook::NoHook;

    /// The loop's edits, played by the test: it adopts when told to.
    struct Edits {
        fleet: Fleet,
        accept: bool,
        adopted: Vec<Arrival>,
    }

    impl LoopEdits for Edits {
        fn fleet(&self) -> &Fleet {
            &self.fleet
        }
        fn max_uavs(&self) -> usize {
            100
        }
        fn road_version(&self) -> u64 {
            0
        }
        fn adopt(&mut self, arrival: Arrival) -> bool {
            self.adopted.push(arrival);
            self.accept
        }
        fn release(&mut self, _: &str) -> Option<fleet::Uav> {
            None
        }
        fn release_all(&mut self) -> Vec<fleet::Uav> {
            Vec::new()
        }
    }

    fn edits(accept: bool) -> Edits {
        let scenario = engine::demo_scenario().unwrap();
        let policies = policies::PolicyRegistry::with_pd(scenario.params.delta);
        let config = fleet::FleetConfig { params: scenario.params, ..Default::default() };
        Edits { fleet: Fleet::new(config, scenario.road, policies), accept, adopted: Vec::new() }
    }

    #[test]
    fn a_standby_refuses_every_change_but_its_owners_road() {
        // A region's side starts as a standby until its claim makes it the owner.
        let side = RegionLoop::new(RegionShared::new("west"), Arc::default()).unwrap();
        let add = Command::AddUav {
            id: "x".into(),
            position: Vec2::new(13.0, 16.0),
            policy: None,
            goal: None,
            link: None,
        };
        assert_eq!(side.admits(&add), Err(ChangeError::Standby("west".into())));
        let road = edits(true).fleet.airspace().clone();
        let follow = Command::FollowRoad(Box::new(engine::command::NewRoad { road, checked_passage_m: 0.0 }));
        assert_eq!(side.admits(&follow), Ok(()));
        assert_eq!(NoHook.admits(&add), Ok(()), "a single server admits every change");
    }

    #[test]
    fn an_adoption_goes_through_the_loops_edit_path_and_opens_ownership_only_when_taken() {
        let log = super::super::OwnershipLog::default();
        let record = UavRecord {
            p: [13.0, 16.0],
            v: [0.5, 0.0],
            goal: Some([20.0, 16.0]),
            policy: "pd".into(),
            link: Some("udp://10.0.0.5:19850".into()),
            airborne: true,
        };
        let mut refused = edits(false);
        assert!(!RegionLoop::adopt(&mut refused, "far", record.clone(), "failover", &log));
        assert!(log.intervals().0.is_empty(), "nothing opened for a refused UAV");
        let mut taken = edits(true);
        assert!(RegionLoop::adopt(&mut taken, "far", record, "failover", &log));
        assert_eq!(log.intervals().0[0].came, "failover");
        let arrival = &taken.adopted[0];
        assert_eq!((arrival.id.as_str(), arrival.state.v.x, arrival.airborne), ("far", 0.5, true));
        assert_eq!(arrival.link.as_deref(), Some("udp://10.0.0.5:19850"));
    }
}
