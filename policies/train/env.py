"""The tracking environment: the exact 2-D double integrator of the Rust simulator, in float64.

Contract shared with the Rust crates (`uav::UavState::stepped`, `uav::saturate`, the policy observation):

    dt = 0.05 s, δ = 5 m/s²
    u   = u_raw · δ/‖u_raw‖ if ‖u_raw‖ > δ, else u_raw        (norm saturation; non-finite u_raw → 0)
    p⁺  = p + v·dt + u·(½dt²),   v⁺ = v + u·dt                 (exact zero-order hold)
    s   = [p − p_r, v − v_r, v]                                (observation, 6 numbers)
    r   = −λs1(‖p⁺ − p_r⁺‖ − ‖p − p_r‖) − λs2(‖v⁺ − v_r⁺‖ − ‖v − v_r‖) − λo‖v‖     (paper eq. 16)

(p_r, v_r) is the reference the observation at t was taken against, and (p_r⁺, v_r⁺) is the SAME reference one
step later: for a moving reference its value at t+1 (being on the reference at t+1 is what tracking means), for a
point target the same point. A target jump (the navigation algorithm handing out a new target) takes effect in the
NEXT observation, never in (p_r⁺, v_r⁺): the reward then judges the action against what the agent was asked to do,
and carries no term the action could not influence. λo‖v‖ uses the velocity at t, as in the paper.

All functions work on arrays whose last axis holds the two components, so they serve one UAV or a batch.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

DT = 0.05
DELTA = 5.0


@dataclass(frozen=True)
class RewardWeights:
    """Weights of paper eq. (16)."""

    lambda_s1: float = 5.0
    lambda_s2: float = 0.7
    lambda_o: float = 0.1

    def as_dict(self) -> dict:
        return asdict(self)


def norm(x: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis, computed as sqrt(x² + y²) like nalgebra's `norm()`."""
    return np.sqrt(x[..., 0] * x[..., 0] + x[..., 1] * x[..., 1])


def saturate(u_raw: np.ndarray, delta: float = DELTA) -> np.ndarray:
    """Scales each acceleration onto the ball ‖u‖ ≤ δ keeping its direction; non-finite rows become 0."""
    u = np.asarray(u_raw, dtype=np.float64)
    finite = np.all(np.isfinite(u), axis=-1)
    u = np.where(finite[..., None], u, 0.0)
    n = norm(u)
    over = n > delta
    factor = np.where(over, delta / np.where(over, n, 1.0), 1.0)
    return np.where(over[..., None], u * factor[..., None], u)


def step(p: np.ndarray, v: np.ndarray, u: np.ndarray, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """Exact step of the double integrator under the (already saturated) acceleration u."""
    return p + v * dt + u * (0.5 * dt * dt), v + u * dt


def observation(p: np.ndarray, v: np.ndarray, p_r: np.ndarray, v_r: np.ndarray) -> np.ndarray:
    """s = [p − p_r, v − v_r, v] (float64; the network takes it as float32)."""
    return np.concatenate([p - p_r, v - v_r, v], axis=-1)


def reward(
    p: np.ndarray,
    v: np.ndarray,
    p_r: np.ndarray,
    v_r: np.ndarray,
    p_next: np.ndarray,
    v_next: np.ndarray,
    p_r_next: np.ndarray,
    v_r_next: np.ndarray,
    w: RewardWeights = RewardWeights(),
) -> np.ndarray:
    """Paper eq. (16); see the module docstring for which reference the t+1 terms use."""
    d_pos = norm(p_next - p_r_next) - norm(p - p_r)
    d_vel = norm(v_next - v_r_next) - norm(v - v_r)
    return -w.lambda_s1 * d_pos - w.lambda_s2 * d_vel - w.lambda_o * norm(v)
