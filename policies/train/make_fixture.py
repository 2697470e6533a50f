"""Writes rollouts of the Python environment in the parity-fixture format (for comparisons and debugging).

    "$PY" policies/train/make_fixture.py --out /tmp/rollouts.python.json

The committed fixtures/rollouts.json is written by the Rust simulator
(`AIRROADS_WRITE_FIXTURE=1 cargo test -p policies --test parity_fixture`, which also fails when it is stale);
tests/test_parity.py replays every rollout with env.py and matches each number to 1e-9. Format:

    {"dt", "delta", "reward": {"lambda_s1", "lambda_s2", "lambda_o"},
     "rollouts": [{"p0", "v0", "steps": [{"p_r", "v_r", "p_r_next", "v_r_next", "u_raw", "u",
                                          "p", "v",   # state after the step
                                          "obs",      # observation before the step, w.r.t. p_r, v_r
                                          "reward"}]}]}

The three rollouts here: a point target with a jump (p_r_next keeps the old target on the step before the jump),
the ellipse tracked from rest by a PD controller, and random raw inputs up to 20 m/s² against a moving reference
(exercising the saturation).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import env
from references import evaluation

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "rollouts.json"


def _rollout(p0, v0, refs, controller) -> dict:
    """refs: list of (p_r, v_r, p_r_next, v_r_next) per step; controller(obs) -> u_raw."""
    p, v = np.asarray(p0, float), np.asarray(v0, float)
    steps = []
    for p_r, v_r, p_r_next, v_r_next in refs:
        obs = env.observation(p, v, p_r, v_r)
        u_raw = controller(obs)
        u = env.saturate(u_raw)
        p_next, v_next = env.step(p, v, u)
        r = env.reward(p, v, p_r, v_r, p_next, v_next, p_r_next, v_r_next)
        row = dict(p_r=p_r, v_r=v_r, p_r_next=p_r_next, v_r_next=v_r_next, u_raw=u_raw, u=u, p=p_next, v=v_next)
        row = {k: [float(x) for x in a] for k, a in row.items()}
        steps.append(row | {"obs": [float(x) for x in obs], "reward": float(r)})
        p, v = p_next, v_next
    return {"p0": [float(x) for x in p0], "v0": [float(x) for x in v0], "steps": steps}


def _pd(kp: float, kd: float):
    return lambda obs: -kp * obs[0:2] - kd * obs[2:4]


def rollouts() -> list[dict]:
    zero = np.zeros(2)
    a, b = np.array([3.0, 4.0]), np.array([-2.0, 1.5])
    jump = [(a, zero, a, zero)] * 12 + [(b, zero, b, zero)] * 12
    ell = evaluation("ellipse", steps=30)
    track = [(ell.p[k], ell.v[k], ell.p[k + 1], ell.v[k + 1]) for k in range(30)]
    rng = np.random.default_rng(7)
    t = np.arange(21) * env.DT
    line_p = np.stack([1.0 + 0.8 * t, -2.0 + 0.3 * t], axis=-1)
    line_v = np.tile([0.8, 0.3], (21, 1))
    line = [(line_p[k], line_v[k], line_p[k + 1], line_v[k + 1]) for k in range(20)]
    return [
        _rollout([0.0, 0.0], [1.0, -0.5], jump, _pd(20.0, 8.0)),
        _rollout(ell.p0, ell.v0, track, _pd(200.0, 25.0)),
        _rollout([1.2, -1.9], [0.0, 0.5], line, lambda obs: rng.uniform(-20.0, 20.0, size=2)),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help=f"output file (not {FIXTURE.name}: Rust writes that)")
    args = ap.parse_args()
    doc = {"dt": env.DT, "delta": env.DELTA, "reward": env.RewardWeights().as_dict(), "rollouts": rollouts()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc) + "\n")
    print(f"wrote {args.out}: {len(doc['rollouts'])} rollouts")


if __name__ == "__main__":
    main()
