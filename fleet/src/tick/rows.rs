//! The rows of every UAV's QP for one tick, built in parallel: its road rows (`safety::road_rows`),
//! a collision row b_kd per cooperating neighbour within the activation radius, and an obstacle row
//! per neighbour that does not cooperate but may be in the air (its reach disk; both
//! `safety::neighbour_rows`). A foreign UAV (flown by another region) is such an obstacle, its view
//! numbered after the fleet's own UAVs.
//! Each UAV's rows depend only on the states read this tick, so any number of threads gives the same
//! rows. What depends on the order of filtering (the whole pair row against a neighbour filtered
//! earlier in the tick, given its u_d) is applied to a copy just before each UAV's QP
//! ([`RowBuilder::rows_of`], in the order of [`crate::tick::filtering`]).
//!
//! The rows of each block of [`UAVS_PER_BLOCK`] consecutive UAVs share one buffer ([`Ragged`]), one
//! block per parallel task: a block's total varies far less from tick to tick than one UAV's row
//! count, so the buffers stop growing after the first ticks (no allocation in steady state).
//!
//! The same pass records each UAV's margins as the run's metrics count them ([`UavMargins`]): its
//! road margin from the walls its rows look at (the query widened to the margin's reach), its
//! closest pair from its neighbour list, so that the metrics need no second pass over the walls.

use crate::member::Uav;
use crate::ragged::Ragged;
use crate::runs::margins::{UavMargins, pair_margins, road_margin_at, road_margin_reach};
use crate::tick::{map_into, parallel};
use rayon::prelude::*;
use roads::{Airspace, Boundary, SEGMENT_NEAR_M};
use safety::{
    Neighbour, ReachDisk, RoadRule, Row, RowKind, neighbour_rows, road_rows, walls_rows_and_margin,
};
use uav::{Params, UavState, Vec2};

/// What the rows of other UAVs need to know about one UAV this tick (plain data, shared by threads).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowView {
    /// Its state as read this tick.
    pub state: UavState,
    /// It follows commands and gets rows of its own.
    pub flying: bool,
    /// It shares pair rows with its neighbours ([`crate::Condition::cooperates`]).
    pub cooperates: bool,
    /// It is in the air, or may be ([`crate::Condition::in_the_air`]).
    pub in_the_air: bool,
    /// Its reach disk when it does not cooperate but may be in the air ([`crate::Condition::in_the_air`]).
    pub obstacle: Option<ReachDisk>,
    /// Its tracked segment or cell (a hint for the road's queries).
    pub segment: usize,
}

/// Every UAV's neighbours this tick: own UAVs (`own[k]`), foreign UAVs (`foreign[k]`, indices into
/// `foreign_disks`) and where each foreign UAV may be.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NeighbourLists<'a> {
    /// `own[k]`: the fleet's UAVs near UAV k.
    pub own: &'a Ragged<usize>,
    /// `foreign[k]`: the foreign UAVs near UAV k.
    pub foreign: &'a Ragged<usize>,
    /// Each foreign UAV's reach disk.
    pub foreign_disks: &'a [ReachDisk],
}

/// UAVs whose rows share one buffer and one parallel task.
const UAVS_PER_BLOCK: usize = 64;

/// The rows, pair partners and margins of [`UAVS_PER_BLOCK`] consecutive UAVs.
#[derive(Debug, Default)]
struct RowBlock {
    /// `rows[i]`: the rows of the block's UAV i.
    rows: Ragged<Row>,
    /// `partners[i]`: the flying UAVs the block's UAV i has a collision row against.
    partners: Ragged<usize>,
    /// `margins[i]`: the margins of the block's UAV i.
    margins: Vec<UavMargins>,
    /// `collision[i]`: the smallest S_kd of the block's UAV i to a neighbour in the air, when both
    /// are (empty unless [`RowBuilder::collision_per_uav`]).
    collision: Vec<Option<f64>>,
}

/// Row buffers, reused from tick to tick.
#[derive(Debug, Default)]
pub(crate) struct RowBuilder {
    /// Also measure each UAV's smallest collision margin to a neighbour in the air
    /// ([`RowBuilder::collision_margin`]; `FleetConfig::uav_collision_margins`).
    pub collision_per_uav: bool,
    views: Vec<RowView>,
    /// `blocks[b]`: the rows and margins of UAVs `b·UAVS_PER_BLOCK..`.
    blocks: Vec<RowBlock>,
}

impl RowBuilder {
    /// Builds every flying UAV's rows (without the sequential share) from `uavs` and their
    /// neighbour lists; `disk_of(u)` is UAV u's reach disk. Each foreign UAV f is an obstacle, view
    /// `uavs.len() + f`.
    pub fn build(
        &mut self,
        road: &Airspace,
        rule: RoadRule,
        params: &Params,
        uavs: &[Uav],
        neighbours: NeighbourLists<'_>,
        disk_of: impl Fn(&Uav) -> ReachDisk + Sync,
    ) {
        let NeighbourLists { own: lists, foreign: foreign_lists, foreign_disks } = neighbours;
        let view = |u: &Uav| RowView {
            state: u.state,
            flying: u.condition.flying(),
            cooperates: u.condition.cooperates(),
            in_the_air: u.condition.in_the_air(),
            obstacle: (!u.condition.cooperates() && u.condition.in_the_air()).then(|| disk_of(u)),
            segment: u.nav.way().map_or(u.nav.tracker.current.unwrap_or(0), |w| w.cell()),
        };
        map_into(uavs, view, &mut self.views);
        self.views.extend(foreign_disks.iter().map(|disk| RowView {
            state: UavState { p: disk.centre, v: disk.velocity },
            flying: false,
            cooperates: false,
            in_the_air: true,
            obstacle: Some(*disk),
            segment: 0,
        }));
        let n = uavs.len();
        self.blocks.resize_with(n.div_ceil(UAVS_PER_BLOCK), RowBlock::default);
        self.blocks.truncate(n.div_ceil(UAVS_PER_BLOCK));
        let (views, collision_per_uav) = (&self.views, self.collision_per_uav);
        let build = |(b, block): (usize, &mut RowBlock)| {
            let first = b * UAVS_PER_BLOCK;
            let uavs = first..(first + UAVS_PER_BLOCK).min(n);
            block.rows.reset(uavs.len());
            block.partners.reset(uavs.len());
            block.margins.clear();
            block.collision.clear();
            for (i, k) in uavs.enumerate() {
                let me = views[k];
                // The closest later neighbour (for the metrics) and, if asked, the nearest in the air
                // (asked or not, the same pass: a UAV counted as on the ground measures no such pair).
                let all = lists[k].iter().map(|&d| (d, &views[d].state, views[d].in_the_air));
                let me_in_the_air = collision_per_uav && me.in_the_air;
                let (closest, nearest) = pair_margins((k, &me.state, me_in_the_air), params.delta, all);
                let mut road_margins = None;
                if me.flying {
                    let neighbours = lists[k].iter().copied().chain(foreign_lists[k].iter().map(|&f| n + f));
                    block.rows.fill(i, |rows| {
                        road_margins = rows_of_one(road, rule, params, me, neighbours, views, rows);
                    });
                    // Its pair partners, read from its rows while they are in the cache (a foreign
                    // UAV's view never flies).
                    let partners = block.rows[i].iter().filter_map(|r| match r.kind {
                        RowKind::Collision(d) if d != k && views[d].flying => Some(d),
                        _ => None,
                    });
                    block.partners.fill(i, |out| out.extend(partners));
                }
                // Where the rows' pass could not give the road margin, today's query for this UAV only.
                let (wall, road_margin) = road_margins.unwrap_or_else(|| {
                    let wall = road.signed_distance_in(me.segment, &me.state.p);
                    (wall, road_margin_at(road, Some(me.segment), &me.state, params.delta, wall))
                });
                block.margins.push(UavMargins { wall, road_margin, closest });
                if collision_per_uav {
                    block.collision.push(nearest);
                }
            }
        };
        if parallel(n) {
            self.blocks.par_iter_mut().enumerate().for_each(build);
        } else {
            self.blocks.iter_mut().enumerate().for_each(build);
        }
    }

    /// What the rows of other UAVs know of UAV k this tick (k ≥ the fleet's size: a foreign UAV).
    pub fn view(&self, k: usize) -> RowView {
        self.views[k]
    }

    /// UAV k's rows as built, each pair row with its share only (empty when it does not fly).
    pub fn built(&self, k: usize) -> &[Row] {
        self.blocks.get(k / UAVS_PER_BLOCK).map_or(&[], |block| &block.rows[k % UAVS_PER_BLOCK])
    }

    /// The flying UAVs UAV k has a collision row against this tick (empty when it does not fly).
    pub fn partners(&self, k: usize) -> &[usize] {
        self.blocks.get(k / UAVS_PER_BLOCK).map_or(&[], |block| &block.partners[k % UAVS_PER_BLOCK])
    }

    /// UAV k's margins at the states read this tick (None when there is no UAV k).
    pub fn margins(&self, k: usize) -> Option<UavMargins> {
        self.blocks.get(k / UAVS_PER_BLOCK)?.margins.get(k % UAVS_PER_BLOCK).copied()
    }

    /// UAV k's smallest collision margin S_kd to a neighbour in the air at the states read this tick,
    /// when it is in the air itself (`Some(None)`: no such neighbour or not in the air; None when
    /// not measured: [`RowBuilder::collision_per_uav`] was off, or there is no UAV k).
    pub fn collision_margin(&self, k: usize) -> Option<Option<f64>> {
        self.blocks.get(k / UAVS_PER_BLOCK)?.collision.get(k % UAVS_PER_BLOCK).copied()
    }

    /// True when [`RowBuilder::margins`] are those of `uavs` now: built for as many UAVs, each
    /// still at the state read this tick.
    pub fn margins_hold_for(&self, uavs: &[Uav]) -> bool {
        let built: usize = self.blocks.iter().map(|block| block.margins.len()).sum();
        let same = |(u, view): (&Uav, &RowView)| u.state == view.state;
        // Each UAV on its own, an `all` being the same in any order: in parallel for large fleets.
        built == uavs.len()
            && if parallel(uavs.len()) {
                uavs.par_iter().zip(&self.views).all(same)
            } else {
                uavs.iter().zip(&self.views).all(same)
            }
    }

    /// UAV k's rows, with the whole pair row against each cooperating neighbour d filtered before
    /// it this tick (`before(d)`, its input `u_of(d)`): the rows as built when there is none (no
    /// copy), else a copy made whole in `out`.
    pub fn rows_of<'a>(
        &'a self,
        k: usize,
        delta: f64,
        before: impl Fn(usize) -> bool,
        u_of: impl Fn(usize) -> Vec2,
        out: &'a mut Vec<Row>,
    ) -> &'a [Row] {
        let built = self.built(k);
        // The neighbour whose whole pair row this row becomes, if any.
        let whole = |row: &Row| match row.kind {
            RowKind::Collision(d) if self.views[d].cooperates && before(d) => Some(d),
            _ => None,
        };
        if built.iter().all(|row| whole(row).is_none()) {
            return built;
        }
        out.clear();
        out.extend_from_slice(built);
        let delta_sum = 2.0 * delta;
        for row in out.iter_mut() {
            if let Some(d) = whole(row) {
                // d was filtered earlier this tick: enforce the whole relative row given its u_d.
                row.c = row.c * delta_sum / delta + row.a.dot(&u_of(d));
            }
        }
        out
    }
}

/// The road rows (on a network: its walls, rule R2 whatever `rule` says, docs/safety.md §5.1) and
/// neighbour rows of one flying UAV `me` (see the module doc); returns its distance to the road's
/// boundary and road margin when rule R2's pass over the walls gave them (inside the road).
fn rows_of_one(
    road: &Airspace,
    rule: RoadRule,
    p: &Params,
    me: RowView,
    neighbours: impl Iterator<Item = usize>,
    views: &[RowView],
    out: &mut Vec<Row>,
) -> Option<(f64, f64)> {
    let state = me.state;
    let (v, delta) = (state.v, p.delta);
    let margins = match (road, rule) {
        (Airspace::Road(road), RoadRule::Halfplanes | RoadRule::Paper) => {
            road_rows(road, rule, state.p, v, me.segment, p, out);
            None
        }
        (Airspace::Road(road), RoadRule::Walls) => {
            // The boundary distance and the road margin from the rows' own walls when those settle
            // them: the nearest wall looked at is the nearest of all when it is within the query's
            // reach, and a wall beyond the reach has a margin above reach − v²/(2δ). The query
            // reaches as far as the tracked segment's list of walls (which it reads whole anyway).
            let reach = Some(SEGMENT_NEAR_M);
            let seen = walls_rows_and_margin(road, state.p, v, me.segment, p, reach, out);
            seen.and_then(|seen| {
                let (wall, room) = (seen.nearest_d2.sqrt(), seen.reach - 1e-9 * (1.0 + seen.reach));
                (wall <= room && seen.margin + v.norm_squared() / (2.0 * delta) <= room)
                    .then_some((wall, seen.margin))
            })
        }
        (Airspace::Network(net), _) => {
            // On a network the boundary distance is the cells' own (another formula): the margin's
            // reach from it, known only inside (at a positive distance to the boundary).
            let wall = net.signed_distance_in(me.segment, &state.p);
            let reach = (wall > 0.0).then(|| road_margin_reach(&state, delta, wall));
            let seen = walls_rows_and_margin(net, state.p, v, me.segment, p, reach, out);
            seen.map(|seen| (wall, seen.margin))
        }
    };
    let what = |d: usize| {
        let other = views[d];
        let seen = match (other.cooperates, other.obstacle) {
            (true, _) => Neighbour::Cooperating(other.state),
            (false, Some(disk)) => Neighbour::Obstacle(disk),
            (false, None) => Neighbour::Absent,
        };
        (d, seen)
    };
    neighbour_rows(state, neighbours.map(what), p, out);
    margins
}
