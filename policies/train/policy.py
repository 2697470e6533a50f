"""The PPO policy (two hidden layers of 128 units) and its export to a self-contained ONNX graph.

The graph computes the deterministic action in m/s² with everything folded in:

    obs [N,6] float32 ─Mul(obs_scale)─Gemm─Tanh─Gemm─Tanh─Gemm─Clip(-1,1)─Mul(δ)→ u [N,2] float32

so u = δ·clip(μ(s), -1, 1) lies in the box [-δ, δ]² but may leave the ball ‖u‖ ≤ δ: the consumer applies the norm
saturation, exactly as the training environment did (vecenv.py). Only Mul, Gemm, Tanh and Clip appear (opset 13,
IR version 8), which tract-onnx and onnxruntime both load.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from gymnasium import spaces
from onnx import TensorProto, helper, numpy_helper
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

import env

OPSET = 13
IR_VERSION = 8
# Inverse scales of s = [p − p_r, v − v_r, v]: errors of centimetres must move the first layer.
OBS_SCALE = (10.0, 10.0, 3.0, 3.0, 0.5, 0.5)


class ScaledObservation(BaseFeaturesExtractor):
    """Multiplies the raw observation by fixed constants (no trainable weights)."""

    def __init__(self, observation_space: spaces.Box, scale=OBS_SCALE):
        super().__init__(observation_space, features_dim=observation_space.shape[0])
        self.register_buffer("scale", torch.tensor(scale, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return obs * self.scale


def policy_kwargs(obs_scale=OBS_SCALE, log_std_init: float = -1.2) -> dict:
    """SB3 policy_kwargs of the tracking policy: tanh MLPs, 2×128 for both policy and value."""
    return {
        "net_arch": {"pi": [128, 128], "vf": [128, 128]},
        "activation_fn": torch.nn.Tanh,
        "features_extractor_class": ScaledObservation,
        "features_extractor_kwargs": {"scale": tuple(obs_scale)},
        "log_std_init": log_std_init,
    }


def make_actor_odd(policy: ActorCriticPolicy) -> None:
    """Zeroes and freezes the biases of the actor (mean network), making μ an odd function: μ(−s) = −μ(s), μ(0) = 0.

    The task is symmetric under point reflection (p, v, p_r, v_r, u → their negatives leave dynamics, reward and the
    training distribution unchanged), so the optimal policy is odd; enforcing it removes the small zero-error offset
    a free network keeps, which would otherwise show as a constant millimetre tracking bias."""
    for layer in _layers(policy):
        if isinstance(layer, torch.nn.Linear):
            with torch.no_grad():
                layer.bias.zero_()
            layer.bias.requires_grad_(False)


def deterministic_action(policy: ActorCriticPolicy, obs: np.ndarray) -> np.ndarray:
    """What the ONNX graph computes, evaluated by torch: δ·clip(μ(obs), -1, 1) in m/s²."""
    with torch.no_grad():
        mean = policy.get_distribution(torch.as_tensor(obs, dtype=torch.float32)).distribution.mean
    return env.DELTA * np.clip(mean.numpy(), -1.0, 1.0)


def _layers(policy: ActorCriticPolicy) -> list[torch.nn.Module]:
    return [*policy.mlp_extractor.policy_net, policy.action_net]


def to_onnx(policy: ActorCriticPolicy) -> onnx.ModelProto:
    """Builds the ONNX graph of the deterministic action from the policy's weights."""
    init = [numpy_helper.from_array(policy.features_extractor.scale.numpy(), "obs_scale")]
    nodes = [helper.make_node("Mul", ["obs", "obs_scale"], ["x0"])]
    x = "x0"
    for i, layer in enumerate(_layers(policy)):
        y = f"x{i + 1}"
        if isinstance(layer, torch.nn.Linear):
            w, b = (t.detach().numpy().astype(np.float32) for t in (layer.weight, layer.bias))
            init += [numpy_helper.from_array(w, f"w{i}"), numpy_helper.from_array(b, f"b{i}")]
            nodes.append(helper.make_node("Gemm", [x, f"w{i}", f"b{i}"], [y], transB=1))
        elif isinstance(layer, torch.nn.Tanh):
            nodes.append(helper.make_node("Tanh", [x], [y]))
        elif isinstance(layer, torch.nn.ReLU):
            nodes.append(helper.make_node("Relu", [x], [y]))
        else:
            raise TypeError(f"cannot export layer {layer!r}")
        x = y
    for name, value in (("lo", -1.0), ("hi", 1.0), ("delta", env.DELTA)):
        init.append(numpy_helper.from_array(np.array(value, np.float32), name))
    nodes.append(helper.make_node("Clip", [x, "lo", "hi"], ["mean_clipped"]))
    nodes.append(helper.make_node("Mul", ["mean_clipped", "delta"], ["u"]))
    graph = helper.make_graph(
        nodes,
        "airroads_tracker",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["N", 6])],
        [helper.make_tensor_value_info("u", TensorProto.FLOAT, ["N", 2])],
        init,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="airroads-train")
    model.ir_version = IR_VERSION
    onnx.checker.check_model(model, full_check=True)
    return model


def export(policy: ActorCriticPolicy, path: Path) -> str:
    """Writes the ONNX file; returns its sha256 (hex)."""
    path.write_bytes(to_onnx(policy).SerializeToString())
    return sha256(path)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


class OnnxPolicy:
    """The exported graph run by onnxruntime on one CPU thread: obs (N, 6) float32 → u (N, 2) float32."""

    def __init__(self, path: Path):
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])

    def __call__(self, obs: np.ndarray, accel_ff: np.ndarray | None = None) -> np.ndarray:
        """`accel_ff` is ignored: the signature is evaluate.Controller's."""
        return self.session.run(["u"], {"obs": np.asarray(obs, dtype=np.float32)})[0]
