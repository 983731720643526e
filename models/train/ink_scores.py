"""Ink-pixel scores for binary reconstructions (1 = ink), pooled over all pixels of a group."""

from __future__ import annotations

import numpy as np


def ink_counts(pred: np.ndarray, target: np.ndarray) -> tuple[int, int, int]:
    """True positives, false positives, false negatives of the ink class."""
    p = np.asarray(pred, bool)
    t = np.asarray(target, bool)
    if p.shape != t.shape:
        raise ValueError(f"prediction {p.shape} and target {t.shape} differ in shape")
    tp = int(np.count_nonzero(p & t))
    return tp, int(np.count_nonzero(p)) - tp, int(np.count_nonzero(t)) - tp


def scores_from_counts(tp: int, fp: int, fn: int) -> dict[str, float]:
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
    iou = tp / (tp + fp + fn) if tp + fp + fn else 1.0
    return {"precision": precision, "recall": recall, "f1": f1, "iou": iou}


def ink_scores(pred: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """Precision, recall, F1 and IoU of the ink class (an empty prediction of an empty page scores 1)."""
    return scores_from_counts(*ink_counts(pred, target))
