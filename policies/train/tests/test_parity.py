"""Replays the reference rollouts of fixtures/rollouts.json (written by the Rust simulator)
with env.py's step, saturation, observation and reward, and matches every number to 1e-9."""

import json

import numpy as np
import pytest

import env
from make_fixture import FIXTURE

TOL = 1e-9


@pytest.fixture(scope="module")
def fixture():
    if not FIXTURE.exists():
        pytest.fail(f"{FIXTURE} is absent: AIRROADS_WRITE_FIXTURE=1 cargo test -p policies --test parity_fixture")
    return json.loads(FIXTURE.read_text())


def test_constants_match(fixture):
    assert fixture["dt"] == env.DT and fixture["delta"] == env.DELTA
    assert fixture["reward"] == env.RewardWeights().as_dict()
    assert fixture["rollouts"] and all(r["steps"] for r in fixture["rollouts"])


def test_replay_matches_every_number(fixture):
    w = env.RewardWeights(**fixture["reward"])
    for i, rollout in enumerate(fixture["rollouts"]):
        p, v = np.array(rollout["p0"]), np.array(rollout["v0"])
        for k, s in enumerate(rollout["steps"]):
            where = f"rollout {i} step {k}"
            ref = {key: np.array(s[key]) for key in ("p_r", "v_r", "p_r_next", "v_r_next", "u_raw")}
            obs = env.observation(p, v, ref["p_r"], ref["v_r"])
            np.testing.assert_allclose(obs, s["obs"], rtol=0, atol=TOL, err_msg=f"{where}: obs")
            u = env.saturate(ref["u_raw"], fixture["delta"])
            np.testing.assert_allclose(u, s["u"], rtol=0, atol=TOL, err_msg=f"{where}: u")
            p1, v1 = env.step(p, v, u, fixture["dt"])
            np.testing.assert_allclose(p1, s["p"], rtol=0, atol=TOL, err_msg=f"{where}: p")
            np.testing.assert_allclose(v1, s["v"], rtol=0, atol=TOL, err_msg=f"{where}: v")
            r = env.reward(p, v, ref["p_r"], ref["v_r"], p1, v1, ref["p_r_next"], ref["v_r_next"], w)
            assert abs(r - s["reward"]) <= TOL, f"{where}: reward {r} != {s['reward']}"
            p, v = p1, v1
