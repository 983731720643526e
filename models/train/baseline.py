"""The naive baseline the network has to beat: a denoised, thresholded event-activity image.

Per pixel, the activity is the sum over time bins of |voxel|: a polarity-blind, time-weighted
event count of the same window the network sees (the voxel grid is all a shard stores). It is
median-filtered (removes isolated noise events), box-blurred (fills the gaps between sparse
events on a stroke) and thresholded; kernel sizes and threshold are tuned for the best ink F1
on training samples. No learning beyond those three numbers.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from darkread.models.train.metrics import ink_counts, scores_from_counts


@dataclass(frozen=True)
class BaselineParams:
    median: int = 3
    blur: int = 3
    threshold: float = 0.5

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def activity(voxels: np.ndarray) -> np.ndarray:
    """[...,B,H,W] -> [...,H,W] float32 event activity."""
    return np.abs(np.asarray(voxels, np.float32)).sum(axis=-3)


def _smooth(image: np.ndarray, median: int, blur: int) -> np.ndarray:
    out = image.astype(np.float32)
    if median > 1:
        out = cv2.medianBlur(out, median)
    if blur > 1:
        out = cv2.blur(out, (blur, blur))
    return out


def smoothed_activity(voxels: np.ndarray, median: int, blur: int) -> np.ndarray:
    act = activity(voxels)
    if act.ndim == 2:
        return _smooth(act, median, blur)
    return np.stack([_smooth(a, median, blur) for a in act])


def predict(voxels: np.ndarray, params: BaselineParams) -> np.ndarray:
    """Ink mask (uint8, 1 = ink) for one voxel grid or a batch."""
    return (smoothed_activity(voxels, params.median, params.blur) > params.threshold).astype(np.uint8)


def tune(voxels: np.ndarray, targets: np.ndarray, medians: tuple[int, ...] = (1, 3, 5), blurs: tuple[int, ...] = (1, 3, 5, 7)) -> tuple[BaselineParams, float]:
    """Grid search of kernel sizes and threshold for the best pooled ink F1 on ``voxels``/``targets``."""
    target = np.asarray(targets, bool)
    best = (BaselineParams(), -1.0)
    for median, blur in itertools.product(medians, blurs):
        smooth = smoothed_activity(voxels, median, blur)
        positive = smooth[smooth > 0]
        if positive.size == 0:
            continue
        for threshold in np.unique(np.quantile(positive, np.linspace(0.02, 0.95, 40))):
            f1 = scores_from_counts(*ink_counts(smooth > threshold, target))["f1"]
            if f1 > best[1]:
                best = (BaselineParams(median, blur, float(threshold)), f1)
    return best
