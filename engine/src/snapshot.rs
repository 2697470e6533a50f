//! The immutable snapshot the fleet loop publishes after every tick (`GET /api/state`, `/ws`, Rerun).

use fleet::{Condition, Fleet, Uav, collision_margin, road_margin_in};
use links::LinkPhase;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use uav::Vec2;

/// Record flag of the binary stream and the regions' wire: within ε of its goal.
pub const UAV_ARRIVED: u8 = 1;
/// Record flag of the binary stream and the regions' wire: its link is lost.
pub const UAV_LOST: u8 = 2;

/// The status byte of a record ([`UavStatus`]'s number; docs/streams.md's table).
pub fn status_code(status: UavStatus) -> u8 {
    status as u8
}

/// What one UAV is doing, as the dashboard colours it. The numbers are the binary stream's status
/// byte (a public format: docs/streams.md, `web/binary.js` and `scripts/airroads_stream.py` are
/// checked against them); a new status takes the next number, none is ever renumbered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum UavStatus {
    /// Flying its policy towards its goal (or hovering without one); no slack in use.
    Flying = 0,
    /// Within ε of its goal.
    Arrived = 1,
    /// The filter needed slack this tick, or the fleet is paused, or the policy failed: braking.
    Braking = 2,
    /// The QP failed this tick; the UAV brakes.
    Failed = 3,
    /// No fresh state from the link; its last known state was used.
    Stale = 4,
    /// No state for `stale_after` (or reconnecting while it may be airborne): neighbours avoid its reach.
    Lost = 5,
    /// Connecting to its Crazyflie.
    Connecting = 6,
    /// Taking off to the flight altitude.
    TakingOff = 7,
    /// Landing.
    Landing = 8,
    /// On the ground after landing.
    Landed = 9,
    /// Motors cut by an emergency stop, as the Crazyflie confirmed.
    Stopped = 10,
    /// Emergency stop sent, not yet confirmed by the Crazyflie: it may still be in the air.
    Stopping = 11,
    /// Held back by a traffic rule (`wait_reason` says which).
    Waiting = 12,
}

impl UavStatus {
    /// Every status, in the order of their numbers.
    pub const ALL: [UavStatus; 13] = [
        Self::Flying,
        Self::Arrived,
        Self::Braking,
        Self::Failed,
        Self::Stale,
        Self::Lost,
        Self::Connecting,
        Self::TakingOff,
        Self::Landing,
        Self::Landed,
        Self::Stopped,
        Self::Stopping,
        Self::Waiting,
    ];
}

/// One UAV in a snapshot. Vectors are `[x, y]` in metres, m/s and m/s².
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct UavSnapshot {
    /// Unique id (shared with the previous snapshot's while the UAV at this index keeps it).
    #[schemars(with = "String")]
    pub id: Arc<str>,
    /// Name of its policy.
    #[schemars(with = "String")]
    pub policy: Arc<str>,
    /// Position p (m).
    pub p: [f64; 2],
    /// Velocity v (m/s).
    pub v: [f64; 2],
    /// The policy's nominal input u_r (m/s²).
    pub u_ref: [f64; 2],
    /// The filtered input u sent to the UAV (m/s²).
    pub u: [f64; 2],
    /// Temporary target p^r (m).
    pub target: [f64; 2],
    /// Goal p_g, or null when it hovers.
    pub goal: Option<[f64; 2]>,
    /// Within ε of its goal.
    pub arrived: bool,
    /// What it is doing.
    pub status: UavStatus,
    /// Its link: `sim` or the Crazyflie URI.
    #[schemars(with = "String")]
    pub link: Arc<str>,
    /// Where it is in its flight as its link reports it (`flying` for in-process UAVs); its name in JSON.
    #[serde(serialize_with = "phase_name")]
    #[schemars(with = "String")]
    pub phase: LinkPhase,
    /// Its link is lost (see `status`).
    pub lost: bool,
    /// The link's last error (why it is not connected, or a stop or landing not confirmed), null
    /// when none.
    pub link_error: Option<String>,
    /// What its firmware reports about itself (Crazyflies only; absent for in-process UAVs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub firmware: Option<FirmwareSnapshot>,
    /// Why a traffic rule holds it back (`single_file`, `deadlock_backoff`, `junction`, `merge`), null
    /// when none does.
    pub wait_reason: Option<&'static str>,
    /// CBF rows binding at u.
    pub active_rows: usize,
    /// Largest slack of its QP this tick (0 when none was needed).
    pub slack: f64,
    /// Smallest barrier value among its rows (null without rows).
    pub min_barrier: Option<f64>,
    /// Smallest collision margin S_kd (eq. 2) to a neighbour, null without neighbours nearby (m).
    pub collision_margin_m: Option<f64>,
    /// Road margin (eq. 6, braking distance included) to the nearest wall (m).
    pub road_margin_m: f64,
}

/// What a Crazyflie's firmware reports (`firmware` in a UAV's snapshot): the supervisor's bitfield
/// decoded (crazyflie-firmware `supervisor.c`), the battery and how much of the state log arrives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
pub struct FirmwareSnapshot {
    /// `supervisor.info`, null until the firmware has logged it.
    pub supervisor_info: Option<u16>,
    /// Armed (supervisor bit 1).
    pub armed: bool,
    /// Flying, as the supervisor sees it (bit 4).
    pub flying: bool,
    /// Tumbled (bit 5).
    pub tumbled: bool,
    /// Locked until a reboot (bit 6): an emergency stop or a commander-watchdog timeout in flight.
    pub locked: bool,
    /// Crashed (bit 7).
    pub crashed: bool,
    /// Battery voltage (V), null until logged.
    pub battery_v: Option<f64>,
    /// Fraction of the expected state samples received over the last second, null until known.
    pub link_quality: Option<f64>,
}

impl FirmwareSnapshot {
    /// The snapshot of a link's report.
    pub fn of(report: links::VehicleReport) -> Self {
        let bit = |n: u16| report.supervisor_info.is_some_and(|i| i & (1 << n) != 0);
        Self {
            supervisor_info: report.supervisor_info,
            armed: bit(1),
            flying: bit(4),
            tumbled: bit(5),
            locked: bit(6),
            crashed: bit(7),
            battery_v: report.battery_v,
            link_quality: report.link_quality,
        }
    }
}

/// The fleet after one tick.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct Snapshot {
    /// Ticks run since the server started.
    pub tick: u64,
    /// Time since the server started (s).
    pub time: f64,
    /// True while the fleet is paused (`POST /api/fleet/pause`).
    pub paused: bool,
    /// Increases whenever the road changes (`GET /api/road` gives the layout).
    pub road_version: u64,
    /// Smallest collision margin over all pairs this tick, null with fewer than two UAVs nearby (m).
    pub min_collision_margin_m: Option<f64>,
    /// Smallest road margin over all UAVs this tick, null without UAVs (m).
    pub min_road_margin_m: Option<f64>,
    /// Safe distances D_c and D_s the margins are held above (m).
    pub d_c: f64,
    /// D_s (m).
    pub d_s: f64,
    /// Every UAV, in the order they were added.
    pub uavs: Vec<UavSnapshot>,
    /// The single-file sections of the road and their reservations (`traffic` navigation).
    pub reservations: Vec<ReservationSnapshot>,
}

/// A single-file section: one direction at a time.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ReservationSnapshot {
    /// Its centre line from start to end, points about 0.5 m apart (m).
    pub path: Vec<[f64; 2]>,
    /// The end it admits from (`start` or `end` of `path`), null while free.
    pub open_from: Option<&'static str>,
    /// UAVs admitted (inside or on their way in).
    pub admitted: u32,
    /// UAVs waiting for their turn.
    pub waiting: u32,
}

/// Distance between the points of a reservation's path (m).
const PATH_STEP_M: f64 = 0.5;

fn reservations(fleet: &Fleet) -> Vec<ReservationSnapshot> {
    let Some(line) = fleet.road().map(|r| r.centerline()) else { return Vec::new() };
    fleet
        .section_use()
        .map(|z| {
            let (start, end) = (z.section.start, z.section.end);
            let steps = ((end - start) / PATH_STEP_M).ceil().max(1.0) as usize;
            let path = (0..=steps)
                .map(|k| xy(&line.point_at(start + (end - start) * k as f64 / steps as f64)))
                .collect();
            let open_from = z.open.map(|entry| if entry == 0 { "start" } else { "end" });
            ReservationSnapshot { path, open_from, admitted: z.admitted, waiting: z.waiting }
        })
        .collect()
}

fn xy(v: &Vec2) -> [f64; 2] {
    [v.x, v.y]
}

/// A link phase as JSON: its name ([`LinkPhase::name`]).
fn phase_name<S: serde::Serializer>(phase: &LinkPhase, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(phase.name())
}

fn status(u: &Uav, paused: bool) -> UavStatus {
    let l = &u.last;
    match u.condition {
        Condition::Lost => return UavStatus::Lost,
        Condition::Stale => return UavStatus::Stale,
        Condition::Cooperating | Condition::Transit | Condition::Grounded => {}
    }
    match u.phase {
        LinkPhase::Connecting => return UavStatus::Connecting,
        LinkPhase::TakingOff => return UavStatus::TakingOff,
        LinkPhase::Landing => return UavStatus::Landing,
        LinkPhase::Landed => return UavStatus::Landed,
        LinkPhase::Stopped => return UavStatus::Stopped,
        LinkPhase::Stopping => return UavStatus::Stopping,
        LinkPhase::Flying => {}
    }
    if l.failed {
        UavStatus::Failed
    } else if u.nav.arrived {
        UavStatus::Arrived
    } else if l.policy_fallback || paused {
        UavStatus::Braking
    } else if u.traffic.waiting.is_some() {
        UavStatus::Waiting
    } else if l.max_slack > 1e-6 {
        UavStatus::Braking
    } else {
        UavStatus::Flying
    }
}

/// `text` as shared text: `previous`'s when it says the same (a count increment, no allocation).
fn shared(previous: Option<&Arc<str>>, text: &str) -> Arc<str> {
    match previous {
        Some(p) if **p == *text => Arc::clone(p),
        _ => Arc::from(text),
    }
}

impl Snapshot {
    /// The snapshot of `fleet` after its last tick; margins use the neighbour lists of that tick.
    pub fn of(fleet: &Fleet, tick: u64, time: f64, road_version: u64) -> Self {
        Self::after(None, fleet, tick, time, road_version)
    }

    /// [`Snapshot::of`], sharing the ids, policy names and link names of `previous` (the last
    /// snapshot) where the UAV at the same index has the same ones: a snapshot of 10,000 UAVs
    /// then allocates its vectors, not 30,000 strings. Built in parallel for large fleets.
    pub fn after(
        previous: Option<&Snapshot>,
        fleet: &Fleet,
        tick: u64,
        time: f64,
        road_version: u64,
    ) -> Self {
        let p = fleet.config.params;
        let road = fleet.airspace();
        let lists = fleet.neighbour_lists();
        let all = fleet.uavs();
        let paused = fleet.paused();
        let before = previous.map_or(&[][..], |s| &s.uavs[..]);
        // The margins the tick's rows stage measured, while the fleet holds the states it read.
        let tick_margins = fleet.tick_margins();
        // Each UAV's entry on its own (in parallel for large fleets: a UAV is `Sync`, its link only
        // read through `&self` methods that lock what they share).
        let entry = |(k, u): (usize, &Uav)| {
            let state = u.state;
            // UAVs on the ground (landed, stopped, not yet up) are not in each other's airspace.
            let collision = tick_margins.and_then(|m| m.collision(k)).unwrap_or_else(|| {
                lists.get(k).filter(|_| u.condition.in_the_air()).and_then(|list| {
                    list.iter()
                        .filter_map(|&d| all.get(d))
                        .filter(|d| d.condition.in_the_air())
                        .map(|d| collision_margin(&state, &d.state, 2.0 * p.delta))
                        .min_by(f64::total_cmp)
                })
            });
            let road_margin = match &tick_margins {
                Some(margins) => margins.road(k),
                None => road_margin_in(road, u.nav.tracker.current, &state, p.delta),
            };
            let was = before.get(k);
            let l = &u.last;
            UavSnapshot {
                id: shared(was.map(|w| &w.id), &u.id),
                policy: shared(was.map(|w| &w.policy), &u.policy),
                p: xy(&u.state.p),
                v: xy(&u.state.v),
                u_ref: xy(&l.u_ref),
                u: xy(&l.u),
                target: xy(&l.target),
                goal: u.nav.goal().map(|g| xy(&g)),
                arrived: u.nav.arrived,
                status: status(u, paused),
                link: shared(was.map(|w| &w.link), u.link.describe()),
                phase: u.phase,
                lost: u.condition == Condition::Lost,
                link_error: u.link.error(),
                firmware: u.link.vehicle().map(FirmwareSnapshot::of),
                wait_reason: u.traffic.waiting.map(|w| w.name()),
                active_rows: l.active_rows,
                slack: l.max_slack,
                min_barrier: l.min_barrier.is_finite().then_some(l.min_barrier),
                collision_margin_m: collision,
                road_margin_m: road_margin,
            }
        };
        let uavs: Vec<UavSnapshot> = if all.len() >= fleet::PARALLEL_FROM_UAVS {
            all.par_iter().enumerate().map(entry).collect()
        } else {
            all.iter().enumerate().map(entry).collect()
        };
        Self {
            tick,
            time,
            paused,
            road_version,
            min_collision_margin_m: uavs.iter().filter_map(|u| u.collision_margin_m).min_by(f64::total_cmp),
            min_road_margin_m: uavs.iter().map(|u| u.road_margin_m).min_by(f64::total_cmp),
            d_c: p.d_c,
            d_s: p.d_s,
            uavs,
            reservations: reservations(fleet),
        }
    }
}

#[cfg(test)]
#[path = "snapshot_tests.rs"]
mod tests;
