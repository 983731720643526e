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
