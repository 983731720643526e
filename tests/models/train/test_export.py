from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import torch

from darkread.edge.reconstruct import Reconstructor
from darkread.models.train.export import OPSET, export_onnx, quantize_int8
from darkread.models.train.net import BinaryUNet


def _trained_looking_model() -> BinaryUNet:
    torch.manual_seed(0)
    model = BinaryUNet()
    for module in model.modules():  # non-trivial BatchNorm statistics so folding is exercised
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.2, 0.2)
            module.running_var.uniform_(0.5, 2.0)
    return model.eval()


def test_onnx_matches_torch_on_random_input(tmp_path: Path) -> None:
    model = _trained_looking_model()
    path = export_onnx(model, tmp_path / "net.onnx")
    graph = onnx.load(str(path))
    assert any(op.domain in ("", "ai.onnx") and op.version >= OPSET for op in graph.opset_import)
    x = np.random.default_rng(0).normal(size=(3, 4, 100, 200)).astype(np.float32)
    with torch.no_grad():
        expected = model(torch.from_numpy(x)).numpy()[:, 0]
    got = Reconstructor(path, warmup=0).logits(x)  # batch of 3 through the dynamic axis
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4)


def test_int8_model_stays_close_to_fp32(tmp_path: Path) -> None:
    model = _trained_looking_model()
    fp32 = export_onnx(model, tmp_path / "net.onnx")
    x = np.random.default_rng(1).normal(size=(4, 4, 100, 200)).astype(np.float32)
    int8 = quantize_int8(fp32, tmp_path / "net_int8.onnx", x)
    a = Reconstructor(fp32, warmup=0).logits(x)
    b = Reconstructor(int8, warmup=0).logits(x)
    assert b.shape == a.shape
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.95
