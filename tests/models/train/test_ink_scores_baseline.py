from __future__ import annotations

import numpy as np
import pytest

from darkread.models.train.baseline import BaselineParams, activity, predict, tune
from darkread.models.train.ink_scores import ink_scores


def test_ink_scores_on_a_known_case() -> None:
    target = np.array([[1, 1, 0, 0]], bool)
    pred = np.array([[1, 0, 1, 0]], bool)
    s = ink_scores(pred, target)
    assert s["precision"] == pytest.approx(0.5) and s["recall"] == pytest.approx(0.5)
    assert s["f1"] == pytest.approx(0.5) and s["iou"] == pytest.approx(1 / 3)


def test_empty_prediction_of_an_empty_page_is_perfect() -> None:
    empty = np.zeros((4, 4), bool)
    assert ink_scores(empty, empty)["f1"] == 1.0


def test_shape_mismatch_is_an_error() -> None:
    with pytest.raises(ValueError):
        ink_scores(np.zeros((2, 2)), np.zeros((3, 2)))


def test_activity_ignores_polarity() -> None:
    voxels = np.zeros((4, 5, 5), np.float32)
    voxels[0, 2, 2] = -1.5
    voxels[3, 2, 2] = 0.5
    assert activity(voxels)[2, 2] == pytest.approx(2.0)


def test_tuned_baseline_finds_dense_ink_and_ignores_sparse_noise() -> None:
    rng = np.random.default_rng(0)
    targets = np.zeros((6, 40, 60), np.uint8)
    targets[:, 10:20, 10:40] = 1
    voxels = rng.normal(0, 1, (6, 4, 40, 60)).astype(np.float32) * (rng.random((6, 4, 40, 60)) < 0.01)
    voxels += 2.0 * targets[:, None] * (rng.random((6, 4, 40, 60)) < 0.5)
    params, f1 = tune(voxels, targets)
    assert f1 > 0.8
    assert isinstance(params, BaselineParams)
    pred = predict(voxels[0], params)
    assert pred.dtype == np.uint8 and pred.shape == (40, 60)
