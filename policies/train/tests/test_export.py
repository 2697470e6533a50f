"""The ONNX export: same numbers as the torch policy, only plain ops, the agreed names and shapes."""

import numpy as np
import onnx
import pytest
import torch
from stable_baselines3 import PPO

import policy as pol
from vecenv import TrackingVecEnv

ALLOWED_OPS = {"Gemm", "MatMul", "Add", "Tanh", "Relu", "Mul", "Clip"}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    torch.manual_seed(0)
    model = PPO("MlpPolicy", TrackingVecEnv(2, seed=0), policy_kwargs=pol.policy_kwargs(), device="cpu", seed=0)
    with torch.no_grad():  # a fresh action head outputs ~0: widen it so the Clip is exercised too
        model.policy.action_net.weight.mul_(300.0)
    path = tmp_path_factory.mktemp("export") / "p.onnx"
    digest = pol.export(model.policy, path)
    return model.policy, path, digest


def test_onnx_equals_torch_policy(exported):
    policy, path, _ = exported
    rng = np.random.default_rng(1)
    obs = (rng.normal(size=(512, 6)) * [2, 2, 1.5, 1.5, 1.5, 1.5]).astype(np.float32)
    u_torch = pol.deterministic_action(policy, obs)
    u_onnx = pol.OnnxPolicy(path)(obs)
    assert u_onnx.dtype == np.float32 and u_onnx.shape == (512, 2)
    np.testing.assert_allclose(u_onnx, u_torch, rtol=0, atol=1e-5)
    assert np.any(np.abs(u_onnx) == 5.0) and np.any(np.abs(u_onnx) < 4.0)  # both clipped and linear outputs


def test_graph_contract(exported):
    _, path, digest = exported
    model = onnx.load(str(path))
    assert {n.op_type for n in model.graph.node} <= ALLOWED_OPS
    assert all(o.version <= 17 for o in model.opset_import if o.domain in ("", "ai.onnx"))
    (inp,), (out,) = model.graph.input, model.graph.output
    assert (inp.name, out.name) == ("obs", "u")
    for value, width in ((inp, 6), (out, 2)):
        dims = value.type.tensor_type.shape.dim
        assert value.type.tensor_type.elem_type == onnx.TensorProto.FLOAT
        assert dims[0].dim_param == "N" and dims[1].dim_value == width
    assert digest == pol.sha256(path)


@pytest.mark.parametrize("batch", [1, 3, 64])
def test_dynamic_batch(exported, batch):
    _, path, _ = exported
    obs = np.linspace(-3, 3, batch * 6, dtype=np.float32).reshape(batch, 6)
    assert pol.OnnxPolicy(path)(obs).shape == (batch, 2)


def test_odd_actor_stays_odd_through_training():
    model = PPO("MlpPolicy", TrackingVecEnv(2, seed=1), n_steps=64, batch_size=64, n_epochs=2,
                policy_kwargs=pol.policy_kwargs(), device="cpu", seed=1)
    pol.make_actor_odd(model.policy)
    model.learn(total_timesteps=128)
    obs = np.random.default_rng(2).normal(size=(64, 6)).astype(np.float32)
    u, u_neg = (pol.deterministic_action(model.policy, x) for x in (obs, -obs))
    np.testing.assert_allclose(u_neg, -u, rtol=0, atol=1e-6)
    assert np.all(pol.deterministic_action(model.policy, np.zeros((1, 6), np.float32)) == 0.0)
