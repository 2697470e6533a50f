//! The rows of every UAV's QP for one tick, built in parallel: its road rows (`safety::road_rows`),
//! a collision row b_kd per cooperating neighbour within the activation radius, and an obstacle row
//! per neighbour that does not cooperate but may be in the air (its reach disk, [`crate::lost`]).
//! Each UAV's rows depend only on the states read this tick, so any number of threads gives the same
//! rows. What depends on the order of filtering (the whole pair row against a neighbour filtered
//! earlier in the tick, given its u_d) is applied afterwards, UAV by UAV ([`RowBuilder::rows_of`]).

use crate::fleet::{CollisionShare, Uav, parallel};
use crate::lost::{ReachDisk, obstacle_row};
use rayon::prelude::*;
use roads::Road;
use safety::barrier::collision_row;
use safety::{RoadRule, Row, RowKind, activation_radius, road_rows};
use uav::{Params, UavState, Vec2};

/// What the rows of other UAVs need to know about one UAV this tick (plain data, shared by threads).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowView {
    /// Its state as read this tick.
    pub state: UavState,
    /// It follows commands and gets rows of its own.
    pub flying: bool,
    /// It shares pair rows with its neighbours ([`Uav::cooperates`]).
    pub cooperates: bool,
    /// Its reach disk when it does not cooperate but may be in the air ([`Uav::in_the_air`]).
    pub obstacle: Option<ReachDisk>,
    /// Its tracked segment (a hint for the road's queries).
    pub segment: usize,
}

/// Per-UAV row buffers, reused from tick to tick.
#[derive(Debug, Default)]
pub(crate) struct RowBuilder {
    views: Vec<RowView>,
    rows: Vec<Vec<Row>>,
}

impl RowBuilder {
    /// Builds every flying UAV's rows (without the sequential share) from `uavs` and their
    /// neighbour lists; `disk_of(d)` is UAV d's reach disk.
    pub fn build(
        &mut self,
        road: &Road,
        rule: RoadRule,
        params: &Params,
        uavs: &[Uav],
        lists: &[Vec<usize>],
        disk_of: impl Fn(usize) -> ReachDisk,
    ) {
        self.views.clear();
        self.views.extend(uavs.iter().enumerate().map(|(d, u)| RowView {
            state: u.state,
            flying: u.flying(),
            cooperates: u.cooperates(),
            obstacle: (!u.cooperates() && u.in_the_air()).then(|| disk_of(d)),
            segment: u.nav.tracker.current.unwrap_or(0),
        }));
        self.rows.resize_with(uavs.len(), Vec::new);
        self.rows.truncate(uavs.len());
        let views = &self.views;
        let build = |(k, rows): (usize, &mut Vec<Row>)| {
            rows.clear();
            let me = views[k];
            if me.flying {
                rows_of_one(road, rule, params, me, lists.get(k).map_or(&[][..], Vec::as_slice), views, rows);
            }
        };
        if parallel(self.rows.len()) {
            self.rows.par_iter_mut().enumerate().for_each(build);
        } else {
            self.rows.iter_mut().enumerate().for_each(build);
        }
    }

    /// UAV k's rows, with the whole pair row against each cooperating neighbour d < k already
    /// filtered this tick (its input `u_of(d)`) when the share is sequential.
    pub fn rows_of(
        &mut self,
        k: usize,
        share: CollisionShare,
        delta: f64,
        u_of: impl Fn(usize) -> Vec2,
    ) -> &[Row] {
        let rows = &mut self.rows[k];
        let delta_sum = 2.0 * delta;
        if share == CollisionShare::Sequential {
            for row in rows.iter_mut() {
                if let RowKind::Collision(d) = row.kind
                    && d < k
                    && self.views[d].cooperates
                {
                    // d was filtered earlier this tick: enforce the whole relative row given its u_d.
                    row.c = row.c * delta_sum / delta + row.a.dot(&u_of(d));
                }
            }
        }
        rows
    }
}

/// The road rows and neighbour rows of one flying UAV `me` (see the module doc).
fn rows_of_one(
    road: &Road,
    rule: RoadRule,
    p: &Params,
    me: RowView,
    neighbours: &[usize],
    views: &[RowView],
    out: &mut Vec<Row>,
) {
    let state = me.state;
    road_rows(road, rule, state.p, state.v, me.segment, p, out);
    let delta_sum = 2.0 * p.delta;
    // Sampled-data margin (docs/safety.md §4.4, §8 d): with inputs held for dt, the curvature of
    // b_kd lets a pair drift below the continuous-time boundary by up to ½·δΣ·dt² per step, and in
    // dense jams the filtered inputs alternate from tick to tick; the filter keeps twice that,
    // δΣ·dt², beyond D_c.
    let d_c = p.d_c + delta_sum * p.dt * p.dt;
    for &d in neighbours {
        let other = views[d];
        if !other.cooperates {
            if let Some(disk) = other.obstacle {
                out.push(obstacle_row(state, &disk, d_c, p, RowKind::Collision(d)));
            }
            continue;
        }
        let (p_kd, v_kd) = (state.p - other.state.p, state.v - other.state.v);
        if p_kd.norm() > activation_radius(p.d_c, v_kd.norm(), delta_sum) {
            continue;
        }
        out.push(collision_row(p_kd, v_kd, p.delta, p.delta, d_c, p.zeta, RowKind::Collision(d)));
    }
}
