"""References for training and evaluation.

A `Reference` is a precomputed episode: the reference trajectory (p_r, v_r) at steps 0..T, a schedule of target
jumps, and the UAV's initial state. A jump at step k re-anchors the reference at the UAV: from step k on the agent
sees p_r(j) + shift with shift = p(k) + offset[k] − p_r(k), as when a navigation algorithm hands out a new
temporary target within r_s of the UAV (see env.py for why a jump never enters the reward of the step before it).

Training mixes four kinds: point targets that jump at random intervals (literal Algorithm 1), a "carrot" target
re-placed ahead of the UAV every step (road-aware navigation), Lissajous curves (ellipses, figure-8s) and constant-
speed polylines (rectangles and other corners), with speeds up to 3 m/s. The three evaluation references of the
paper are analytic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from env import DT

R_S = 5.0  # radius of the temporary target around the UAV (m)
V_MAX = 3.0  # fastest training reference (m/s)
KINDS = ("point", "carrot", "lissajous", "polyline")
KIND_PROBS = (0.2, 0.1, 0.35, 0.35)
EVAL_STEPS = 1000  # 50 s


@dataclass
class Reference:
    """One episode: p, v of shape (T+1, 2); jump (T+1,) bool; offset (T+1, 2); initial UAV state p0, v0."""

    p: np.ndarray
    v: np.ndarray
    jump: np.ndarray
    offset: np.ndarray
    p0: np.ndarray
    v0: np.ndarray


def _smooth(p: np.ndarray, v: np.ndarray, p0: np.ndarray | None = None, v0: np.ndarray | None = None) -> Reference:
    n = len(p)
    p0 = p[0].copy() if p0 is None else p0
    return Reference(p, v, np.zeros(n, bool), np.zeros((n, 2)), p0, np.zeros(2) if v0 is None else v0)


def polyline(corners: np.ndarray, durations: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constant velocity along each side corners[i] → corners[i+1] in durations[i] seconds; v is right-continuous
    at the corners, and after the last corner the reference stays there at rest."""
    vel = np.vstack([(corners[1:] - corners[:-1]) / durations[:, None], np.zeros((1, 2))])
    start = np.concatenate([[0.0], np.cumsum(durations)])
    i = np.clip(np.searchsorted(start, t, side="right") - 1, 0, len(corners) - 1)
    return corners[i] + vel[i] * (t - start[i])[:, None], vel[i]


def evaluation(name: str, steps: int = EVAL_STEPS) -> Reference:
    """The paper's references, UAV at rest at the start: 'ellipse', 'figure8' or 'rectangle' (12.5 s per side,
    constant speed along each side: 0.8 m/s on the 10 m sides, 1.2 m/s on the 15 m sides)."""
    t = np.arange(steps + 1) * DT
    w = np.pi / 25.0
    c, s = np.cos(w * t), np.sin(w * t)
    if name == "ellipse":
        p = np.stack([10 * c, 7.5 * s], axis=-1)
        v = np.stack([-10 * w * s, 7.5 * w * c], axis=-1)
    elif name == "figure8":
        p = np.stack([7.5 * s, 7.5 * s * c], axis=-1)
        v = np.stack([7.5 * w * c, 7.5 * w * (c * c - s * s)], axis=-1)
    elif name == "rectangle":
        corners = np.array([[7.5, -5.0], [7.5, 5.0], [-7.5, 5.0], [-7.5, -5.0], [7.5, -5.0]])
        durations = np.full(4, 12.5)
        laps = int(np.ceil(t[-1] / 50.0)) + 1
        corners = np.vstack([corners[:1]] + [corners[1:]] * laps)
        p, v = polyline(corners, np.tile(durations, laps), t)
    else:
        raise ValueError(f"unknown evaluation reference {name!r}")
    return _smooth(p, v)


EVAL_NAMES = ("ellipse", "figure8", "rectangle")


def _disk(rng: np.random.Generator, radius: float) -> np.ndarray:
    """A point at a uniformly drawn distance (not area) from the origin: small offsets are well represented."""
    a = rng.uniform(0, 2 * np.pi)
    return radius * rng.uniform() * np.array([np.cos(a), np.sin(a)])


def _initial_near(rng: np.random.Generator, ref: Reference) -> Reference:
    """Starts the UAV at rest on the reference (as in the evaluation), slightly off it, or far off it."""
    mode = rng.choice(3, p=[0.35, 0.35, 0.3])
    if mode == 0:
        ref.p0, ref.v0 = ref.p[0].copy(), np.zeros(2)
    elif mode == 1:
        ref.p0, ref.v0 = ref.p[0] + _disk(rng, 0.1), ref.v[0] + _disk(rng, 0.2)
    else:
        ref.p0, ref.v0 = ref.p[0] + _disk(rng, R_S), _disk(rng, V_MAX)
    return ref


def _lissajous(rng: np.random.Generator, t: np.ndarray) -> Reference:
    wx = rng.uniform(0.05, 1.2)
    wy = wx * rng.choice([1.0, 2.0, 0.5, rng.uniform(0.3, 3.0)])
    amp = rng.uniform(0.5, 12.0, size=2)
    w = np.array([wx, wy])
    speed, accel = rng.uniform(0.2, V_MAX), rng.uniform(0.1, 3.0)
    amp *= min(1.0, speed / np.linalg.norm(amp * w), accel / np.linalg.norm(amp * w * w))
    phase = rng.uniform(0, 2 * np.pi, size=2)
    arg = t[:, None] * w + phase
    return _smooth(amp * np.sin(arg), amp * w * np.cos(arg))


def _polyline(rng: np.random.Generator, t: np.ndarray) -> Reference:
    n = 4 + int(t[-1] * V_MAX / 1.0)
    turns = np.where(rng.uniform(size=n) < 0.5, rng.choice([-1, 1], size=n) * np.pi / 2, rng.uniform(-np.pi, np.pi, n))
    heading = rng.uniform(0, 2 * np.pi) + np.cumsum(turns)
    lengths = rng.uniform(1.0, 15.0, size=n)
    speeds = np.full(n, rng.uniform(0.2, V_MAX)) if rng.uniform() < 0.5 else rng.uniform(0.2, V_MAX, size=n)
    steps = lengths[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    corners = np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    p, v = polyline(corners, lengths / speeds, t + rng.uniform(0, lengths[0] / speeds[0]))
    return _smooth(p, v)


def _point(rng: np.random.Generator, n: int) -> Reference:
    ref = _smooth(np.zeros((n, 2)), np.zeros((n, 2)), _disk(rng, R_S), _disk(rng, V_MAX) * (rng.uniform() < 0.5))
    k = int(rng.integers(5, 100))
    while k < n:
        ref.jump[k], ref.offset[k] = True, _disk(rng, R_S)
        k += int(rng.integers(5, 100))
    return ref


def _carrot(rng: np.random.Generator, n: int) -> Reference:
    ref = _smooth(np.zeros((n, 2)), np.zeros((n, 2)), _disk(rng, R_S), _disk(rng, V_MAX) * (rng.uniform() < 0.5))
    heading = rng.uniform(0, 2 * np.pi) + np.cumsum(rng.normal(0, rng.uniform(0, 0.1), size=n))
    distance = rng.uniform(0.5, 1.0) * R_S
    arrive = int(rng.integers(n // 3, n + 1))  # the goal comes within reach: the target stops moving
    ref.jump[1:arrive] = True
    ref.offset[:] = distance * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    return ref


def random_reference(rng: np.random.Generator, steps: int) -> Reference:
    """A training episode of `steps` steps drawn from the mix described in the module docstring."""
    kind = KINDS[rng.choice(len(KINDS), p=KIND_PROBS)]
    if kind == "point":
        return _point(rng, steps + 1)
    if kind == "carrot":
        return _carrot(rng, steps + 1)
    t = np.arange(steps + 1) * DT
    return _initial_near(rng, _lissajous(rng, t) if kind == "lissajous" else _polyline(rng, t))
