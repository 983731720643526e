"""The binary text reconstruction network: a small U-Net sized for one wearable CPU core.

Voxel grid [B,4,100,200] in, ink logits [B,1,100,200] out (``logits > 0`` = ink).

Why this shape (see the latency table in the project's reference notes): at 100x200 a plain
3x3-conv U-Net spends most of its time in memory-bound full-resolution work (wide activations,
resize, concat). So only one narrow layer runs at full resolution; everything else runs at
1/2, 1/4 and 1/8 scale with depthwise-separable blocks; skips are *added* (1x1 projection +
add) instead of concatenated; upsampling is size-based ``interpolate`` so the odd 25 -> 13 step
round-trips exactly (100 is not divisible by 8).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

INPUT_SHAPE: tuple[int, int, int] = (4, 100, 200)
HEADS: tuple[str, ...] = ("full", "shuffle")


@dataclass(frozen=True)
class NetConfig:
    """Widths of the four scales (full, 1/2, 1/4, 1/8) and separable blocks per encoder scale (1/2, 1/4, 1/8)."""

    # the shipped network's: the 1/8 scale (13x25 at 100x200) is where width and depth cost least a
    # window, and its eight blocks see across a word (the network before had 64 wide, four blocks)
    widths: tuple[int, int, int, int] = (8, 16, 32, 96)
    blocks: tuple[int, int, int] = (1, 2, 8)
    in_channels: int = INPUT_SHAPE[0]
    # "full": the last decoder stage at full resolution (resize, add the stem, refine, 1x1 head);
    # "shuffle": it stays at half resolution and a 1x1 head gives each pixel's 2x2 sub-pixel logits,
    # put in place by a pixel shuffle (no full-resolution work after the stem: about a third less time)
    head: str = "shuffle"

    def __post_init__(self) -> None:
        if self.head not in HEADS:
            raise ValueError(f"NetConfig.head must be one of {HEADS}, not {self.head!r}")

    def to_dict(self) -> dict[str, object]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> NetConfig:
        """From a checkpoint's or a run's JSON."""
        values = dict(data)
        values["widths"] = tuple(int(w) for w in values["widths"])
        values["blocks"] = tuple(int(b) for b in values["blocks"])
        values.setdefault("head", "full")  # (checkpoints from before the choice: all full)
        return cls(**values)


def conv_bn_relu(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)
    )


class SeparableBlock(nn.Module):
    """Depthwise 3x3 + pointwise 1x1, residual when shapes allow: most of the receptive field for few MACs."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.depthwise = nn.Sequential(
            nn.Conv2d(cin, cin, 3, padding=1, groups=cin, bias=False), nn.BatchNorm2d(cin), nn.ReLU(inplace=True)
        )
        self.pointwise = nn.Sequential(nn.Conv2d(cin, cout, 1, bias=False), nn.BatchNorm2d(cout))
        self.residual = cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.pointwise(self.depthwise(x))
        return F.relu(y + x if self.residual else y)


class Down(nn.Module):
    """Strided 3x3 conv (halves the size, rounding up) followed by a separable block."""

    def __init__(self, cin: int, cout: int, blocks: int = 1) -> None:
        super().__init__()
        self.reduce = conv_bn_relu(cin, cout, stride=2)
        self.blocks = nn.Sequential(*[SeparableBlock(cout, cout) for _ in range(blocks)])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.blocks(self.reduce(x))


class Up(nn.Module):
    """Project the coarse map to the skip's width, resize to the skip's size, add, refine."""

    def __init__(self, cin: int, cskip: int) -> None:
        super().__init__()
        self.project = nn.Sequential(nn.Conv2d(cin, cskip, 1, bias=False), nn.BatchNorm2d(cskip))
        self.refine = SeparableBlock(cskip, cskip)

    def forward(self, coarse: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        up = F.interpolate(self.project(coarse), size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return self.refine(F.relu(up + skip))


class BinaryUNet(nn.Module):
    """Voxel grid -> ink logits. See the module docstring for why it looks like this."""

    def __init__(self, config: NetConfig | None = None) -> None:
        super().__init__()
        self.config = config or NetConfig()
        w0, w1, w2, w3 = self.config.widths
        self.stem = conv_bn_relu(self.config.in_channels, w0)
        b1, b2, b3 = self.config.blocks
        self.down1 = Down(w0, w1, blocks=b1)
        self.down2 = Down(w1, w2, blocks=b2)
        self.down3 = Down(w2, w3, blocks=b3)
        self.up2 = Up(w3, w2)
        self.up1 = Up(w2, w1)
        if self.config.head == "full":
            self.up0 = Up(w1, w0)
            self.head = nn.Conv2d(w0, 1, 1)
        else:
            self.refine = SeparableBlock(w1, w1)
            self.head = nn.Conv2d(w1, 4, 1)  # the 2x2 sub-pixels' logits, channel = 2 * row + column

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        s0 = self.stem(x)
        s1 = self.down1(s0)
        s2 = self.down2(s1)
        s3 = self.down3(s2)
        y = self.up2(s3, s2)
        y = self.up1(y, s1)
        if self.config.head == "full":
            return self.head(self.up0(y, s0))
        out = F.pixel_shuffle(self.head(self.refine(y)), 2)
        if torch.onnx.is_in_onnx_export():
            return out  # (exported at INPUT_SHAPE, even sides: no slice, so the output keeps fixed sizes)
        return out[..., : x.shape[-2], : x.shape[-1]]  # an odd side comes back one longer


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
