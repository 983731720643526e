from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import torch
from darkread.edge.reconstruct import Reconstructor
from darkread.models.train.export import OPSET, export_onnx, linear_resize_matrix, quantize_int8
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


def test_export_has_no_resize_left(tmp_path: Path) -> None:
    graph = onnx.load(str(export_onnx(_trained_looking_model(), tmp_path / "net.onnx"))).graph
    ops = [n.op_type for n in graph.node]
    assert "Resize" not in ops and ops.count("MatMul") == 6  # three upsamplings, rows and columns each


def test_resize_matrix_is_onnxruntimes_linear_resize() -> None:
    """The contract resize_as_matmul relies on, against the op it replaces (odd and even sizes)."""
    import onnxruntime as ort
    from onnx import TensorProto, helper

    for (h, w), (big_h, big_w) in (((13, 25), (25, 50)), ((50, 100), (100, 200)), ((7, 3), (9, 8))):
        node = helper.make_node("Resize", ["x", "", "", "sizes"], ["y"], mode="linear", coordinate_transformation_mode="half_pixel")
        graph = helper.make_graph(
            [node], "resize", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 2, h, w])],
            [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)],
            [helper.make_tensor("sizes", TensorProto.INT64, [4], [1, 2, big_h, big_w])],
        )
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
        x = np.random.default_rng(h).normal(size=(1, 2, h, w)).astype(np.float32)
        want = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"x": x})[0]
        got = linear_resize_matrix(h, big_h) @ x @ linear_resize_matrix(w, big_w).T
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
