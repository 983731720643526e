"""One line's strip: frames accumulate into a running ink average (the alpha channel) guarded by a
per-pixel improvement mask (a pixel takes a new frame only where its match score holds up to the
best score that pixel has seen)."""

from __future__ import annotations

import numpy as np

from darkread.edge.stitch.canvas import Canvas
from darkread.edge.stitch.frames import StitchConfig

STRIP_LAYERS = ("avg", "count", "conf", "best")


def row_taper(height: int, sigma_rows: float) -> np.ndarray:
    """Column vector of row weights, 1 at the window centre (the fixated line)."""
    rows = np.arange(height, dtype=np.float32) - (height - 1) / 2.0
    return np.exp(-0.5 * (rows / np.float32(sigma_rows)) ** 2)[:, None].astype(np.float32)


def accumulate(canvas: Canvas, mask: np.ndarray, x: int, y: int, score: float, cfg: StitchConfig) -> int:
    """Blend ``mask`` into the strip at top-left (x, y); returns how many pixels took it."""
    h, w = mask.shape
    canvas.ensure(x, y, x + w, y + h)
    avg, count, conf, best = (canvas.view(k, x, y, x + w, y + h) for k in STRIP_LAYERS)
    improves = score >= best - cfg.improvement_tolerance
    n = count + 1.0
    alpha = np.maximum(1.0 / n, np.float32(cfg.alpha))
    blended = avg + alpha * (mask.astype(np.float32) - avg)
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

    def add(self, mask: np.ndarray, x: int, y: int, score: float, gaze_row: float, frame_id: int, cfg: StitchConfig) -> None:
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
