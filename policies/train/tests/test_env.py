"""Dynamics, saturation, observation and reward of env.py, and the batched training environment."""

import numpy as np
import pytest

import env
from references import EVAL_NAMES, evaluation, random_reference
from vecenv import TrackingVecEnv


def test_step_is_exact_constant_acceleration_kinematics():
    p, v, u = np.array([1.0, -2.0]), np.array([0.5, 3.0]), np.array([-4.0, 2.0])
    p1, v1 = env.step(p, v, u)
    np.testing.assert_allclose(p1, [1.0 + 0.025 - 0.005, -2.0 + 0.15 + 0.0025], rtol=0, atol=1e-15)
    np.testing.assert_allclose(v1, [0.5 - 0.2, 3.0 + 0.1], rtol=0, atol=1e-15)
    # Exact zero-order hold: two half steps are one full step (Euler would differ by u·dt²/4).
    ph, vh = env.step(*env.step(p, v, u, dt=0.025), u, dt=0.025)
    np.testing.assert_allclose(ph, p1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(vh, v1, rtol=0, atol=1e-15)


def test_saturation_scales_onto_the_ball_keeping_direction():
    np.testing.assert_allclose(env.saturate(np.array([6.0, 8.0])), [3.0, 4.0], atol=1e-15)
    np.testing.assert_array_equal(env.saturate(np.array([1.0, -1.0])), [1.0, -1.0])
    np.testing.assert_array_equal(env.saturate(np.array([5.0, 0.0])), [5.0, 0.0])
    # Per-axis clipping would give (5, 5), outside the ball.
    u = env.saturate(np.array([10.0, 10.0]))
    np.testing.assert_allclose(u, [5 / np.sqrt(2)] * 2, atol=1e-15)
    batch = env.saturate(np.array([[0.0, 0.0], [30.0, -40.0], [np.nan, 1.0], [np.inf, 0.0]]))
    np.testing.assert_allclose(batch, [[0, 0], [3, -4], [0, 0], [0, 0]], atol=1e-15)


def test_observation_layout():
    s = env.observation(np.array([1.0, 2.0]), np.array([3.0, 4.0]), np.array([0.5, -1.0]), np.array([1.0, 1.0]))
    np.testing.assert_array_equal(s, [0.5, 3.0, 2.0, 3.0, 3.0, 4.0])


def test_reward_is_paper_eq16_against_the_reference_at_t_plus_1():
    p, v = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    p_r, v_r = np.array([3.0, 4.0]), np.array([0.0, 0.0])  # ‖p̂‖ = 5, ‖v̂‖ = 1
    p1, v1 = np.array([0.0, 1.0]), np.array([0.0, 2.0])
    p_r1, v_r1 = np.array([0.0, 4.0]), np.array([0.0, 2.0])  # ‖p̂⁺‖ = 3, ‖v̂⁺‖ = 0
    expected = -5.0 * (3.0 - 5.0) - 0.7 * (0.0 - 1.0) - 0.1 * 1.0
    assert env.reward(p, v, p_r, v_r, p1, v1, p_r1, v_r1) == pytest.approx(expected, abs=1e-15)
    w = env.RewardWeights(1.0, 2.0, 3.0)
    assert env.reward(p, v, p_r, v_r, p1, v1, p_r1, v_r1, w) == pytest.approx(2.0 + 2.0 - 3.0, abs=1e-15)


@pytest.mark.parametrize("name", EVAL_NAMES)
def test_evaluation_reference_velocity_is_the_derivative(name):
    ref = evaluation(name)
    assert ref.p.shape == (1001, 2) and np.all(ref.v0 == 0) and np.all(ref.p0 == ref.p[0])
    mid_velocity = (ref.p[1:] - ref.p[:-1]) / env.DT
    smooth = np.linalg.norm(ref.v[1:] - ref.v[:-1], axis=-1) < 0.1  # all but the rectangle's corners
    np.testing.assert_allclose(mid_velocity[smooth], ((ref.v[1:] + ref.v[:-1]) / 2)[smooth], atol=1e-3)
    np.testing.assert_allclose(ref.p[-1], ref.p[0], atol=1e-12)  # one full lap in 50 s


def test_rectangle_corners_and_speeds():
    ref = evaluation("rectangle")
    for k, corner in zip((0, 250, 500, 750, 1000), [(7.5, -5), (7.5, 5), (-7.5, 5), (-7.5, -5), (7.5, -5)]):
        np.testing.assert_allclose(ref.p[k], corner, atol=1e-12)
    np.testing.assert_allclose(ref.v[[0, 249, 250, 500, 750]], [[0, 0.8], [0, 0.8], [-1.2, 0], [0, -0.8], [1.2, 0]])


def test_training_references_are_finite_and_reachable():
    rng = np.random.default_rng(0)
    for _ in range(200):
        ref = random_reference(rng, 300)
        assert ref.p.shape == ref.v.shape == ref.offset.shape == (301, 2) and ref.jump.shape == (301,)
        assert np.all(np.isfinite(ref.p)) and np.all(np.isfinite(ref.v))
        assert np.linalg.norm(ref.p0 - ref.p[0]) <= 5.0 + 1e-12
        assert np.max(np.linalg.norm(ref.v, axis=-1)) <= 3.0 + 1e-9
        assert np.all(np.linalg.norm(ref.offset, axis=-1) <= 5.0 + 1e-12)


def test_vecenv_steps_with_env_functions_and_truncates():
    venv = TrackingVecEnv(n_envs=4, seed=3, episode_steps=5)
    obs = venv.reset()
    assert obs.shape == (4, 6) and obs.dtype == np.float32
    actions = np.array([[2.0, 0.0], [0.3, -0.4], [-1.0, 1.0], [0.0, 0.0]], dtype=np.float32)
    p, v = venv.p.copy(), venv.v.copy()
    p_r, v_r = venv._reference(venv.t, venv.shift)
    p_r1, v_r1 = venv._reference(venv.t + 1, venv.shift)
    np.testing.assert_array_equal(obs, env.observation(p, v, p_r, v_r).astype(np.float32))
    _, rewards, dones, _ = venv.step(actions)
    p1, v1 = env.step(p, v, env.saturate(env.DELTA * actions.astype(np.float64)))
    np.testing.assert_array_equal(venv.p, p1)
    np.testing.assert_allclose(rewards, env.reward(p, v, p_r, v_r, p1, v1, p_r1, v_r1), rtol=1e-6)
    assert not dones.any()
    for _ in range(4):
        _, _, dones, infos = venv.step(actions)
    assert dones.all() and all(i["TimeLimit.truncated"] and i["terminal_observation"].shape == (6,) for i in infos)
    assert np.all(venv.t == 0)
