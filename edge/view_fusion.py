"""One view per fixation: its frames registered to each other and fused into ink probability.

During a fixation the eye rests and the window stays where the fixation's gaze centre put it
(the pipeline locks it, and moves its frames a little above and below it), but the head drifts,
so the frames of one fixation show the same few words a few pixels apart. Each frame is placed at
its sensor offset from the frame before, refined by the stitcher's own registration
(:func:`darkread.stitch.register.register_frame`, correlation against what the view already
holds); the view is the union of its frames' windows, placed as the newest frame saw it (where and
when the stitcher predicts it), so it can be larger than one window. A
frame that does not register onto the view (the head jumped, or the classifier joined two
fixations) is not blended in blind: ``add`` says so and the caller starts a new view with it.
The mean of the frames' ink probabilities (of their binary masks, without the network's
probabilities) is the view's ink probability; it goes on the wire in ``n_levels`` grey levels
with the number of frames behind it, and the stitcher averages it in as that many frames. Pure:
numpy, OpenCV and the stitcher.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from darkread.core.frame_record import MAX_VIEW_GROWTH, FrameRecord, threshold_levels
from darkread.proto.messages import View
from darkread.stitch.register import register_frame

N_LEVELS = 8  # the mean of up to ~7 frames to within half a step; few levels compress well in a PNG
SEARCH_RADIUS_PX = 12  # head drift between two frames of a fixation (50-100 ms apart), beyond the sensor's offset
MIN_SCORE = 0.8  # a weaker match: the frame starts a new view (the stitcher places it on its own) rather than blur this one
# (0.6 let low-light frames that matched noise blur their views: docs/views.md) ...
DOUBTED_MIN_SCORE = 0.75  # ... but a frame the network doubted (dim light) cannot match even its right place
DOUBTED = 1.2  # that well: from this doubt on, a weaker match still joins the view (docs/views.md, "Dim frames")
MARGIN_PX = 32  # the fused canvas reaches this far beyond the first frame's window (head drift in a fixation)
# a frame whose network doubts more than this (pixels of probability 0.2-0.8 per ink pixel) is
# averaged in as its mask: measured 1.1-1.5 at 100 lux, ~1.55 at 30, ~2 at 10, 2-3 at 5 lux, where
# the doubt is noise and the page comes from many overlapping views whose masks' majority is sharper
MAX_DOUBT = 1.8
# Where the head's motion is known from a sensor that does not see the page (the gyroscope: the
# head's rotation, not the page's sway in the hand), a doubted frame whose best match is weaker than
# DOUBTED_MIN_SCORE still joins when that best match lies where the motion puts it: two cues that
# agree (docs/views.md, "Dim frames placed where the gyroscope agrees")
AGREE_PX = 2.0
AGREE_MIN_SCORE = 0.5
MIN_INK_FRACTION = 0.003  # frames (or views) with less ink hold nothing to register: the sensor's offset places them


@dataclass(frozen=True)
class ViewRecord(FrameRecord):
    """A fused view: ``mask`` is its thresholded ink (probability >= 1/2); ``levels`` the
    probability in ``n_levels`` steps and ``frames`` the frames fused (the stitcher weighs it so)."""

    t0_us: int = 0  # the first fused frame; ``t_us`` is the last
    events_used: int = 0
    gaze_rad: tuple[float, float] = (0.0, 0.0)

    def to_message(self, enc: str = "png"):  # proto stays a lazy import

        return View.of(self, t0_us=self.t0_us, gaze_rad=self.gaze_rad, events_used=self.events_used, enc=enc)


def quantise(probability: np.ndarray, n_levels: int = N_LEVELS) -> np.ndarray:
    """Ink probability in [0, 1] -> uint8 level indices 0 .. n_levels - 1 (nearest level)."""
    return np.rint(np.clip(probability, 0.0, 1.0) * (n_levels - 1)).astype(np.uint8)


def threshold(levels: np.ndarray, n_levels: int = N_LEVELS) -> np.ndarray:
    """Level indices -> binary ink where the probability is at least one half."""
    return threshold_levels(levels, n_levels)


def doubt(probability: np.ndarray) -> float:
    """How unsure the network was of a frame: pixels between 0.2 and 0.8 per pixel above one half."""
    p = np.asarray(probability)
    unsure = int(np.count_nonzero((p > 0.2) & (p < 0.8)))
    return unsure / max(int(np.count_nonzero(p > 0.5)), 1)


def _crop(layer: np.ndarray, x0: int, y0: int, w: int, h: int) -> np.ndarray:
    """The box [x0, x0 + w) x [y0, y0 + h) of ``layer``, zeros outside it."""
    out = np.zeros((h, w), np.float32)
    H, W = layer.shape
    ix0, iy0, ix1, iy1 = max(x0, 0), max(y0, 0), min(x0 + w, W), min(y0 + h, H)
    if ix0 < ix1 and iy0 < iy1:
        out[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0] = layer[iy0:iy1, ix0:ix1]
    return out


class ViewFuser:
    """Accumulates the frames of one fixation; ``view()`` returns them fused (not thread-safe).

    The sum and count live on a canvas in the first frame's coordinates with a ``margin_px`` rim,
    each frame resampled onto it once (at its sub-pixel place); ``view()`` cuts out the newest
    frame's window (at the nearest pixel; the stitcher registers the view to a fraction again).
    """

    def __init__(
        self, n_levels: int = N_LEVELS, radius_px: int = SEARCH_RADIUS_PX, margin_px: int = MARGIN_PX, max_doubt: float = MAX_DOUBT
    ) -> None:
        self.n_levels = int(n_levels)
        self.max_doubt = float(max_doubt)
        self.radius = int(radius_px)
        self.margin = int(margin_px)
        self._first: FrameRecord | None = None
        self._last: FrameRecord | None = None
        self._last_xy = (0.0, 0.0)  # the newest frame's top-left, in the first frame's coordinates
        self._box = (0, 0, 0, 0)  # union of the frames' windows (x0, y0, x1, y1), first frame's coordinates
        self._sum: np.ndarray | None = None
        self._count: np.ndarray | None = None
        self._touched = (0, 0, 0, 0)  # canvas box (x0, y0, x1, y1) any frame added to: sum and count are 0 outside it
        self._frames = 0
        self._events = 0
        self._gaze_sum = np.zeros(2)
        self._gaze_rad = (0.0, 0.0)
        self.last_score: float | None = None  # the newest frame's match onto the view (None: placed unmatched)
        self.last_agreed = False  # whether it joined because the gyroscope's motion agreed with a weak match
        self.last_doubt: float | None = None  # how much the network doubted the newest frame (None: no probability given)

    def __len__(self) -> int:
        return self._frames

    def fresh(self) -> ViewFuser:
        """An empty fuser with the same settings (the next view)."""
        return ViewFuser(self.n_levels, self.radius, self.margin, self.max_doubt)

    @property
    def t0_us(self) -> int:
        """Event time of the first fused frame (0 while empty)."""
        return self._first.t_us if self._first is not None else 0

    @property
    def last_t_us(self) -> int | None:
        """Event time of the newest fused frame (None while empty)."""
        return self._last.t_us if self._last is not None else None

    def add(
        self,
        frame: FrameRecord,
        events_used: int = 0,
        gaze_rad: tuple[float, float] = (0.0, 0.0),
        probability: np.ndarray | None = None,
        moved: tuple[float, float] | None = None,
    ) -> tuple[float, float] | None:
        """Fuse ``frame`` in; returns where it landed relative to the first frame's top-left, or
        None, leaving the view as it was, when it does not register onto the view.

        ``probability``: the network's ink probability behind the frame's mask, averaged in instead
        of the mask (the frame is still registered by its mask): with only a few frames per view, a
        stroke the network was unsure of survives as grey instead of vanishing or turning solid.
        Not for a frame the network doubted all over (``doubt`` above ``max_doubt``: dim light). A
        doubted frame (``DOUBTED``) joins on a weaker match (``DOUBTED_MIN_SCORE``).

        ``moved``: how far the scene moved in the sensor since the newest frame, by a sensor trusted
        for it (the gyroscope), or None. A doubted frame whose best match is weaker still (down to
        ``AGREE_MIN_SCORE``) joins when that match lies within ``AGREE_PX`` of where ``moved`` puts it."""
        mask = frame.mask.astype(np.float32)
        if probability is not None and probability.shape != mask.shape:
            raise ValueError(f"frame {frame.frame_id}: probability {probability.shape} is not the mask's {mask.shape}")
        unsure = doubt(probability) if probability is not None else None
        if self._first is None or self._sum is None or self._count is None:
            h, w = mask.shape
            m = self.margin
            self._first = frame
            self._sum = np.zeros((h + 2 * m, w + 2 * m), np.float32)
            self._count = np.zeros_like(self._sum)
            xy = (0.0, 0.0)
            self.last_score = None
        else:
            doubted = unsure is not None and unsure >= DOUBTED
            found = self._match(frame, mask)
            if found is None:
                return None
            xy, score = found
            agrees = False
            if score is not None and score < (DOUBTED_MIN_SCORE if doubted else MIN_SCORE):
                agrees = (doubted and moved is not None and score >= AGREE_MIN_SCORE
                          and self._off_prediction(frame, xy, moved) <= AGREE_PX)
                if not agrees:
                    return None
            self.last_score, self.last_agreed = score, agrees
        self.last_doubt = unsure
        soft = self.last_doubt is not None and self.last_doubt <= self.max_doubt
        self._accumulate(np.asarray(probability, np.float32) if soft else mask, xy)
        self._last, self._last_xy = frame, xy
        self._grow_box(xy, mask.shape)
        self._frames += 1
        self._events += int(events_used)
        self._gaze_sum += frame.gaze_px
        self._gaze_rad = gaze_rad
        return xy

    def _off_prediction(self, frame: FrameRecord, xy: tuple[float, float], moved: tuple[float, float]) -> float:
        """How far (px) ``xy`` lies from where the newest frame's place, the sensor offset and the
        scene's motion ``moved`` since put ``frame``."""
        assert self._last is not None
        predicted_x = self._last_xy[0] + frame.origin[0] - self._last.origin[0] - moved[0]
        predicted_y = self._last_xy[1] + frame.origin[1] - self._last.origin[1] - moved[1]
        return math.hypot(xy[0] - predicted_x, xy[1] - predicted_y)

    def _match(self, frame: FrameRecord, mask: np.ndarray) -> tuple[tuple[float, float], float | None] | None:
        """The frame's top-left in the first frame's coordinates (where the newest frame was plus the
        sensor offset between them, corrected by correlation against the view) and the match's
        score (None on blank paper: placed by the offset alone); None when the correlation has no
        peak it can trust (too little overlap, the peak on the search's rim)."""
        assert self._first is not None and self._last is not None and self._sum is not None
        assert self._count is not None
        h, w = mask.shape
        px = int(round(self._last_xy[0])) + frame.origin[0] - self._last.origin[0]
        py = int(round(self._last_xy[1])) + frame.origin[1] - self._last.origin[1]
        # (ink where sum / count >= 1/2, without dividing the whole canvas; counted where frames
        # were added, the rest of the canvas holds none)
        tx0, ty0, tx1, ty1 = self._touched
        touched_sum, touched_count = self._sum[ty0:ty1, tx0:tx1], self._count[ty0:ty1, tx0:tx1]
        view_ink = np.count_nonzero(touched_sum >= 0.5 * np.maximum(touched_count, 1e-6)) / self._sum.size
        if np.count_nonzero(frame.mask) / frame.mask.size < MIN_INK_FRACTION or view_ink < MIN_INK_FRACTION:
            return (float(px), float(py)), None  # blank paper: nothing to correlate, nothing to blur
        r, m = self.radius, self.margin
        box = (px + m - r, py + m - r, w + 2 * r, h + 2 * r)
        count = _crop(self._count, *box)
        probability = _crop(self._sum, *box) / np.maximum(count, 1e-6)  # only the search box
        found = register_frame(probability, (count > 0.5).astype(np.float32), mask, r)
        if found is None or found.on_rim:
            return None
        return (px + found.shift_xy[0] + found.subpixel_xy[0], py + found.shift_xy[1] + found.subpixel_xy[1]), float(found.score)

    def _grow_box(self, xy: tuple[float, float], shape: tuple[int, int]) -> None:
        """Take the frame's window (top-left ``xy``, nearest pixel) into the view's box, within the canvas."""
        x, y = int(round(xy[0])), int(round(xy[1]))
        box = (x, y, x + shape[1], y + shape[0])
        if self._frames:
            box = (min(box[0], self._box[0]), min(box[1], self._box[1]), max(box[2], self._box[2]), max(box[3], self._box[3]))
        m = self.margin
        self._box = (max(box[0], -m), max(box[1], -m), min(box[2], shape[1] + m), min(box[3], shape[0] + m))

    def _accumulate(self, mask: np.ndarray, xy: tuple[float, float]) -> None:
        """Add ``mask`` with its top-left at ``xy`` (first frame's coordinates; bilinear below a
        pixel, as the stitcher does); what falls beyond the margin is left out. Only the canvas
        rows and columns the frame touches are resampled (a whole-pixel move of both the frame
        and the output keeps every bilinear weight, so the sums are the same)."""
        assert self._sum is not None and self._count is not None
        h, w = mask.shape
        x, y = xy[0] + self.margin, xy[1] + self.margin
        x0, y0 = max(int(np.floor(x)), 0), max(int(np.floor(y)), 0)
        x1, y1 = min(int(np.floor(x)) + w + 1, self._sum.shape[1]), min(int(np.floor(y)) + h + 1, self._sum.shape[0])
        if x0 >= x1 or y0 >= y1:
            return
        move = np.array([[1.0, 0.0, x - x0], [0.0, 1.0, y - y0]], np.float32)
        size = (x1 - x0, y1 - y0)
        flags, border = cv2.INTER_LINEAR, cv2.BORDER_CONSTANT
        self._sum[y0:y1, x0:x1] += cv2.warpAffine(mask, move, size, flags=flags, borderMode=border, borderValue=0.0)
        self._count[y0:y1, x0:x1] += cv2.warpAffine(np.ones((h, w), np.float32), move, size, flags=flags, borderMode=border, borderValue=0.0)
        t = self._touched
        self._touched = (x0, y0, x1, y1) if t[2] <= t[0] else (min(t[0], x0), min(t[1], y0), max(t[2], x1), max(t[3], y1))

    def view(self, view_id: int, shed_level: int = 0, light_lux: float | None = None) -> ViewRecord:
        """The fused view so far: the union of its frames' windows (the fuser must hold a frame),
        placed where the newest frame's window is at its time; ``shed_level``: what a live edge
        falling behind was giving up meanwhile (``edge.load``); ``light_lux``: the light measured
        at the page now (None: not known)."""
        if self._first is None or self._last is None or self._sum is None or self._count is None:
            raise ValueError("no frame to fuse")
        lx, ly = int(round(self._last_xy[0])), int(round(self._last_xy[1]))
        h, w = self._last.mask.shape
        x0, y0, x1, y1 = self._box
        # at most MAX_VIEW_GROWTH windows per side, around the newest frame's (a long view's drift)
        reach_x, reach_y = (MAX_VIEW_GROWTH - 1) * w // 2, (MAX_VIEW_GROWTH - 1) * h // 2
        x0, y0 = max(x0, lx - reach_x), max(y0, ly - reach_y)
        x1, y1 = min(x1, lx + w + reach_x), min(y1, ly + h + reach_y)
        m = self.margin
        count = _crop(self._count, x0 + m, y0 + m, x1 - x0, y1 - y0)
        probability = np.where(count > 0.5, _crop(self._sum, x0 + m, y0 + m, x1 - x0, y1 - y0) / np.maximum(count, 1e-6), 0.0)
        levels = quantise(probability, self.n_levels)
        gaze = self._gaze_sum / self._frames
        origin = (self._last.origin[0] + x0 - lx, self._last.origin[1] + y0 - ly)
        return ViewRecord(
            frame_id=int(view_id), t_us=self._last.t_us, mask=threshold(levels, self.n_levels),
            origin=origin, gaze_px=(float(gaze[0]), float(gaze[1])), levels=levels, n_levels=self.n_levels,
            t0_us=self._first.t_us, frames=self._frames, events_used=self._events, gaze_rad=self._gaze_rad,
            scene_px=self._last.scene_px, shed_level=shed_level, light_lux=light_lux,
        )
