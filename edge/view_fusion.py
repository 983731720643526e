"""One view per fixation: its frames registered to each other and fused into ink probability.

During a fixation the eye rests, but the head drifts and the window follows the gaze's jitter, so
the frames of one fixation show the same few words a few pixels apart. Each frame is placed at
its sensor offset from the view's first frame, refined by the stitcher's own registration
(:func:`darkread.stitch.register.register_frame`, correlation against what the view already
holds), and averaged in. The mean of binary frames is an ink probability; it goes on the wire in
``n_levels`` grey levels. Pure: numpy and the stitcher.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darkread.frame_record import FrameRecord
from darkread.stitch.register import register_frame
from darkread.stitch.strip import placed

N_LEVELS = 4  # paper, unlikely, likely, surely ink: two bits a pixel before compression
SEARCH_RADIUS_PX = 6  # head drift within one fixation, beyond the sensor's offset
MIN_SCORE = 0.3  # a weaker correlation keeps the sensor's offset


@dataclass(frozen=True)
class ViewRecord(FrameRecord):
    """A fused view: ``mask`` is its thresholded ink (probability >= 1/2, what a binary stitcher
    takes); ``levels`` the probability in ``n_levels`` steps (level / (n_levels - 1))."""

    levels: np.ndarray = None  # type: ignore[assignment]  # uint8 [h, w], 0 .. n_levels - 1
    n_levels: int = N_LEVELS
    t0_us: int = 0  # the first fused frame; ``t_us`` is the last
    frames: int = 1
    events_used: int = 0
    gaze_rad: tuple[float, float] = (0.0, 0.0)

    def to_message(self, enc: str = "png"):  # noqa: ANN201 - proto stays a lazy import
        from darkread.proto.messages import View

        levels = np.ascontiguousarray(self.levels, dtype=np.uint8)
        return View(
            seq=0, view_id=self.frame_id, t0_us=self.t0_us, t_us=self.t_us, origin=self.origin,
            gaze_px=self.gaze_px, gaze_rad=self.gaze_rad, frames=self.frames, events_used=self.events_used,
            shape=(int(levels.shape[0]), int(levels.shape[1])), n_levels=self.n_levels, levels=levels.tobytes(), enc=enc,
        )


def quantise(probability: np.ndarray, n_levels: int = N_LEVELS) -> np.ndarray:
    """Ink probability in [0, 1] -> uint8 level indices 0 .. n_levels - 1 (nearest level)."""
    return np.rint(np.clip(probability, 0.0, 1.0) * (n_levels - 1)).astype(np.uint8)


def threshold(levels: np.ndarray, n_levels: int = N_LEVELS) -> np.ndarray:
    """Level indices -> binary ink where the probability is at least one half."""
    return (2 * levels.astype(np.int32) >= n_levels - 1).astype(np.uint8)


def _crop(layer: np.ndarray, x0: int, y0: int, w: int, h: int) -> np.ndarray:
    """The box [x0, x0 + w) x [y0, y0 + h) of ``layer``, zeros outside it."""
    out = np.zeros((h, w), np.float32)
    H, W = layer.shape
    ix0, iy0, ix1, iy1 = max(x0, 0), max(y0, 0), min(x0 + w, W), min(y0 + h, H)
    if ix0 < ix1 and iy0 < iy1:
        out[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0] = layer[iy0:iy1, ix0:ix1]
    return out


class ViewFuser:
    """Accumulates the frames of one fixation; ``view()`` returns them fused (not thread-safe)."""

    def __init__(self, n_levels: int = N_LEVELS, radius_px: int = SEARCH_RADIUS_PX) -> None:
        self.n_levels = int(n_levels)
        self.radius = int(radius_px)
        self._first: FrameRecord | None = None
        self._last: FrameRecord | None = None
        self._sum: np.ndarray | None = None
        self._count: np.ndarray | None = None
        self._frames = 0
        self._events = 0
        self._gaze_rad = (0.0, 0.0)

    def __len__(self) -> int:
        return self._frames

    @property
    def t0_us(self) -> int:
        """Event time of the first fused frame (0 while empty)."""
        return self._first.t_us if self._first is not None else 0

    def add(self, frame: FrameRecord, events_used: int = 0, gaze_rad: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
        """Fuse ``frame`` in; returns where it landed relative to the view's top-left."""
        mask = frame.mask.astype(np.float32)
        h, w = mask.shape
        if self._first is None:
            self._first = frame
            self._sum, self._count = mask.copy(), np.ones((h, w), np.float32)
            dx = dy = 0.0
        else:
            dx, dy = self._place(frame, mask)
            self._accumulate(mask, dx, dy)
        self._last = frame
        self._frames += 1
        self._events += int(events_used)
        self._gaze_rad = gaze_rad
        return dx, dy

    def _place(self, frame: FrameRecord, mask: np.ndarray) -> tuple[float, float]:
        """The sensor offset from the first frame, corrected by correlation against the view so far."""
        assert self._first is not None and self._sum is not None and self._count is not None  # noqa: S101
        h, w = mask.shape
        px = frame.origin[0] - self._first.origin[0]
        py = frame.origin[1] - self._first.origin[1]
        r = self.radius
        known = _crop(self._count, px - r, py - r, w + 2 * r, h + 2 * r) > 0
        reference = _crop(self._sum / np.maximum(self._count, 1.0), px - r, py - r, w + 2 * r, h + 2 * r)
        found = register_frame(reference, known.astype(np.float32), mask, r)
        if found is None or found.score < MIN_SCORE or found.on_rim:
            return px, py
        return px + found.shift_xy[0] + found.subpixel_xy[0], py + found.shift_xy[1] + found.subpixel_xy[1]

    def _accumulate(self, mask: np.ndarray, x: float, y: float) -> None:
        """Add ``mask`` with its top-left at (x, y) of the view (bilinear below a pixel, as the stitcher does)."""
        assert self._sum is not None and self._count is not None  # noqa: S101
        dx, dy = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - dx, y - dy
        cover = None
        if fx > 0.05 or fy > 0.05:
            mask, cover, _ = placed(mask, fx, fy, 0.0)
            cover = cover.astype(np.float32)
        H, W = self._sum.shape
        h, w = mask.shape
        x0, y0, x1, y1 = max(dx, 0), max(dy, 0), min(dx + w, W), min(dy + h, H)
        if x0 >= x1 or y0 >= y1:
            return
        self._sum[y0:y1, x0:x1] += mask[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
        self._count[y0:y1, x0:x1] += 1.0 if cover is None else cover[y0 - dy : y1 - dy, x0 - dx : x1 - dx]

    def view(self, view_id: int) -> ViewRecord:
        """The fused view so far (at the first frame's place); the fuser must hold a frame."""
        if self._first is None or self._last is None or self._sum is None or self._count is None:
            raise ValueError("no frame to fuse")
        levels = quantise(self._sum / self._count, self.n_levels)
        return ViewRecord(
            frame_id=int(view_id), t_us=self._last.t_us, mask=threshold(levels, self.n_levels),
            origin=self._first.origin, gaze_px=self._first.gaze_px, levels=levels, n_levels=self.n_levels,
            t0_us=self._first.t_us, frames=self._frames, events_used=self._events, gaze_rad=self._gaze_rad,
        )
