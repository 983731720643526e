from __future__ import annotations

import pytest
import torch

from darkread.models.train.net import (
    INPUT_SHAPE,
    BinaryUNet,
    NetConfig,
    count_parameters,
)


def test_output_is_one_logit_map_per_window() -> None:
    model = BinaryUNet().eval()
    with torch.no_grad():
        out = model(torch.randn(2, *INPUT_SHAPE))
    assert out.shape == (2, 1, 100, 200)
    assert out.dtype == torch.float32


def test_sized_for_a_wearable_cpu() -> None:
    assert count_parameters(BinaryUNet()) <= 1_000_000


@pytest.mark.parametrize("height,width", [(100, 200), (104, 200), (37, 61)])
def test_odd_sizes_round_trip_through_the_pyramid(height: int, width: int) -> None:
    with torch.no_grad():
        out = BinaryUNet().eval()(torch.zeros(1, 4, height, width))
    assert out.shape == (1, 1, height, width)


def test_config_round_trips_through_a_dict() -> None:
    config = NetConfig(widths=(4, 8, 16, 32), blocks=(1, 1, 1))
    assert NetConfig.from_dict(config.to_dict()) == config
    assert count_parameters(BinaryUNet(config)) < count_parameters(BinaryUNet())


@pytest.mark.parametrize("height,width", [(100, 200), (64, 128), (37, 61)])
def test_shuffle_head_gives_one_logit_per_pixel_at_any_size(height: int, width: int) -> None:
    with torch.no_grad():
        out = BinaryUNet(NetConfig(head="shuffle")).eval()(torch.zeros(1, 4, height, width))
    assert out.shape == (1, 1, height, width)


def test_shuffle_head_puts_each_sub_pixel_in_its_place() -> None:
    """Channel 2 * row + column of the half-resolution head is that corner of each 2x2 block."""
    model = BinaryUNet(NetConfig(head="shuffle")).eval()
    with torch.no_grad():
        model.head.weight.zero_()
        model.head.bias.copy_(torch.tensor([0.0, 1.0, 2.0, 3.0]))
        out = model(torch.randn(1, 4, 100, 200))[0, 0]
    assert torch.equal(out[:2, :2], torch.tensor([[0.0, 1.0], [2.0, 3.0]]))
    assert torch.equal(out[98:, 198:], out[:2, :2])


def test_shuffle_head_has_no_full_resolution_decoder() -> None:
    model = BinaryUNet(NetConfig(head="shuffle"))
    assert not hasattr(model, "up0")
    assert model.head.out_channels == 4


def test_head_round_trips_and_defaults_to_full_for_older_configs() -> None:
    config = NetConfig(head="shuffle")
    assert NetConfig.from_dict(config.to_dict()) == config
    older = NetConfig().to_dict()
    del older["head"]
    assert NetConfig.from_dict(older).head == "full"
    with pytest.raises(ValueError, match="head"):
        NetConfig(head="wide")
