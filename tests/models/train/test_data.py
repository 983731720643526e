from __future__ import annotations

import numpy as np

from darkread.core.mask_bits import pack_rows, unpack_rows
from darkread.models.train.data import (
    augment,
    is_validation_seed,
    iterate_batches,
    load_dataset,
    load_shard,
    shard_paths,
)


def test_packed_targets_round_trip() -> None:
    targets = (np.random.default_rng(0).random((3, 100, 200)) < 0.2).astype(np.uint8)
    assert np.array_equal(unpack_rows(pack_rows(targets), 200), targets)


def test_shard_loads_with_unpacked_targets_and_metadata(fake_dataset) -> None:
    root = fake_dataset(shards=1, per_shard=5)
    shard = load_shard(shard_paths(root)[0])
    assert shard.voxels.shape == (5, 4, 100, 200) and shard.voxels.dtype == np.float16
    assert shard.targets.shape == (5, 100, 200) and set(np.unique(shard.targets)) <= {0, 1}
    assert shard.targets.any()
    assert list(shard.meta["lux"]) == [1000, 100, 30, 10, 5]


def test_validation_split_depends_only_on_the_seed() -> None:
    seeds = np.arange(10_000)
    held = is_validation_seed(seeds)
    assert 0.03 < held.mean() < 0.08
    assert np.array_equal(is_validation_seed(seeds[::-1]), held[::-1])


def test_train_and_validation_batches_are_disjoint_and_complete(fake_dataset) -> None:
    root = fake_dataset(shards=2, per_shard=30)
    paths = shard_paths(root)
    rng = np.random.default_rng(0)
    n_train = sum(len(x) for x, _ in iterate_batches(paths, 8, rng, augmentation=False))
    n_val = sum(len(x) for x, _ in iterate_batches(paths, 8, rng, validation=True))
    assert n_train + n_val == 60 and n_val == int(is_validation_seed(np.arange(60)).sum())


def test_load_dataset_respects_the_limit(fake_dataset) -> None:
    root = fake_dataset(shards=2, per_shard=6)
    assert len(load_dataset(root)) == 12
    assert len(load_dataset(root, limit=7)) == 7


def test_time_reversal_is_an_involution_and_keeps_the_target() -> None:
    rng = np.random.default_rng(1)
    voxels = rng.normal(size=(16, 4, 10, 12)).astype(np.float32)
    targets = (rng.random((16, 10, 12)) < 0.3).astype(np.uint8)
    once, t_once = augment(voxels, targets, np.random.default_rng(5), max_shift=0)
    assert np.array_equal(t_once, targets)
    changed = ~np.all(once == voxels, axis=(1, 2, 3))
    assert changed.any() and (~changed).any()
    assert np.allclose(once[changed], -voxels[changed][:, ::-1])


def test_shift_moves_voxels_and_targets_together() -> None:
    voxels = np.zeros((1, 4, 20, 30), np.float32)
    targets = np.zeros((1, 20, 30), np.uint8)
    voxels[0, :, 10, 15] = 1
    targets[0, 10, 15] = 1
    out_v, out_t = augment(voxels, targets, np.random.default_rng(3), max_shift=4)
    vy, vx = np.argwhere(np.abs(out_v[0]).sum(0) > 0)[0]
    assert out_t[0, vy, vx] == 1 and out_t.sum() == 1


def test_random_crop_cuts_voxels_and_targets_at_the_same_place() -> None:
    from darkread.models.train.data import random_crop

    rng = np.random.default_rng(0)
    targets = (rng.random((5, 100, 200)) < 0.3).astype(np.uint8)
    voxels = np.repeat(targets[:, None].astype(np.float32), 4, axis=1)
    v, t = random_crop(voxels, targets, (64, 128), rng)
    assert v.shape == (5, 4, 64, 128) and t.shape == (5, 64, 128)
    assert np.array_equal(v[:, 2], t.astype(np.float32))
