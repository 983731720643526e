"""The markers' ignore mask (made by annotate: tests/models/train/test_annotate.py) is stored in shards
so that old shards still load, and the fine-tuning loss and score leave it out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from darkread.models.synth.shards import SampleMeta, write_shard
from darkread.models.train.data import IGNORE_LABEL, augment, labels, load_dataset, load_shard, random_crop, split_labels


def meta(n: int) -> list[SampleMeta]:
    return [SampleMeta(lux=10.0, motion="normal", kind="marker_page", font="f", xheight_px=9.0, seed=i, x0=0, y0=0,
                       t_end_us=i, n_events=1600) for i in range(n)]


def test_shards_with_and_without_a_mask_load_and_concatenate(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    voxels = rng.normal(size=(3, 4, 100, 200)).astype(np.float32)
    targets = (rng.random((3, 100, 200)) < 0.2).astype(np.uint8)
    ignore = np.zeros_like(targets)
    ignore[:, :20, 50:130] = 1
    (tmp_path / "new").mkdir()
    (tmp_path / "old").mkdir()
    write_shard(tmp_path / "new" / "shard-00000.npz", voxels, targets, meta(3), ignore=ignore)
    write_shard(tmp_path / "old" / "shard-00000.npz", voxels[:2], targets[:2], meta(2))  # as every shard before
    new, old = load_shard(tmp_path / "new" / "shard-00000.npz"), load_shard(tmp_path / "old" / "shard-00000.npz")
    assert np.array_equal(new.ignore, ignore) and np.array_equal(new.targets, targets)
    assert old.ignore is None and np.array_equal(old.ignore_or_none(), np.zeros_like(targets[:2]))
    assert np.array_equal(new.select(np.array([2, 0])).ignore, ignore[[2, 0]])
    from darkread.models.train.finetune import load_annotated

    both, counts = load_annotated([tmp_path / "old", tmp_path / "new"])
    assert len(both) == 5 and both.ignore.shape == (5, 100, 200)
    assert not both.ignore[:2].any() and np.array_equal(both.ignore[2:], ignore)
    assert load_dataset(tmp_path / "old").ignore is None


def test_labels_carry_the_mask_through_shifts_and_crops() -> None:
    rng = np.random.default_rng(1)
    targets = (rng.random((4, 100, 200)) < 0.3).astype(np.uint8)
    ignore = np.zeros_like(targets)
    ignore[:, 40:60, 80:120] = 1
    lab = labels(targets, ignore)
    assert lab.dtype == np.uint8 and (lab[ignore == 1] == IGNORE_LABEL).all()
    marker = np.zeros((4, 4, 100, 200), np.float32)
    marker[:, :, 40:60, 80:120] = 7.0  # the voxels' copy of where the mask is
    v, y = augment(marker, lab, rng, max_shift=6)
    v, y = random_crop(v, y, (64, 128), rng)
    t, valid = split_labels(y)
    assert np.array_equal(valid == 0, np.abs(v[:, 0]) == 7.0)  # the mask moved with the voxels
    assert set(np.unique(t)) <= {0, 1} and not t[valid == 0].any()
    assert labels(targets, None) is targets


def test_loss_has_no_gradient_on_ignored_pixels_and_does_not_see_their_targets() -> None:
    import torch

    from darkread.models.train.fit import bce_dice_loss

    torch.manual_seed(0)
    logits = torch.randn(2, 1, 16, 32, requires_grad=True)
    targets = (torch.rand(2, 1, 16, 32) < 0.3).float()
    valid = torch.ones_like(targets)
    valid[:, :, 4:10, 8:20] = 0
    loss = bce_dice_loss(logits, targets, 0.5, valid)
    loss.backward()
    assert float(logits.grad[valid == 0].abs().max()) == 0.0
    assert float(logits.grad[valid == 1].abs().min()) > 0.0
    flipped = torch.where(valid == 0, 1 - targets, targets)  # what the mask hides does not matter
    other = torch.where(valid == 0, torch.randn_like(logits) * 9, logits.detach())
    assert float(bce_dice_loss(other, flipped, 0.5, valid)) == pytest.approx(float(loss.detach()), rel=1e-6)
    plain = bce_dice_loss(logits.detach(), targets, 0.5)  # no mask: the loss as before
    assert float(bce_dice_loss(logits.detach(), targets, 0.5, torch.ones_like(targets))) == pytest.approx(float(plain), rel=1e-6)


def test_monitored_f1_leaves_the_ignored_pixels_out() -> None:
    import torch

    from darkread.models.train.fit import evaluate_model

    class Constant(torch.nn.Module):  # predicts ink everywhere
        def forward(self, x):
            return torch.ones(x.shape[0], 1, *x.shape[2:])

    targets = np.zeros((2, 100, 200), np.uint8)
    targets[:, 10:20] = 1  # text: 10 rows
    ignore = np.zeros_like(targets)
    ignore[:, 30:] = 1  # everything else but 20 blank rows is masked
    voxels = np.zeros((2, 4, 100, 200), np.float32)
    masked = evaluate_model(Constant(), voxels, targets, ignore=ignore)["f1"]
    full = evaluate_model(Constant(), voxels, targets)["f1"]
    assert masked == pytest.approx(2 * 10 / (2 * 10 + 20))  # tp 10 rows, fp the 20 valid blank rows
    assert full == pytest.approx(2 * 10 / (2 * 10 + 90))
