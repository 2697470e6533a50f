"""The shipped models in policies/models: manifest hash, golden pairs, recorded evaluation."""

import json
from pathlib import Path

import numpy as np
import pytest

import policy as pol

MODELS = Path(__file__).resolve().parents[2] / "models"
MANIFESTS = sorted(p for p in MODELS.glob("*.json") if not p.name.endswith(".golden.json"))


def check_model_files(manifest_path: Path) -> dict:
    """Asserts a manifest, its ONNX file and its golden pairs agree; returns the manifest."""
    manifest = json.loads(manifest_path.read_text())
    onnx_path = manifest_path.parent / manifest["model"]
    assert pol.sha256(onnx_path) == manifest["sha256"]
    golden = json.loads((manifest_path.parent / manifest["golden"]).read_text())
    assert golden["sha256"] == manifest["sha256"] and len(golden["pairs"]) >= 32
    obs = np.array([p["obs"] for p in golden["pairs"]], dtype=np.float32)
    u = np.array([p["u"] for p in golden["pairs"]], dtype=np.float32)
    np.testing.assert_allclose(pol.OnnxPolicy(onnx_path)(obs), u, rtol=0, atol=golden["tolerance"])
    for name in ("ellipse", "figure8", "rectangle"):
        assert set(manifest["evaluation"]["policy"][name]) >= {"total", "x", "y"}
    return manifest


@pytest.mark.skipif(not MANIFESTS, reason=f"no trained model in {MODELS}: run train.py")
@pytest.mark.parametrize("manifest_path", MANIFESTS, ids=[p.stem for p in MANIFESTS])
def test_shipped_model(manifest_path):
    manifest = check_model_files(manifest_path)
    assert not manifest["smoke"] and manifest["training_steps"] > 0
