//! The fleet loop's failover step between two ticks (`failover` has the rules): a standby holds
//! the releases sent to its region and commands nothing; a takeover adopts the mirror's UAVs; an
//! owner that gives way stops commanding its fleet and keeps its records. Only plain data moves here; nothing waits.

use super::loop_hook::RegionLoop;
use super::ownership::wall_now;
use engine::hook::LoopEdits;
use std::collections::HashSet;
use std::time::Instant;

impl RegionLoop {
    /// One failover step; true while this server is a standby (the handover step then stops).
    pub(super) fn fail_over(&mut self, edits: &mut dyn LoopEdits, now: Instant) -> bool {
        let failover = self.shared.failover.clone();
        if failover.take_give_way() {
            self.give_way(edits);
        }
        if !failover.is_owner() {
            self.handover.hold_releases(now);
            return true;
        }
        if failover.take_takeover() {
            self.take_over(edits, &failover, now);
        }
        false
    }

    /// Another owner is ahead: this server stops commanding every UAV at once and closes their
    /// links without landing them (the new owner flies them on); it keeps their records.
    fn give_way(&mut self, edits: &mut dyn LoopEdits) {
        let at = wall_now();
        let mut records = Vec::new();
        for mut uav in edits.release_all() {
            uav.link.detach();
            self.handover.ownership.close(&uav.id, at, "gave_way");
            records.push((uav.id.clone(), super::handover::record(&uav)));
        }
        tracing::warn!("gave way: {} UAVs' records kept for a later takeover", records.len());
        self.shared.failover.keep_given_away(records, Instant::now());
        self.handover.forget_all();
    }

    /// Adopts the mirror's UAVs and the releases held, except those a neighbour now lists or that
    /// this region was seen releasing (they are the neighbour's), and those already flown here.
    fn take_over(&mut self, edits: &mut dyn LoopEdits, failover: &super::Failover, now: Instant) {
        let mut records: Vec<(String, super::handover::UavRecord)> = failover
            .mirror()
            .map(|(mirror, _)| mirror.uavs.iter().map(|u| (u.id.clone(), u.uav.clone())).collect())
            .unwrap_or_default();
        // What this server gave way with, when no owner since left a mirror of it (a mirror's
        // records come first, so an id in both is taken from the mirror).
        records.extend(failover.take_given_away());
        // Releases a neighbour sent while this server was a standby answer offers only the dead
        // owner saw: each must be safe here, like an offer (a neighbour's message is untrusted).
        let held = self.handover.take_held();
        for (id, uav) in held {
            match edits.fleet().check_start(&uav.state(), "state") {
                Ok(()) => records.push((id, uav)),
                Err(e) => {
                    tracing::warn!("takeover: the release of `{id}` held as a standby is not safe here: {e}");
                    super::screen::PeerRefusals::count(&self.shared.screen.refused.unsafe_uav);
                }
            }
        }
        // The neighbours' ghosts are not theirs: a ghost is a UAV released (here, maybe).
        let listed = self.shared.foreign.commanded_ids();
        let mut flown: HashSet<String> = edits.fleet().uavs().iter().map(|u| u.id.clone()).collect();
        let (mut adopted, mut skipped) = (0usize, 0usize);
        for (id, uav) in records {
            let theirs = listed.contains(&id) || failover.released_away(&id, now);
            let valid = uav::check_uav_id(&id).is_ok() && uav.state().is_finite();
            if theirs || flown.contains(&id) || !valid || flown.len() >= edits.max_uavs() {
                skipped += 1;
                continue;
            }
            if Self::adopt(edits, &id, uav, "failover", &self.handover.ownership) {
                flown.insert(id);
                adopted += 1;
            }
        }
        tracing::warn!("took over: {adopted} UAVs adopted, {skipped} left (a neighbour's, or already here)");
    }
}
