"""A batched stable-baselines3 VecEnv of the tracking task: all UAVs step together in numpy (no per-env Python).

The agent's action a ∈ [-1, 1]² (SB3 clips its Gaussian samples to the box per axis) is scaled to u_raw = δ·a,
then the environment applies the norm saturation ‖u‖ ≤ δ of env.saturate. The exported ONNX graph reproduces
u_raw = δ·clip(μ, -1, 1) for the deterministic action μ, so the Rust side's saturation gives the same u.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv

import env
from references import Reference, random_reference

EPISODE_STEPS = 300


class TrackingVecEnv(VecEnv):
    """`n_envs` independent episodes of `episode_steps` steps, each drawn by references.random_reference.
    Episodes end by truncation only, flagged for SB3 bootstrapping."""

    def __init__(
        self,
        n_envs: int,
        seed: int,
        episode_steps: int = EPISODE_STEPS,
        weights: env.RewardWeights = env.RewardWeights(),
    ):
        obs_space = gym.spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float32)
        act_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.render_mode = None
        super().__init__(n_envs, obs_space, act_space)
        self.rng = np.random.default_rng(seed)
        self.steps, self.weights = episode_steps, weights
        n, m = n_envs, episode_steps + 1
        self.ref_p, self.ref_v = np.zeros((n, m, 2)), np.zeros((n, m, 2))
        self.jump, self.offset = np.zeros((n, m), bool), np.zeros((n, m, 2))
        self.p, self.v, self.shift = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2))
        self.t = np.zeros(n, dtype=np.int64)
        self.actions = np.zeros((n, 2))

    def _load(self, i: int, ref: Reference) -> None:
        self.ref_p[i], self.ref_v[i], self.jump[i], self.offset[i] = ref.p, ref.v, ref.jump, ref.offset
        self.p[i], self.v[i], self.shift[i], self.t[i] = ref.p0, ref.v0, 0.0, 0

    def _reference(self, t: np.ndarray, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.arange(self.num_envs)
        return self.ref_p[idx, t] + shift, self.ref_v[idx, t]

    def _obs(self) -> np.ndarray:
        p_r, v_r = self._reference(self.t, self.shift)
        return env.observation(self.p, self.v, p_r, v_r).astype(np.float32)

    def reset(self) -> np.ndarray:
        for i in range(self.num_envs):
            self._load(i, random_reference(self.rng, self.steps))
        return self._obs()

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.asarray(actions, dtype=np.float64)

    def step_wait(self):
        idx = np.arange(self.num_envs)
        p_r, v_r = self._reference(self.t, self.shift)
        p_r_next, v_r_next = self._reference(self.t + 1, self.shift)
        u = env.saturate(env.DELTA * self.actions)
        p, v = env.step(self.p, self.v, u)
        rewards = env.reward(self.p, self.v, p_r, v_r, p, v, p_r_next, v_r_next, self.weights)
        self.p, self.v, self.t = p, v, self.t + 1
        jumped = self.jump[idx, self.t]
        new_shift = p + self.offset[idx, self.t] - self.ref_p[idx, self.t]
        self.shift = np.where(jumped[:, None], new_shift, self.shift)
        obs = self._obs()
        dones = self.t >= self.steps
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            infos[i] = {"terminal_observation": obs[i].copy(), "TimeLimit.truncated": True}
            self._load(i, random_reference(self.rng, self.steps))
        if dones.any():
            obs = self._obs()
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list[Any]:
        raise NotImplementedError("TrackingVecEnv has no per-environment objects")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)
