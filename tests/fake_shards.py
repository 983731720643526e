"""Shared by tests/models/train and tests/lab/train (their conftest.py bring its fixtures): tiny fake
shards in the synthetic-dataset format: learnable, so a few steps must lower the loss."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

H, W = 100, 200


def fake_samples(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Targets: a few horizontal bars (ink); voxels: the bars' edges in +/- polarity plus noise."""
    rng = np.random.default_rng(seed)
    targets = np.zeros((n, H, W), np.uint8)
    voxels = np.zeros((n, 4, H, W), np.float32)
    for i in range(n):
        for _ in range(3):
            y, x = rng.integers(10, H - 15), rng.integers(10, W - 60)
            targets[i, y : y + 4, x : x + int(rng.integers(10, 50))] = 1
        edges = np.diff(targets[i].astype(np.float32), axis=1, prepend=0)
        for b in range(4):
            voxels[i, b] = np.roll(edges, b - 2, axis=1) + rng.normal(0, 0.3, (H, W)) * (rng.random((H, W)) < 0.02)
    return voxels, targets


def write_fake_shard(path: Path, n: int, seed: int, first_seed: int = 0) -> Path:
    voxels, targets = fake_samples(n, seed)
    np.savez(
        path,
        voxels=voxels.astype(np.float16),
        targets=np.packbits(targets.astype(bool), axis=-1),
        target_shape=np.array([H, W]),
        lux=np.array([1000, 100, 30, 10, 5] * n)[:n].astype(np.float32),
        xheight_px=np.full(n, 12.0, np.float32),
        motion=np.linspace(0, 1, n).astype(np.float32),
        font=np.array(["DejaVuSans"] * n),
        kind=np.array(["line"] * n),
        seed=np.arange(first_seed, first_seed + n, dtype=np.int64),
    )
    return path


@pytest.fixture
def fake_dataset(tmp_path: Path) -> Callable[..., Path]:
    def make(shards: int = 2, per_shard: int = 24, name: str = "data") -> Path:
        root = tmp_path / name
        root.mkdir()
        for s in range(shards):
            write_fake_shard(root / f"shard-{s:05d}.npz", per_shard, seed=s, first_seed=s * per_shard)
        return root

    return make


@pytest.fixture
def shard_writer() -> Callable[..., Path]:
    """``write_fake_shard(path, n, seed)`` for tests that make datasets their own way."""
    return write_fake_shard
