"""The shipped ONNX read back into torch: same logits, and a clear error for a file that is not this network."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from darkread.models.train.export import export_onnx
from darkread.models.train.net import BinaryUNet, NetConfig
from darkread.models.train.onnx_weights import OnnxWeightsError, max_output_difference, model_from_onnx, onnx_config

SHIPPED = Path(__file__).resolve().parents[3] / "models" / "binary_unet.onnx"


def sparse_voxels(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(n, 4, 100, 200)) * (rng.random((n, 4, 100, 200)) < 0.05)).astype(np.float32)


def test_shipped_onnx_loads_into_torch_with_identical_outputs() -> None:
    if not SHIPPED.is_file():
        pytest.skip("no shipped model")
    model = model_from_onnx(SHIPPED)
    assert max_output_difference(model, SHIPPED, sparse_voxels(2, 0)) < 1e-4


def test_export_then_load_round_trips_folded_batchnorm(tmp_path: Path) -> None:
    torch.manual_seed(1)
    original = BinaryUNet()
    for module in original.modules():  # non-trivial statistics: the exporter folds them into the convolutions
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.3, 0.3)
            module.running_var.uniform_(0.5, 2.0)
            module.weight.data.uniform_(0.5, 1.5)
            module.bias.data.uniform_(-0.2, 0.2)
    path = export_onnx(original.eval(), tmp_path / "net.onnx")
    loaded = model_from_onnx(path)
    x = torch.from_numpy(sparse_voxels(2, 1))
    with torch.no_grad():
        np.testing.assert_allclose(loaded(x).numpy(), original(x).numpy(), atol=1e-4)
    # the loaded net is trainable torch again: a gradient reaches the first convolution
    loaded.train()(x).mean().backward()
    assert loaded.stem[0].weight.grad is not None and float(loaded.stem[0].weight.grad.abs().sum()) > 0


@pytest.mark.parametrize("config", [NetConfig(), NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1)),
                                    NetConfig(widths=(8, 24, 32, 48), blocks=(2, 1, 3), head="shuffle")])
def test_a_file_says_which_network_it_is(config: NetConfig, tmp_path: Path) -> None:
    path = export_onnx(BinaryUNet(config).eval(), tmp_path / "net.onnx")
    assert onnx_config(path) == config
    assert model_from_onnx(path).config == config


def test_other_widths_or_a_non_onnx_file_are_refused(tmp_path: Path) -> None:
    small = export_onnx(BinaryUNet(NetConfig(widths=(4, 8, 16, 16))).eval(), tmp_path / "small.onnx")
    with pytest.raises(OnnxWeightsError, match="not this architecture"):
        model_from_onnx(small, NetConfig())  # read as the shipped widths it does not have
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model at all")
    with pytest.raises(OnnxWeightsError, match="not"):
        model_from_onnx(junk)
    with pytest.raises(FileNotFoundError):
        model_from_onnx(tmp_path / "missing.onnx")


def test_a_shuffle_head_starts_from_the_shipped_layers_it_shares() -> None:
    if not SHIPPED.is_file():
        pytest.skip("no shipped model")
    full, shuffle = model_from_onnx(SHIPPED), model_from_onnx(SHIPPED, NetConfig(head="shuffle"))
    shared = {k: v for k, v in shuffle.state_dict().items() if not k.startswith(("refine.", "head."))}
    assert shared and all(torch.equal(v, full.state_dict()[k]) for k, v in shared.items())
    assert shuffle.head.weight.shape == (4, 16, 1, 1)  # fresh: the shipped head has one output at full resolution


def test_an_exported_shuffle_network_round_trips_exactly(tmp_path: Path) -> None:
    torch.manual_seed(2)
    original = BinaryUNet(NetConfig(head="shuffle")).eval()
    path = export_onnx(original, tmp_path / "shuffle.onnx")
    loaded = model_from_onnx(path)  # the file says which head it has
    assert loaded.config.head == "shuffle"
    assert max_output_difference(loaded, path, sparse_voxels(2, 3)) < 1e-4
    as_full = model_from_onnx(path, NetConfig(head="full"))  # a start for the other head: the shared layers only
    assert torch.equal(as_full.stem[0].weight, loaded.stem[0].weight)
    assert not torch.equal(as_full.head.weight[:, :1], loaded.head.weight[:1, :1])
