"""`train compare` on a tiny case: two models on a shard directory, numbers checked against a direct count."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from darkread.models.train.compare import compare
from darkread.models.train.data import load_dataset
from darkread.models.train.evaluate import predict_onnx
from darkread.models.train.export import export_onnx
from darkread.models.train.ink_scores import ink_scores
from darkread.models.train.net import BinaryUNet


@pytest.fixture(scope="module")
def two_models(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("models")
    out = {}
    for i, name in enumerate(("shipped", "tuned")):
        torch.manual_seed(i)
        model = BinaryUNet().eval()
        with torch.no_grad():
            model.head.bias.fill_(0.3 * (i - 0.5))  # one predicts more ink than the other
        out[name] = export_onnx(model, root / f"{name}.onnx")
    return out


def test_compare_scores_each_model_on_a_shard_directory(tmp_path, two_models, shard_writer) -> None:
    data = tmp_path / "val"
    data.mkdir()
    shard_writer(data / "shard-00000.npz", 6, 0)
    report = compare([data], two_models, tmp_path / "out", read=False, progress=False)
    truth = load_dataset(data)
    for name, path in two_models.items():
        expected = ink_scores(predict_onnx(path, truth.voxels), truth.targets)["f1"]
        assert report["rows"][0][name]["ink"]["f1"] == pytest.approx(expected, abs=1e-4)
        assert report["summary"][0][f"{name}_ink_f1"] == pytest.approx(expected, abs=1e-4)
    assert report["summary"][0]["windows"] == 6 and "read" not in report["rows"][0]["tuned"]
    saved = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert saved["models"]["tuned"]["sha256_12"] != saved["models"]["shipped"]["sha256_12"]
    table = (tmp_path / "out" / "compare.md").read_text()
    assert "| val | 1 | 6 |" in table and (tmp_path / "out" / "compare.png").stat().st_size > 1000
