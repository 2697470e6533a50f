//! The safety margins a run reports: eq. (2) and eq. (6) left sides with the corrected sign (E1).

use roads::Road;
use safety::barrier::braking_margin;
use uav::{UavState, Vec2};

/// S_kd = ‖p_kd‖ − min(v̄_kd, 0)²/(2(δ_k+δ_d)): the closest two UAVs get if both brake now.
pub fn collision_margin(k: &UavState, d: &UavState, delta_sum: f64) -> f64 {
    let p = k.p - d.p;
    let n = p.norm();
    let rate = if n > 0.0 { p.dot(&(k.v - d.v)) / n } else { 0.0 };
    braking_margin(n, rate, delta_sum)
}

/// min over the finite walls of `dist − min(ḋist, 0)²/(2δ)`: the closest the UAV gets to the road
/// boundary if it brakes now. Walls are measured as the filter enforces them (rule R2): a wall's
/// line distance in its slab from either side, its end points as points. Negative distance when outside.
pub fn road_margin(road: &Road, s: &UavState, delta: f64) -> f64 {
    if !road.contains(&s.p) {
        return road.boundary_distance(&s.p);
    }
    let mut best = f64::INFINITY;
    for w in road.walls() {
        let (c, t) = w.nearest(&s.p);
        let (dist, rate) = if t > 0.0 && t < 1.0 {
            let d = w.signed_distance(&s.p);
            (d.abs(), d.signum() * w.n_in.dot(&s.v))
        } else {
            let e: Vec2 = s.p - c;
            let n = e.norm();
            (n, if n > 0.0 { e.dot(&s.v) / n } else { 0.0 })
        };
        best = best.min(braking_margin(dist, rate, delta));
    }
    best
}
