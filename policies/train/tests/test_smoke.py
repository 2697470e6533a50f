"""The training command end to end in --smoke mode (a few thousand steps): every file is written and consistent.
Run it alone with `pytest -m smoke`; it is part of the full suite too."""

import pytest

import train
from test_models import check_model_files


@pytest.mark.smoke
def test_smoke_training_writes_all_files(tmp_path):
    manifest = train.main(["--smoke", "--out", str(tmp_path), "--name", "smoke", "--seed", "5"])
    assert {p.name for p in tmp_path.iterdir()} == {"smoke.onnx", "smoke.json", "smoke.golden.json"}
    assert manifest["smoke"] and manifest["seed"] == 5 and manifest["training_steps"] >= 4096
    assert check_model_files(tmp_path / "smoke.json") == manifest
