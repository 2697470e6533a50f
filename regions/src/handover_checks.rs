//! What a region checks before it takes a UAV another region offers (the messages of other regions
//! are untrusted input; docs/regions.md, Security): each refusal is the reason sent back
//! and is counted by name (`peer_refused`).

use super::{Handover, MAX_RESERVATIONS_PER_SENDER, UavRecord};
use crate::screen::PeerRefusals;
use fleet::Fleet;
use links::LinkRules;
use roads::Airspace;

impl Handover {
    /// Why this region cannot take UAV `id` offered by `from` (Err: the reason sent back).
    pub(super) fn check_offer(
        &self,
        fleet: &Fleet,
        max_uavs: usize,
        rules: &LinkRules,
        from: &str,
        id: &str,
        uav: &UavRecord,
    ) -> Result<(), String> {
        let refused = |counter: &std::sync::atomic::AtomicU64, why: String| {
            PeerRefusals::count(counter);
            Err(why)
        };
        if let Err(e) = uav::check_uav_id(id) {
            return refused(&self.screen.refused.bad_id, format!("id: {e}"));
        }
        if fleet.uav(id).is_some() {
            return refused(&self.screen.refused.unsafe_uav, format!("a UAV `{id}` is flown here already"));
        }
        if self.reservations.get(id).is_some_and(|r| r.from != from) {
            return Err(format!("UAV `{id}` is being handed over from another region"));
        }
        let waiting = self.reservations.values().filter(|r| r.from == from).count();
        if waiting >= MAX_RESERVATIONS_PER_SENDER && !self.reservations.contains_key(id) {
            let why = format!("region `{from}` has {waiting} offers accepted here and not released");
            return refused(&self.screen.refused.too_many_offers, why);
        }
        // Safe here: inside the road, in or next to this region, at least D_c (braking margin)
        // from every UAV flown here.
        let state = uav.state();
        if let Err(e) = fleet.check_start(&state, "state") {
            return refused(&self.screen.refused.unsafe_uav, format!("unsafe here: {e}"));
        }
        // In this region or next to it: on a road the segment past either end (the tracker's
        // hysteresis), on a network a cell a passage joins to one of its cells.
        let space = fleet.airspace();
        let cell = match space {
            Airspace::Road(road) => Some(road.locate(&state.p, None)),
            Airspace::Network(net) => net.locate(&state.p),
        };
        if !cell.is_some_and(|c| space.in_or_next_to_region(c, &self.own)) {
            let why = format!("[{}, {}] is not in or next to region `{}`", state.p.x, state.p.y, self.own);
            return refused(&self.screen.refused.far_from_region, why);
        }
        if !fleet.policy_names().any(|n| n == uav.policy) {
            return Err(format!("policy `{}` is not loaded here", uav.policy));
        }
        if let Some(Err(e)) = uav.link.as_deref().map(|l| links::check_link_with(l, rules)) {
            return Err(format!("link: {e}"));
        }
        if fleet.uavs().len() + self.reservations.len() >= max_uavs {
            return Err(format!("this region flies its maximum of {max_uavs} UAVs"));
        }
        Ok(())
    }
}
