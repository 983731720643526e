from __future__ import annotations

import numpy as np
import pytest
import torch
from darkread.models.train.finetune import (
    finetune_arrays,
    make_targets,
    match_target,
    render_page_ink,
)
from darkread.models.train.net import BinaryUNet, NetConfig


@pytest.fixture(scope="module")
def page() -> np.ndarray:
    text = "The quick brown fox jumps over the lazy dog while\nreading in the dark with event vision on glasses.\nPack my box with five dozen liquor jugs, said Mia.\nSphinx of black quartz, judge my vow in the night."
    return render_page_ink(text, xheight_px=10.0)


def test_rendered_page_is_an_ink_mask(page: np.ndarray) -> None:
    assert page.dtype == np.uint8 and set(np.unique(page)) == {0, 1}
    assert 0.005 < page.mean() < 0.2


def test_a_noisy_prediction_is_located_on_the_page(page: np.ndarray) -> None:
    y, x = 100, 150
    truth = page[y : y + 100, x : x + 200]
    rng = np.random.default_rng(0)
    noisy = truth.copy()
    flip = rng.random(noisy.shape) < 0.03
    noisy[flip] = 1 - noisy[flip]
    match = match_target(noisy, page)
    assert match is not None and match.scale == 1.0
    assert (match.x, match.y) == (x, y)
    assert np.array_equal(match.target, truth)


def test_an_empty_or_random_prediction_gives_no_target(page: np.ndarray) -> None:
    assert match_target(np.zeros((100, 200), np.uint8), page) is None
    noise = (np.random.default_rng(1).random((100, 200)) < 0.1).astype(np.uint8)
    assert match_target(noise, page) is None


def test_make_targets_keeps_only_matched_windows(page: np.ndarray) -> None:
    voxels = np.random.default_rng(2).normal(size=(2, 4, 100, 200)).astype(np.float32)
    preds = np.stack([page[100:200, 150:350], np.zeros((100, 200), np.uint8)])
    kept_v, kept_t, scores = make_targets(voxels, preds, page)
    assert len(kept_v) == 1 and np.array_equal(kept_v[0], voxels[0])
    assert np.array_equal(kept_t[0], page[100:200, 150:350]) and scores[0] > 0.9


def test_finetuning_lowers_the_loss_and_keeps_batchnorm_statistics(page: np.ndarray) -> None:
    torch.manual_seed(0)
    model = BinaryUNet(NetConfig(widths=(4, 8, 8, 8), blocks=(1, 1, 1))).eval()
    targets = np.stack([page[100:150, 150:250], page[120:170, 400:500]])  # small crops: the net is fully convolutional
    voxels = np.repeat(targets[:, None].astype(np.float32) * 2 - 0.2, 4, axis=1)
    stats = model.stem[1].running_mean.clone()
    losses = finetune_arrays(model, voxels, targets, lr=1e-2, steps=5, batch_size=2, threads=1)
    assert losses[-1] < losses[0]
    assert torch.equal(model.stem[1].running_mean, stats)
    assert not model.training
    with pytest.raises(ValueError, match="no windows"):
        finetune_arrays(model, voxels[:0], targets[:0], lr=1e-5, steps=1)


@pytest.mark.slow
def test_windows_of_a_recording_match_its_printed_page(shared_sample_recording) -> None:
    from darkread.edge.reconstruct import Reconstructor, default_model_path
    from darkread.models.train.finetune import _font_for, recording_windows

    if not default_model_path().is_file():
        pytest.skip("no shipped model")
    voxels, meta, text = recording_windows(shared_sample_recording, max_windows=40)
    assert voxels.ndim == 4 and voxels.shape[1:] == (4, 100, 200) and len(voxels) > 0
    preds = Reconstructor(warmup=0)(voxels)
    xheight = float(meta.get("xheight_px", 10.0))
    page = render_page_ink(text, xheight, _font_for(meta))
    kept_v, kept_t, scores = make_targets(voxels, preds, page)
    assert len(kept_v) >= 1 and min(scores) >= 0.35
    assert kept_t.shape[1:] == (100, 200)
