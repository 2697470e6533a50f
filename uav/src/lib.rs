//! Shared vocabulary of airroads: 2-D vectors, the UAV state of the double integrator (paper eq. 1),
//! the scenario parameters (δ, D_s, D_c, ζ, r_s, ...) and the rule for UAV ids.
//!
//! This crate owns no algorithm beyond the exact double-integrator step; roads, safety, policies and
//! links all speak these types.

mod id;
mod params;
pub mod schema;

pub use id::{MAX_UAV_ID_LEN, UAV_ID_RULE, check_uav_id, is_uav_id_char};
pub use params::{MAX_DT_S, MIN_DT_S, PARAM_RANGES, ParamError, ParamRange, Params};

/// A 2-D vector in metres (positions), m/s (velocities) or m/s² (accelerations), world frame.
pub type Vec2 = nalgebra::Vector2<f64>;

/// State of one UAV modelled as a 2-D double integrator: `ṗ = v`, `v̇ = u` (paper eq. 1).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UavState {
    /// Position `p` (m).
    pub p: Vec2,
    /// Velocity `v` (m/s).
    pub v: Vec2,
}

impl UavState {
    /// A UAV at rest at `p`.
    pub fn at_rest(p: Vec2) -> Self {
        Self { p, v: Vec2::zeros() }
    }

    /// Exact zero-order-hold step of the double integrator: `p += v dt + ½u dt²`, `v += u dt`.
    pub fn stepped(&self, u: Vec2, dt: f64) -> Self {
        Self { p: self.p + self.v * dt + u * (0.5 * dt * dt), v: self.v + u * dt }
    }

    /// True when both position and velocity are finite numbers.
    pub fn is_finite(&self) -> bool {
        is_finite(&self.p) && is_finite(&self.v)
    }
}

/// z-component of the 2-D cross product `a × b`.
pub fn cross(a: &Vec2, b: &Vec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// True when both components are finite.
pub fn is_finite(a: &Vec2) -> bool {
    a.x.is_finite() && a.y.is_finite()
}

/// Scales `u` onto the ball `‖u‖ ≤ δ` (keeps its direction); non-finite input gives zero.
pub fn saturate(u: Vec2, delta: f64) -> Vec2 {
    if !is_finite(&u) {
        return Vec2::zeros();
    }
    let n = u.norm();
    if n > delta { u * (delta / n) } else { u }
}

/// The acceleration that brakes a UAV moving at `v` as hard as `‖u‖ ≤ δ` allows, without
/// overshooting to a reverse velocity within one step of `dt`.
pub fn braking_input(v: Vec2, delta: f64, dt: f64) -> Vec2 {
    saturate(-v / dt, delta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_step_matches_constant_acceleration_kinematics() {
        let s = UavState { p: Vec2::new(1.0, -2.0), v: Vec2::new(0.5, 3.0) };
        let u = Vec2::new(-4.0, 2.0);
        // Two half steps equal one full step: the discretisation is exact, not Euler.
        let two_halves = s.stepped(u, 0.025).stepped(u, 0.025);
        let one = s.stepped(u, 0.05);
        assert!((two_halves.p - one.p).norm() < 1e-15);
        assert!((two_halves.v - one.v).norm() < 1e-15);
        assert!((one.p - Vec2::new(1.0 + 0.025 - 0.005, -2.0 + 0.15 + 0.0025)).norm() < 1e-15);
    }

    #[test]
    fn saturation_keeps_direction_and_rejects_nan() {
        let u = saturate(Vec2::new(6.0, 8.0), 5.0);
        assert!((u - Vec2::new(3.0, 4.0)).norm() < 1e-12);
        assert_eq!(saturate(Vec2::new(1.0, 1.0), 5.0), Vec2::new(1.0, 1.0));
        assert_eq!(saturate(Vec2::new(f64::NAN, 1.0), 5.0), Vec2::zeros());
        assert_eq!(saturate(Vec2::new(f64::INFINITY, 1.0), 5.0), Vec2::zeros());
    }

    #[test]
    fn braking_stops_without_reversing() {
        let v = Vec2::new(0.1, 0.0);
        let s = UavState { p: Vec2::zeros(), v }.stepped(braking_input(v, 5.0, 0.05), 0.05);
        assert!(s.v.norm() < 1e-15);
        let fast = Vec2::new(10.0, 0.0);
        assert!((braking_input(fast, 5.0, 0.05) - Vec2::new(-5.0, 0.0)).norm() < 1e-12);
    }
}
