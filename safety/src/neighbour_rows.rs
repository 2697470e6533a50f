//! Rows against neighbours (docs/safety.md §1, §2, §5): the collision row b_kd of each cooperating
//! neighbour within the activation radius, shared δ_k/(δ_k+δ_d), with the class-K function
//! ζb³ + κ·max(b − b₀, 0) of docs/safety.md §10.7 (`barrier::pair_row`), and the row of UAV k alone against
//! a neighbour that does not run the filter, beside the road rows of `road_rows`.
//!
//! A UAV d taking off or landing holds its place: a static obstacle, the collision barrier with
//! δ_d = 0 (docs/safety.md §5 R2 with D_s → D_c), which its neighbour k enforces alone.
//!
//! A UAV whose link gave no state for t seconds may have moved. The Crazyflie holds its last
//! setpoint until its watchdog levels it out after T_hold = 0.5 s and cuts the motors after 2 s; any
//! command it still received was bounded by δ. So it is inside the disk centred on its dead-reckoned
//! position c(t) = p + v·t with radius ρ(t) = ½δτ² + δτ(t − τ), τ = min(t, T_hold): acceleration up
//! to δ for at most T_hold, then coasting. Its neighbour k keeps D_c from that disk with the barrier
//! b = √(2δ(‖p_k − c‖ − D_c − ρ)) + (ṅ − ρ̇), whose row `−p̂ᵀu_k ≤ δ(ṅ − ρ̇)/h + ‖v_⊥‖²/n + ζb³ − ρ̈`
//! also pays for the disk's growth ρ̇ = δτ and ρ̈ = δ while t < T_hold. After the horizon the disk
//! freezes (the motors are off). The lost UAV itself brakes and no longer runs the filter.

use crate::barrier::{Clearance, Row, RowKind, collision_row, pair_row};
use crate::road_rows::activation_radius;
use uav::{Params, UavState, Vec2};

/// How long a Crazyflie keeps its last setpoint before its watchdog levels it out (s).
pub const WATCHDOG_HOLD_S: f64 = 0.5;

/// Where a UAV can be t seconds after its last state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachDisk {
    /// Dead-reckoned centre c(t).
    pub centre: Vec2,
    /// Velocity of the centre (the last velocity; zero once frozen).
    pub velocity: Vec2,
    /// Radius ρ(t) (m).
    pub radius: f64,
    /// ρ̇ (m/s).
    pub growth: f64,
    /// ρ̈ (m/s²).
    pub growth_rate: f64,
}

/// The disk that contains a UAV `t` seconds after its `last` state, frozen after `horizon`.
pub fn reach_disk(last: UavState, t: f64, delta: f64, horizon: f64) -> ReachDisk {
    disk_holding(last, t, delta, WATCHDOG_HOLD_S, horizon)
}

/// The disk that contains a UAV still flown by someone else (another region's fleet loop) `t`
/// seconds after its `last` state: any command up to δ the whole time (no watchdog levels it out),
/// so ρ(t) = ½δt², frozen after `horizon` like [`reach_disk`].
pub fn flown_reach_disk(last: UavState, t: f64, delta: f64, horizon: f64) -> ReachDisk {
    disk_holding(last, t, delta, f64::INFINITY, horizon)
}

/// The disk of a UAV accelerating at up to δ for at most `hold` seconds, then coasting, frozen after
/// `horizon`: centre p + v·t, radius ½δτ² + δτ(t − τ) with τ = min(t, hold).
fn disk_holding(last: UavState, t: f64, delta: f64, hold: f64, horizon: f64) -> ReachDisk {
    let frozen = t >= horizon;
    let t = t.clamp(0.0, horizon.max(0.0));
    let tau = t.min(hold);
    let radius = 0.5 * delta * tau * tau + delta * tau * (t - tau);
    let (velocity, growth, growth_rate) = if frozen {
        (Vec2::zeros(), 0.0, 0.0)
    } else {
        (last.v, delta * tau, if t < hold { delta } else { 0.0 })
    };
    ReachDisk { centre: last.p + last.v * t, velocity, radius, growth, growth_rate }
}

/// The row of UAV k (state `me`) keeping `clearance` from the disk (a point when its radius is 0):
/// the whole pair row, k alone.
pub fn obstacle_row(me: UavState, disk: &ReachDisk, clearance: f64, params: &Params, kind: RowKind) -> Row {
    let p_kd = me.p - disk.centre;
    let n = p_kd.norm();
    let p_hat = if n > 0.0 { p_kd / n } else { Vec2::new(1.0, 0.0) };
    // The boundary approaches k at ρ̇: as if the centre moved towards k at that speed.
    let v_kd = me.v - disk.velocity - p_hat * disk.growth;
    // k's own model error (docs/safety.md §12); the disk holds the other's.
    let clearance = Clearance::one(clearance + disk.radius, params);
    let mut row = collision_row(p_kd, v_kd, params.delta, 0.0, clearance, params.zeta, kind);
    row.c -= disk.growth_rate;
    row
}

/// A static obstacle (ρ = 0) at `at`.
pub fn point_disk(at: Vec2) -> ReachDisk {
    ReachDisk { centre: at, velocity: Vec2::zeros(), radius: 0.0, growth: 0.0, growth_rate: 0.0 }
}

/// A neighbour as UAV k's rows see it this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Neighbour {
    /// It runs the filter on a fresh state: the pair row is shared (b_kd, δ_d = δ).
    Cooperating(UavState),
    /// It does not run the filter but may be in the air: k keeps D_c from its reach disk alone.
    Obstacle(ReachDisk),
    /// On the ground: no row.
    Absent,
}

/// Appends UAV k's rows (state `me`) against `neighbours` (index d and what d is): a shared
/// collision row b_kd per cooperating neighbour within the activation radius, an obstacle row per
/// neighbour that may be in the air, each of kind `RowKind::Collision(d)`.
pub fn neighbour_rows(
    me: UavState,
    neighbours: impl Iterator<Item = (usize, Neighbour)>,
    p: &Params,
    out: &mut Vec<Row>,
) {
    let delta_sum = 2.0 * p.delta;
    // Sampled-data margin (docs/safety.md §4.4, §8 d): with inputs held for dt, the curvature of
    // b_kd lets a pair drift below the continuous-time boundary by up to ½·δΣ·dt² per step, and in
    // dense jams the filtered inputs alternate from tick to tick; the filter keeps twice that,
    // δΣ·dt², beyond D_c.
    let d_c = p.d_c + delta_sum * p.dt * p.dt;
    // Both UAVs' model errors add up (docs/safety.md §12).
    let pair = Clearance::pair(d_c, p);
    for (d, other) in neighbours {
        match other {
            Neighbour::Cooperating(other) => {
                let (p_kd, v_kd) = (me.p - other.p, me.v - other.v);
                let radius = activation_radius(pair.boundary(), v_kd.norm() + pair.eta_v, delta_sum);
                if p_kd.norm() <= radius {
                    out.push(pair_row(p_kd, v_kd, p.delta, p.delta, pair, p.zeta, RowKind::Collision(d)));
                }
            }
            Neighbour::Obstacle(disk) => out.push(obstacle_row(me, &disk, d_c, p, RowKind::Collision(d))),
            Neighbour::Absent => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flown_disk_grows_at_full_delta_until_the_horizon() {
        let last = UavState { p: Vec2::new(1.0, 0.0), v: Vec2::new(2.0, 0.0) };
        let d = flown_reach_disk(last, 1.0, 5.0, 2.0);
        assert!((d.radius - 2.5).abs() < 1e-12 && (d.growth - 5.0).abs() < 1e-12 && d.growth_rate == 5.0);
        assert!((d.centre - Vec2::new(3.0, 0.0)).norm() < 1e-12);
        // Held for 0.5 s only, the watchdog's disk is smaller: a flown UAV may do more.
        assert!(reach_disk(last, 1.0, 5.0, 2.0).radius < d.radius);
        let frozen = flown_reach_disk(last, 3.0, 5.0, 2.0);
        assert_eq!(frozen.radius, 10.0);
        assert_eq!((frozen.velocity, frozen.growth, frozen.growth_rate), (Vec2::zeros(), 0.0, 0.0));
    }

    #[test]
    fn the_disk_grows_while_held_then_linearly_and_freezes_at_the_horizon() {
        let last = UavState { p: Vec2::new(1.0, 0.0), v: Vec2::new(2.0, 0.0) };
        let d = reach_disk(last, 0.2, 5.0, 2.0);
        assert!((d.radius - 0.1).abs() < 1e-12 && (d.growth - 1.0).abs() < 1e-12 && d.growth_rate == 5.0);
        assert!((d.centre - Vec2::new(1.4, 0.0)).norm() < 1e-12);
        let d = reach_disk(last, 1.0, 5.0, 2.0);
        assert!((d.radius - (0.625 + 1.25)).abs() < 1e-12 && (d.growth - 2.5).abs() < 1e-12);
        assert_eq!(d.growth_rate, 0.0);
        let frozen = reach_disk(last, 3.0, 5.0, 2.0);
        assert_eq!(
            frozen,
            ReachDisk { velocity: Vec2::zeros(), growth: 0.0, ..reach_disk(last, 2.0, 5.0, 2.0) }
        );
    }

    #[test]
    fn the_row_against_a_growing_disk_is_tighter_than_against_a_point() {
        let params = Params::default();
        let me = UavState { p: Vec2::new(3.0, 0.0), v: Vec2::zeros() };
        let point = obstacle_row(me, &point_disk(Vec2::zeros()), params.d_c, &params, RowKind::Collision(0));
        let disk = reach_disk(UavState::at_rest(Vec2::zeros()), 0.2, params.delta, 2.0);
        let grown = obstacle_row(me, &disk, params.d_c, &params, RowKind::Collision(0));
        assert!((point.a - Vec2::new(-1.0, 0.0)).norm() < 1e-12);
        assert!(grown.b < point.b && grown.c < point.c);
    }
}
