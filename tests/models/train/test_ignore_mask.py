"""The markers' ignore mask: it covers what the markers put in a window and nothing of the text, it is
stored in shards so that old shards still load, and the fine-tuning loss and score leave it out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from darkread.models.synth.recording import RecordingSpec, page_to_camera, session_spec
from darkread.models.synth.session import make_session
from darkread.models.synth.shards import SampleMeta, write_shard
from darkread.models.train.annotate import (
    marker_area_for_pose,
    page_coordinates,
    page_ink_for_pose,
    project_page,
    render_ignore,
    render_target,
    window_rays,
)
from darkread.models.train.data import IGNORE_LABEL, augment, labels, load_dataset, load_shard, random_crop, split_labels

SPEC = RecordingSpec(lux=100, motion="normal", kind="pangram", seconds=1.0, seed=4, xheight_px=9.0, n_lines=2,
                     line_chars=24, regime="shifted", markers=True)


@pytest.fixture(scope="module")
def session():
    return make_session(session_spec(SPEC), SPEC.seed)


def inside(mm: np.ndarray, boxes: np.ndarray, grow_mm: float) -> np.ndarray:
    """Page points [n, 2] inside any of the boxes [k, 4] (x0 y0 x1 y1) grown by ``grow_mm``."""
    x, y = mm[:, :1], mm[:, 1:]
    b = boxes[None]
    return ((x >= b[..., 0] - grow_mm) & (x <= b[..., 2] + grow_mm) & (y >= b[..., 1] - grow_mm) & (y <= b[..., 3] + grow_mm)).any(axis=1)


def windows_between_markers_and_text(session, t: float):
    """Windows centred between each marker and the text (both in view), under the true pose at ``t``."""
    page, calib = session.marker_page, session.calib
    H = page_to_camera(session, np.array([t]))[0]
    H = H / H[2, 2]
    text_top, text_bottom = page.text_box_mm[1], page.text_box_mm[3]
    for corners in page.markers.values():
        cx = corners[:, 0].mean()
        above = corners[:, 1].max() < text_top
        y = (corners[:, 1].max() + text_top) / 2 if above else (corners[:, 1].min() + text_bottom) / 2
        uv = project_page(H, calib, np.array([[cx, y]]))[0]
        yield H, (int(uv[0]) - 100, int(uv[1]) - 50)


def test_mask_covers_the_markers_ink_and_no_text(session) -> None:
    page, calib = session.marker_page, session.calib
    ink_for, area_for = page_ink_for_pose(page), marker_area_for_pose(page)
    markers = np.array([[*c.min(axis=0), *c.max(axis=0)] for c in page.markers.values()])
    glyphs = np.array([g["box_mm"] for g in page.glyphs])
    checked = 0
    for t in (0.2, 0.8):
        for H, origin in windows_between_markers_and_text(session, t):
            rays = window_rays(calib, origin)
            ink, s = ink_for(H, calib)
            area, s_area = area_for(H, calib)
            target = render_target(ink, s, H, rays).ravel().astype(bool)
            ignore = render_ignore(area, s_area, H, rays).ravel().astype(bool)
            mm = page_coordinates(H, rays)
            on_marker, on_text = inside(mm, markers, 0.3), inside(mm, glyphs, 0.5)
            if not (target & on_marker).any() or not (target & on_text).any():
                continue  # this window does not see both
            checked += 1
            assert ignore[target & on_marker].all()  # every ink pixel of a marker is ignored
            assert not (ignore & on_text).any()  # no pixel of any glyph's box is
            assert not (target & ~ignore & ~on_text).any()  # what ink is left to learn is text
            assert (target & ~ignore).sum() > 100
    assert checked >= 4


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
