"""Closed-loop evaluation on the paper's three references, and the PD baselines to compare against.

A run lasts 50 s (1000 steps). The UAV starts at rest at the reference's start point; at step k it observes
s = [p − p_r(k), v − v_r(k), v], the controller's raw acceleration is saturated to ‖u‖ ≤ δ and the exact step is
taken. The error samples are e(k) = p(k) − p_r(k) for k = 1..1000 (after each step); RMSE = sqrt(mean ‖e‖²), and
per axis sqrt(mean e_x²), sqrt(mean e_y²).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

import env
from references import EVAL_NAMES, Reference, evaluation

# act(obs float32 (B, 6), accel_ff (B, 2)) -> raw acceleration (B, 2) in m/s², before saturation
Controller = Callable[[np.ndarray, np.ndarray], np.ndarray]


def rollout(act: Controller, refs: list[Reference]) -> np.ndarray:
    """Runs the controller on equally long references at once; returns the errors p(k) − p_r(k), (B, T, 2)."""
    ref_p, ref_v = np.stack([r.p for r in refs]), np.stack([r.v for r in refs])
    p, v = np.stack([r.p0 for r in refs]), np.stack([r.v0 for r in refs])
    steps = ref_p.shape[1] - 1
    errors = np.zeros((len(refs), steps, 2))
    for k in range(steps):
        obs = env.observation(p, v, ref_p[:, k], ref_v[:, k]).astype(np.float32)
        accel_ff = (ref_v[:, k + 1] - ref_v[:, k]) / env.DT
        p, v = env.step(p, v, env.saturate(act(obs, accel_ff)))
        errors[:, k] = p - ref_p[:, k + 1]
    return errors


def rmse(errors: np.ndarray) -> dict:
    """Total and per-axis RMSE (m) of one run's errors (T, 2)."""
    return {
        "total": float(np.sqrt(np.mean(np.sum(errors**2, axis=-1)))),
        "x": float(np.sqrt(np.mean(errors[:, 0] ** 2))),
        "y": float(np.sqrt(np.mean(errors[:, 1] ** 2))),
        "max": float(np.max(np.linalg.norm(errors, axis=-1))),
    }


def evaluate(act: Controller) -> dict:
    """RMSE on ellipse, figure-8 and rectangle: {name: {"total", "x", "y", "max"}}."""
    errors = rollout(act, [evaluation(name) for name in EVAL_NAMES])
    return {name: rmse(e) for name, e in zip(EVAL_NAMES, errors)}


def pd(kp: float, kd: float, feed_forward: bool) -> Controller:
    """u = −kp (p − p_r) − kd (v − v_r) [+ a_r]; a_r is the exact discrete feed-forward (v_r(k+1) − v_r(k))/dt,
    information the learned policy does not get."""

    def act(obs: np.ndarray, accel_ff: np.ndarray) -> np.ndarray:
        obs = obs.astype(np.float64)
        return -kp * obs[:, 0:2] - kd * obs[:, 2:4] + (accel_ff if feed_forward else 0.0)

    return act


# Gains tuned by a grid search on the three references (deadbeat-like for dt = 0.05: kp·dt² ≈ 0.5).
PD_GAINS = {"pd": (200.0, 25.0), "pd_ff": (200.0, 25.0)}


def baselines() -> dict:
    """RMSE of the tuned PD without and with acceleration feed-forward."""
    return {name: evaluate(pd(kp, kd, name == "pd_ff")) for name, (kp, kd) in PD_GAINS.items()}
