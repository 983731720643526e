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
    out: np.ndarray = image.astype(np.float32)
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


def tune(voxels: np.ndarray, targets: np.ndarray, medians: tuple[int, ...] = (1, 3, 5),
         blurs: tuple[int, ...] = (1, 3, 5, 7)) -> tuple[BaselineParams, float]:
    """Grid search of kernel sizes and threshold for the best pooled ink F1 on ``voxels``/``targets``.

    All thresholds of one kernel pair are scored at once from cumulative histograms of the ink
    and paper pixels' smoothed activity.
    """
    target = np.asarray(targets, bool)
    best = (BaselineParams(), -1.0)
    total_ink = int(target.sum())
    for median, blur in itertools.product(medians, blurs):
        smooth = smoothed_activity(voxels, median, blur)
        positive = smooth[smooth > 0]
        if positive.size == 0:
            continue
        thresholds = np.unique(np.quantile(positive, np.linspace(0.0, 0.98, 60)))
        edges = np.concatenate([[-np.inf], thresholds, [np.inf]])
        ink_hist, _ = np.histogram(smooth[target], bins=edges)
        paper_hist, _ = np.histogram(smooth[~target], bins=edges)
        # predicted ink = smooth > thresholds[k]  <=> value in bins k+1 .. end (values equal to the edge
        # fall in the upper bin; the difference is negligible for tuning)
        tp = np.cumsum(ink_hist[::-1])[::-1][1:]
        fp = np.cumsum(paper_hist[::-1])[::-1][1:]
        fn = total_ink - tp
        f1 = 2 * tp / np.maximum(1, 2 * tp + fp + fn)
        k = int(np.argmax(f1))
        if f1[k] > best[1]:
            best = (BaselineParams(median, blur, float(thresholds[k])), float(f1[k]))
    return best
