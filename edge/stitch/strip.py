"""One line's strip: frames accumulate into a running ink average (the alpha channel) guarded by a
per-pixel improvement mask (a pixel takes a new frame only where its match score holds up to the
best score that pixel has seen)."""

from __future__ import annotations

import cv2
import numpy as np

from darkread.edge.stitch.canvas import Canvas
from darkread.edge.stitch.frames import StitchConfig

STRIP_LAYERS = ("avg", "count", "conf", "best")


def row_taper(height: int, sigma_rows: float) -> np.ndarray:
    """Column vector of row weights, 1 at the window centre (the fixated line)."""
    rows = np.arange(height, dtype=np.float32) - (height - 1) / 2.0
    return np.exp(-0.5 * (rows / np.float32(sigma_rows)) ** 2)[:, None].astype(np.float32)


def shifted(mask: np.ndarray, fx: float, fy: float) -> tuple[np.ndarray, np.ndarray]:
    """``mask`` moved right/down by a fraction of a pixel (bilinear), one pixel larger, and where
    it is fully defined (the rim is left to other frames)."""
    h, w = mask.shape
    move = np.float32([[1, 0, fx], [0, 1, fy]])
    moved = cv2.warpAffine(mask.astype(np.float32), move, (w + 1, h + 1), flags=cv2.INTER_LINEAR)
    cover = cv2.warpAffine(np.ones((h, w), np.float32), move, (w + 1, h + 1), flags=cv2.INTER_LINEAR)
    return moved, cover > 0.999


def accumulate(canvas: Canvas, mask: np.ndarray, x: float, y: float, score: float, cfg: StitchConfig) -> int:
    """Blend ``mask`` into the strip at top-left (x, y) (sub-pixel: bilinear); returns how many
    pixels took it."""
    ix, iy = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - ix, y - iy
    if fx > 0.05 or fy > 0.05:
        values, defined = shifted(mask, fx, fy)
    else:
        values, defined = mask.astype(np.float32), None
    h, w = values.shape
    canvas.ensure(ix, iy, ix + w, iy + h)
    avg, count, conf, best = (canvas.view(k, ix, iy, ix + w, iy + h) for k in STRIP_LAYERS)
    improves = score >= best - cfg.improvement_tolerance
    if defined is not None:
        improves &= defined
    n = count + 1.0
    alpha = np.maximum(1.0 / n, np.float32(cfg.alpha))
    blended = avg + alpha * (values - avg)
    np.copyto(avg, blended, where=improves)
    np.copyto(count, n, where=improves)
    np.copyto(conf, conf + row_taper(h, cfg.taper_sigma_rows), where=improves)
    np.copyto(best, np.maximum(best, np.float32(score)), where=improves)
    return int(np.count_nonzero(improves))


class LineStrip:
    """Frames of one line, in page coordinates, plus what is known about the line's position."""

    def __init__(self) -> None:
        self.canvas = Canvas(STRIP_LAYERS)
        self.gaze_rows: list[float] = []  # gaze row of each frame in page coordinates
        self.frame_ids: list[int] = []

    def add(self, mask: np.ndarray, x: float, y: float, score: float, gaze_row: float, frame_id: int, cfg: StitchConfig) -> None:
        accumulate(self.canvas, mask, x, y, score, cfg)
        self.gaze_rows.append(gaze_row)
        self.frame_ids.append(frame_id)

    @property
    def empty(self) -> bool:
        return not self.frame_ids

    def weight(self, power: float = 2.0) -> np.ndarray:
        """Composition weight: confidence (frame count x closeness to the fixated row) to a power,
        so each line on the page comes mostly from its own strip."""
        return self.canvas.layers["conf"] ** np.float32(power)
