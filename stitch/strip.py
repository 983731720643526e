"""One line's strip: frames accumulate into a running ink average (the alpha channel) guarded by a
per-pixel improvement mask (a pixel takes a new frame only where its match score holds up to the
best score that pixel has seen)."""

from __future__ import annotations

import cv2
import numpy as np

from darkread.stitch.canvas import Canvas
from darkread.stitch.config import StitchConfig
from darkread.stitch.register import frame_transform

STRIP_LAYERS = ("avg", "count", "conf", "best")


def row_taper(height: int, sigma_rows: float) -> np.ndarray:
    """Column vector of row weights, 1 at the window centre (the fixated line)."""
    rows = np.arange(height, dtype=np.float32) - (height - 1) / 2.0
    return np.exp(-0.5 * (rows / np.float32(sigma_rows)) ** 2)[:, None].astype(np.float32)


def placed(mask: np.ndarray, fx: float, fy: float, angle_deg: float) -> tuple[np.ndarray, np.ndarray, int]:
    """``mask`` rotated about its centre and moved by a fraction of a pixel (bilinear), on a canvas
    grown by a margin; where it is fully defined (the rim is left to other frames); the margin."""
    h, w = mask.shape
    margin = int(np.ceil(abs(np.sin(np.radians(angle_deg))) * max(h, w) / 2.0)) + 1 if angle_deg else 0
    move = frame_transform((h, w), angle_deg, fx + margin, fy + margin)
    size = (w + 2 * margin + 1, h + 2 * margin + 1)
    moved = cv2.warpAffine(mask.astype(np.float32), move, size, flags=cv2.INTER_LINEAR)
    cover = cv2.warpAffine(np.ones((h, w), np.float32), move, size, flags=cv2.INTER_LINEAR)
    return moved, cover > 0.999, margin


def accumulate(
    canvas: Canvas,
    mask: np.ndarray,
    x: float,
    y: float,
    score: float,
    cfg: StitchConfig,
    angle_deg: float = 0.0,
    weight: int = 1,
) -> int:
    """Blend ``mask`` (binary ink, or an ink probability) into the strip with its top-left at
    (x, y) (sub-pixel: bilinear), rotated by ``angle_deg`` about its centre, as ``weight`` frames
    (a fused view of that many frames counts as they would have); returns how many pixels took it."""
    ix, iy = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - ix, y - iy
    if fx > 0.05 or fy > 0.05 or abs(angle_deg) > 0.02:
        values, defined, margin = placed(mask, fx, fy, angle_deg)
        ix, iy = ix - margin, iy - margin
    else:
        values, defined = mask.astype(np.float32), None
    h, w = values.shape
    canvas.ensure(ix, iy, ix + w, iy + h)
    avg, count, conf, best = (canvas.view(k, ix, iy, ix + w, iy + h) for k in STRIP_LAYERS)
    improves = score >= best - cfg.improvement_tolerance
    replaces = score > best + cfg.replace_margin  # far better match: start the pixel afresh
    if defined is not None:
        improves &= defined
        replaces &= defined
    k = np.float32(weight)
    taper = row_taper(h, cfg.taper_sigma_rows) * k
    n = np.where(replaces, k, count + k).astype(np.float32)
    alpha = np.maximum(k / n, np.float32(cfg.alpha))
    blended = avg + alpha * (values - avg)
    np.copyto(avg, blended, where=improves)
    np.copyto(count, n, where=improves)
    np.copyto(conf, np.where(replaces, taper, conf + taper), where=improves)
    np.copyto(best, np.where(replaces, np.float32(score), np.maximum(best, np.float32(score))), where=improves)
    return int(np.count_nonzero(improves))


class LineStrip:
    """Frames of one line, in page coordinates, plus what is known about the line's position."""

    def __init__(self) -> None:
        self.canvas = Canvas(STRIP_LAYERS)
        self.gaze_points: list[tuple[float, float]] = []  # gaze of each frame in page coordinates
        self.frame_ids: list[int] = []

    def add(
        self,
        mask: np.ndarray,
        x: float,
        y: float,
        score: float,
        gaze_xy: tuple[float, float],
        frame_id: int,
        cfg: StitchConfig,
        angle_deg: float = 0.0,
        weight: int = 1,
    ) -> None:
        accumulate(self.canvas, mask, x, y, score, cfg, angle_deg, weight)
        self.gaze_points.append(gaze_xy)
        self.frame_ids.append(frame_id)

    def fork(self) -> LineStrip:
        """An independent copy: the canvas copied, the per-frame lists copied (their items are immutable)."""
        twin = LineStrip()
        twin.canvas = self.canvas.fork()
        twin.gaze_points = list(self.gaze_points)
        twin.frame_ids = list(self.frame_ids)
        return twin

    @property
    def empty(self) -> bool:
        return not self.frame_ids

    def weight(self, power: float = 2.0) -> np.ndarray:
        """Composition weight: confidence (frame count x closeness to the fixated row) to a power,
        so each line on the page comes mostly from its own strip."""
        return self.canvas.layers["conf"] ** np.float32(power)
