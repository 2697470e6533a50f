//! The policies stage of a tick ([`TickPipeline`]): each policy evaluated once on its batch of
//! UAVs, then the speed limits and the distance kept to neighbours applied to the nominal inputs.

use super::{TickPipeline, for_each_uav};
use crate::member::{Uav, UavPolicy};
use crate::tick::TickState;
use crate::tick::{map_into, map_mut_into};
use crate::traffic::foreign::ForeignNear;
use crate::traffic::speed::{crowd_limit, govern, keep_distance};
use policies::observation;
use roads::network::Network;
use roads::{Airspace, NavMode};
use uav::{Vec2, braking_input};

impl TickPipeline {
    /// Evaluates each policy once on the batch of UAVs that use it, then sets every UAV's nominal
    /// input. Every pass over the records is per UAV (each reads or writes its own): in parallel
    /// for large fleets, the same on any number of threads.
    pub(super) fn run_policies(&mut self, fleet: &mut TickState<'_>) {
        let (delta, dt) = (fleet.config.params.delta, fleet.config.params.dt);
        // Each flying UAV's policy by its place among the registry's names (the same order as
        // `iter_mut`); one that is not flying, or a paused fleet, runs none. A UAV keeps the place
        // it found while the names are the same (their generation, unique to this list of names).
        let paused = fleet.paused;
        if !fleet.policies.names().eq(self.policy_names.iter().map(String::as_str)) {
            self.policy_names = fleet.policies.names().map(String::from).collect();
            self.names_generation = UavPolicy::next_generation();
        }
        let (names, generation) = (&self.policy_names, self.names_generation);
        let slot_of = |uav: &mut Uav| {
            if paused || !uav.condition.flying() {
                return None;
            }
            uav.policy.place_in(generation, names)
        };
        map_mut_into(fleet.uavs, slot_of, &mut self.slots);
        // What each UAV's policy gave: None when it ran none, Some(None) when it ran and gave no
        // finite action, Some(Some(u)) otherwise.
        self.nominal.clear();
        self.nominal.resize(fleet.uavs.len(), None);
        for (i, (_, policy)) in fleet.policies.iter_mut().enumerate() {
            // Only this policy's UAVs' records are read (the slots are a plain array).
            self.batch.clear();
            self.batch.extend((0..self.slots.len()).filter(|&k| self.slots[k] == Some(i)));
            if self.batch.is_empty() {
                continue;
            }
            let uavs = &*fleet.uavs;
            let observe = |&k: &usize| observation(&uavs[k].state, uavs[k].last.target, Vec2::zeros());
            map_into(&self.batch, observe, &mut self.observations);
            let acted = policy.act(&self.observations, &mut self.actions).is_ok();
            for (n, &k) in self.batch.iter().enumerate() {
                let action = self.actions.get(n).filter(|u| acted && uav::is_finite(u));
                self.nominal[k] = Some(action.copied());
            }
        }
        // Every UAV brakes unless its policy gave a finite action; a fallback is counted only for a
        // UAV whose policy ran and gave none.
        let nominal = &self.nominal;
        for_each_uav(fleet.uavs, |k, uav| {
            let (u_ref, fallback) = match nominal[k] {
                Some(Some(u)) => (uav::saturate(u, delta), false),
                Some(None) => (braking_input(uav.state.v, delta, dt), true),
                None => (braking_input(uav.state.v, delta, dt), false),
            };
            uav.last.u_ref = u_ref;
            uav.last.policy_fallback = fallback;
        });
        if paused {
            return;
        }
        match fleet.road {
            Airspace::Road(_) if fleet.config.nav == NavMode::Traffic => self.limit_speeds(fleet),
            Airspace::Road(_) => {}
            Airspace::Network(net) => self.limit_network_speeds(net, fleet),
        }
    }

    /// On a network: each flying UAV keeps to the speed limit of the road it is on ([`govern`])
    /// and, with `traffic` navigation, the distance to every neighbour ([`keep_distance`]). Per UAV
    /// from plain copies, as [`TickPipeline::limit_speeds`].
    fn limit_network_speeds(&mut self, net: &Network, fleet: &mut TickState<'_>) {
        let params = &fleet.config.params;
        let (d_c, delta, dt) = (params.kept_d_c(), params.delta, params.dt);
        let keep = fleet.config.nav == NavMode::Traffic;
        let (positions, velocities, lists) = (&self.positions, &self.velocities, &self.neighbours.lists);
        let limit = |(k, me): (usize, &mut Uav)| {
            if !me.condition.flying() || me.nav.arrived || me.nav.goal().is_none() {
                return;
            }
            let (p, v) = (me.state.p, me.state.v);
            let mut u = me.last.u_ref;
            if let Some(limit) = me.nav.way().and_then(|w| net.speed_limit(w.cell())) {
                u = govern(v, u, limit, delta, dt);
            }
            for &d in lists[k].iter().filter(|_| keep) {
                u = keep_distance(v, u, positions[d] - p, velocities[d], d_c, delta, dt);
            }
            me.last.u_ref = u;
        };
        for_each_uav(fleet.uavs, |k, uav| limit((k, uav)));
    }

    /// The traffic rules' speed limit (narrower road, slower flight; slower still in dense traffic)
    /// and the distance kept to every neighbour, own or foreign (`fleet::speed`), applied to each
    /// flying UAV's nominal input. Per UAV, reading its neighbours' states from plain copies (a link
    /// is not shared across threads): in parallel for large fleets, the same on any number of threads.
    fn limit_speeds(&mut self, fleet: &mut TickState<'_>) {
        let params = &fleet.config.params;
        let (d_c, delta, dt) = (params.kept_d_c(), params.delta, params.dt);
        let (positions, velocities) = (&self.positions, &self.velocities);
        let (traffic, lists) = (&fleet.traffic, &self.neighbours.lists);
        let foreign = ForeignNear::new(&self.neighbours.foreign, &self.foreign_views.views, fleet.foreign);
        let limit = |(k, me): (usize, &mut Uav)| {
            let Some(pos) = me.nav.position.filter(|_| !me.nav.arrived && me.condition.flying()) else {
                return;
            };
            let (p, v) = (me.state.p, me.state.v);
            let mut limit = traffic.speed_limit(pos.s, pos.direction());
            if me.traffic.in_traffic {
                let foreign_positions = foreign.of(k).map(|f| f.p);
                limit =
                    crowd_limit(limit, p, lists[k].iter().map(|&d| positions[d]).chain(foreign_positions));
            }
            let mut u = govern(v, me.last.u_ref, limit, delta, dt);
            for &d in &lists[k] {
                u = keep_distance(v, u, positions[d] - p, velocities[d], d_c, delta, dt);
            }
            for f in foreign.of(k) {
                u = keep_distance(v, u, f.p - p, f.v, d_c, delta, dt);
            }
            me.last.u_ref = u;
        };
        for_each_uav(fleet.uavs, |k, uav| limit((k, uav)));
    }
}
