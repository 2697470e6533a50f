"""The files written next to `<name>.onnx`: the golden input/output pairs and the manifest."""

from __future__ import annotations

import json
import platform
from importlib.metadata import version
from pathlib import Path

import numpy as np

import env
import policy as pol
from evaluate import rollout
from references import EVAL_NAMES, evaluation

GOLDEN_COUNT = 32
GOLDEN_TOLERANCE = 1e-5
PACKAGES = ("numpy", "torch", "gymnasium", "stable-baselines3", "onnx", "onnxruntime")

CONTRACT = {
    "input": {
        "name": "obs",
        "shape": ["N", 6],
        "dtype": "float32",
        "layout": ["p_x - p_r_x", "p_y - p_r_y", "v_x - v_r_x", "v_y - v_r_y", "v_x", "v_y"],
        "units": "m, m/s; world frame",
    },
    "output": {
        "name": "u",
        "shape": ["N", 2],
        "dtype": "float32",
        "meaning": "deterministic acceleration command (m/s^2) = delta * clip(mu, -1, 1) per axis; it lies in "
        "[-delta, delta]^2 and may leave the ball: the consumer applies u * min(1, delta / |u|) before stepping",
    },
    "dt": env.DT,
    "delta": env.DELTA,
    "dynamics": "p' = p + v dt + u (dt^2 / 2), v' = v + u dt (exact zero-order hold, float64)",
    "target": "p_r within r_s = 5 m of the UAV; v_r = 0 for point navigation, the reference velocity for tracking",
}


def _golden_observations(act, rng: np.random.Generator) -> np.ndarray:
    """Half along the evaluation runs (small errors, the regime that matters), half random (large errors, clipping)."""
    refs = [evaluation(name, steps=60) for name in EVAL_NAMES]
    seen: list[np.ndarray] = []

    def recording(obs, accel_ff):
        seen.append(obs)
        return act(obs, accel_ff)

    rollout(recording, refs)
    states = np.stack(seen, axis=1).reshape(-1, 6)  # reference by reference
    along = states[np.linspace(0, len(states) - 1, GOLDEN_COUNT // 2).astype(int)]
    far = rng.uniform(-1, 1, size=(GOLDEN_COUNT - len(along), 6)) * np.array([5, 5, 4, 4, 3, 3])
    return np.concatenate([along, far]).astype(np.float32)


def write_golden(path: Path, onnx_path: Path, seed: int) -> None:
    """obs → u pairs computed by onnxruntime in float32; floats are written as the exact float32 values."""
    act = pol.OnnxPolicy(onnx_path)
    obs = _golden_observations(act, np.random.default_rng(seed))
    u = act(obs)
    head = {"model": onnx_path.name, "sha256": pol.sha256(onnx_path), "input": "obs", "output": "u"}
    head["tolerance"] = GOLDEN_TOLERANCE
    pairs = [json.dumps({"obs": [float(x) for x in o], "u": [float(x) for x in a]}) for o, a in zip(obs, u)]
    # one pair per line
    path.write_text(json.dumps(head)[:-1] + ', "pairs": [\n ' + ",\n ".join(pairs) + "\n]}\n")


def versions() -> dict:
    return {"python": platform.python_version(), **{name: version(name) for name in PACKAGES}}


def write_manifest(path: Path, onnx_path: Path, **fields) -> dict:
    """Writes the manifest: file hash and contract, plus whatever the caller records (seed, steps, evaluation, ...);
    returns it as read back from JSON."""
    doc = {
        "model": onnx_path.name,
        "sha256": pol.sha256(onnx_path),
        "golden": onnx_path.with_suffix(".golden.json").name,
        "contract": CONTRACT,
        "onnx": {"opset": pol.OPSET, "ir_version": pol.IR_VERSION, "ops": ["Mul", "Gemm", "Tanh", "Clip"]},
        "versions": versions(),
        **fields,
    }
    text = json.dumps(doc, indent=1)
    path.write_text(text + "\n")
    return json.loads(text)
