//! The tracking reward the RL policy is trained with (paper eq. 16), the Rust side of the parity
//! contract with `policies/train/env.py`.

use uav::{UavState, Vec2};

/// Weights of eq. (16): λs1 (position error change), λs2 (velocity error change), λo (speed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RewardWeights {
    /// λs1, default 5.
    pub lambda_s1: f64,
    /// λs2, default 0.7.
    pub lambda_s2: f64,
    /// λo, default 0.1.
    pub lambda_o: f64,
}

impl Default for RewardWeights {
    fn default() -> Self {
        Self { lambda_s1: 5.0, lambda_s2: 0.7, lambda_o: 0.1 }
    }
}

/// Eq. (16): `r = −λs1(‖p̂(t+1)‖ − ‖p̂(t)‖) − λs2(‖v̂(t+1)‖ − ‖v̂(t)‖) − λo‖v(t)‖`, where
/// p̂ = p − p_r and v̂ = v − v_r; the t+1 terms use the reference one step later (`p_r_next`,
/// `v_r_next`, the same point for a fixed target).
pub fn tracking_reward(
    now: &UavState,
    next: &UavState,
    (p_r, v_r): (Vec2, Vec2),
    (p_r_next, v_r_next): (Vec2, Vec2),
    w: &RewardWeights,
) -> f64 {
    let d_pos = (next.p - p_r_next).norm() - (now.p - p_r).norm();
    let d_vel = (next.v - v_r_next).norm() - (now.v - v_r).norm();
    -w.lambda_s1 * d_pos - w.lambda_s2 * d_vel - w.lambda_o * now.v.norm()
}
