"""The hierarchical stitcher: frames -> lines (return sweeps) -> registered strips -> de-warped lines
-> page.

Page coordinates are the sensor coordinates of the first frame, corrected for head motion: each
frame is predicted at its sensor position plus the head-motion correction measured on the frames
before it, then refined by correlation against the page and the growing strip.
"""

from __future__ import annotations

import copy
import logging
import statistics
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import cv2
import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.stitch.config import StitchConfig
from darkread.stitch.dewarp import dewarp_strip
from darkread.stitch.page import (
    PageCanvas,
    assign_lines,
    binarize,
    covered_box,
    estimate_skew,
    ink_level,
    main_column_span,
    rotation_to_fit,
    text_bands,
    union_box,
)
from darkread.stitch.register import Registration, locate_frame, register_frame
from darkread.stitch.segment import LineSegmenter
from darkread.stitch.stitched_page import StitchedPage
from darkread.stitch.strip import LineStrip

log = logging.getLogger(__name__)

MIN_FRAME_SIDE = 8  # smaller masks hold too little text to register by correlation


@dataclass
class _FinishedLine:
    """What the page keeps of a line once its strip is composed in (the strip itself is freed)."""

    box: tuple[int, int, int, int]  # the strip's extent in page coordinates
    gaze_xy: tuple[float, float]  # median gaze in page coordinates

    @classmethod
    def of(cls, strip: LineStrip) -> _FinishedLine:
        x, y = np.median(np.asarray(strip.gaze_points, dtype=np.float64), axis=0)
        return cls(strip.canvas.box, (float(x), float(y)))


def _apply(affine: np.ndarray, xy: tuple[float, float]) -> tuple[float, float]:
    x, y = affine @ np.array([xy[0], xy[1], 1.0])
    return float(x), float(y)


def _apply_all(affine: np.ndarray, points: dict[int, tuple[float, float]]) -> dict[int, tuple[float, float]]:
    """``_apply`` to every value of ``points`` at once (one matrix product, not one per frame)."""
    if not points:
        return {}
    xy = np.asarray(list(points.values()), dtype=np.float64)
    moved = xy @ affine[:, :2].T + affine[:, 2]
    return dict(zip(points.keys(), map(tuple, moved.tolist())))


def predict_correction(
    recent: Sequence[tuple[int, np.ndarray]],
    t_us: int,
    min_span_us: int = 60_000,
    max_ahead_us: int = 200_000,
) -> np.ndarray:
    """Head-motion correction expected at ``t_us`` from recent measurements (in time order).

    A straight line through them (drift is slow and smooth; the fit averages tremor out), evaluated
    at ``t_us`` but at most ``max_ahead_us`` past the newest one, when they span at least
    ``min_span_us``; their median otherwise. Frames come every 3 ms (busy text) to 40 ms: a velocity
    fitted over a few milliseconds is registration jitter, and carried across a saccade's 100-150 ms
    gap it throws the prediction a line pitch off, out of the search window.
    """
    if not recent:
        return np.zeros(2)
    times = np.array([t for t, _ in recent], dtype=np.float64)
    values = np.array([c for _, c in recent], dtype=np.float64)
    if len(recent) < 3 or float(times.max() - times.min()) < min_span_us or t_us - times[-1] > 1_000_000:
        return _median_rows(values)
    dt = times - times.mean()
    # least squares, closed form (np.polyfit's SVD cost more than the rest of the prediction)
    slope = (dt @ (values - values.mean(axis=0))) / float(dt @ dt)
    return values.mean(axis=0) + slope * (min(float(t_us), times[-1] + max_ahead_us) - times.mean())


def predict_from_scene(anchors: Sequence[np.ndarray], scene_px: tuple[float, float]) -> np.ndarray:
    """Head-motion correction of a frame taken when the scene had moved ``scene_px``, from recent
    frames' ``correction + scene offset`` (constant while only the head moves; their median
    drops a frame that registered a line off)."""
    return _median_rows(np.asarray(anchors, dtype=np.float64)) - np.asarray(scene_px, dtype=np.float64)


def _median(values: Iterable[float]) -> float:
    """np.median of a few values, without its overhead (~30x): called several times per frame."""
    return float(statistics.median(values))


def _median_rows(values: np.ndarray) -> np.ndarray:
    """Column medians of a small (n, 2) array, as np.median(values, axis=0)."""
    return np.array([statistics.median(column) for column in values.T.tolist()], dtype=np.float64)


Outcome = Literal["blank", "dropped", "placed", "registered"]
"""What became of a frame: too little ink; no trustworthy match (left out); put where predicted
(nothing to match against there); matched and blended in."""


class Placement(NamedTuple):
    frame: FrameRecord
    outcome: Outcome
    score: float  # the match score it was placed with (0 when not registered)


class PageStitcher:
    """Incremental stitcher: ``add`` frames in time order as they arrive, ask for ``page`` any time.

    Frames are decided ``cfg.sweep_confirm_frames`` frames late (a return sweep must be confirmed);
    ``add`` and ``flush`` return each decided frame with its ``Outcome``. ``flush`` integrates the
    undecided tail, ``page`` does not change the state, ``snapshot`` is the page as if the
    reading ended now (the state is kept, so frames can follow).
    """

    def __init__(self, cfg: StitchConfig = StitchConfig()) -> None:
        self.cfg = cfg
        self._segmenter = LineSegmenter(cfg)
        self._page = PageCanvas()
        self._lines: list[_FinishedLine] = []
        self._strip: LineStrip | None = None
        # (t_us, page position - sensor position) of recent frames: the head motion, sub-pixel
        self._corrections: deque[tuple[int, np.ndarray]] = deque(maxlen=cfg.drift_window_frames)
        # correction + scene offset of recent frames that carry one (see ``predict_from_scene``)
        self._anchors: deque[np.ndarray] = deque(maxlen=max(cfg.scene_anchor_frames, 1))
        self._rolls: deque[float] = deque(maxlen=cfg.roll_window)  # frame rotation vs the page
        self._scores: deque[float] = deque(maxlen=cfg.drift_window_frames)  # recent match scores
        self._registered = 0
        self._used = 0
        self._dropped = 0
        self._positions: dict[int, tuple[float, float]] = {}
        self._score = 0.0  # the last decided frame's match score

    def add(self, frame: FrameRecord) -> list[Placement]:
        if min(frame.mask.shape) < MIN_FRAME_SIDE:
            raise ValueError(
                f"frame {frame.frame_id}: the stitcher needs masks of at least {MIN_FRAME_SIDE}x{MIN_FRAME_SIDE}, "
                f"got shape {frame.mask.shape}"
            )
        return [self._place(decided, new_line) for decided, new_line in self._segmenter.push(frame)]

    def flush(self) -> list[Placement]:
        return [self._place(decided, new_line) for decided, new_line in self._segmenter.flush()]

    def _place(self, frame: FrameRecord, new_line: bool) -> Placement:
        self._score = 0.0
        outcome = self._integrate(frame, new_line)
        return Placement(frame, outcome, self._score)

    def fork(self) -> PageStitcher:
        """An independent copy for a snapshot or a checkpoint. Frames are immutable and shared, so
        the cost is the canvases (page area), not the frames stitched so far (a deep copy of a
        30,000-frame session took longer than the question it served)."""
        twin = copy.copy(self)
        twin._segmenter = self._segmenter.fork()
        twin._page = self._page.fork()
        twin._lines = list(self._lines)
        twin._strip = None if self._strip is None else self._strip.fork()
        twin._corrections = deque(self._corrections, maxlen=self._corrections.maxlen)
        twin._anchors = deque(self._anchors, maxlen=self._anchors.maxlen)
        twin._rolls = deque(self._rolls, maxlen=self._rolls.maxlen)
        twin._scores = deque(self._scores, maxlen=self._scores.maxlen)
        twin._positions = dict(self._positions)
        return twin

    def snapshot(self, positions: bool = True) -> StitchedPage:
        """The page with the undecided frames integrated too, leaving this stitcher as it was
        (without ``positions`` the page's ``frame_positions`` stay empty: cheaper)."""
        if not self._segmenter.pending:
            return self.page(positions)
        ended = self.fork()
        ended.flush()
        return ended.page(positions)

    @property
    def canvas_pixels(self) -> int:
        """Pixels the page's canvas spans (memory grows with it: 12 bytes each, plus the strip)."""
        h, w = self._page.canvas.shape
        return int(h * w)

    @property
    def frames_used(self) -> int:
        return self._used

    @property
    def frames_dropped(self) -> int:
        return self._dropped

    def _finish_line(self) -> None:
        strip = self._strip
        self._strip = None
        if strip is None or strip.empty:
            return
        if not self._page.canvas.empty:
            box = strip.canvas.box
            reference, seen = self._page.reference(None, box)
            warp = dewarp_strip(strip.canvas, reference, seen, self.cfg)
            if warp is not None:
                log.debug("line %d de-warped with %d tracked points", len(self._lines), warp.points)
        self._page.add_strip(strip)
        self._lines.append(_FinishedLine.of(strip))

    def _integrate(self, frame: FrameRecord, new_line: bool) -> Outcome:
        cfg = self.cfg
        mask = frame.ink_probability()  # a fused view: its grey levels, registered and averaged as such
        if frame.mask.mean() < cfg.min_ink_fraction:
            self._dropped += 1
            return "blank"
        if new_line:
            self._finish_line()
        if self._strip is None:
            self._strip = LineStrip()
        h, w = mask.shape
        r = cfg.search_radius_px
        use_scene = cfg.scene_anchor_frames > 0 and frame.scene_px is not None
        if frame.scene_px is None:
            self._anchors.clear()  # the head's motion was not measured: the offsets before and after do not chain
        gap_us = frame.t_us - self._corrections[-1][0] if self._corrections else 0
        if use_scene and frame.scene_px is not None and self._anchors and gap_us >= cfg.scene_gap_ms * 1e3:
            correction = predict_from_scene(self._anchors, frame.scene_px)
        else:
            correction = predict_correction(self._corrections, frame.t_us)
        px, py = np.round(np.asarray(frame.origin) + correction).astype(int).tolist()
        x, y = float(px), float(py)
        reference, seen = self._page.reference(self._strip, (px - r, py - r, px + w + r, py + h + r))
        roll = _median(self._rolls) if self._rolls else 0.0
        search_roll = cfg.roll_step_deg > 0 and self._registered % cfg.roll_every_frames == 0
        angles = (roll - cfg.roll_step_deg, roll, roll + cfg.roll_step_deg) if search_roll else (roll,)
        reg = register_frame(reference, seen, mask, r, cfg.blur_sigma_px, cfg.min_overlap_fraction, angles)
        rejected = False  # a wide search found no unambiguous match
        if reg is not None and cfg.wide_search_px > r and (reg.on_rim or self._weak(reg.score)):
            reg = self._search_wide(frame, px, py, roll)
            rejected = reg is None
        elif reg is not None and cfg.wide_search_px > r and self._doubtful(reg.score):
            wider = self._search_wide(frame, px, py, roll)
            same_line = wider is not None and abs(wider.shift_xy[1] - reg.shift_xy[1]) < cfg.ambiguity_rows
            if wider is not None and same_line and wider.score >= reg.score + cfg.anchor_gain:
                reg = wider
        if (reg is None or reg.score < cfg.anchor_trigger_score or self._weak(reg.score)) and not self._page_empty():
            found = self._search_anchor(frame, px, py, roll, reg)
            if found is not None:
                reg, rejected = found, False
        if rejected:
            self._dropped += 1
            return "dropped"
        if reg is None:
            score = 0.0  # nothing to compare with yet: placed as predicted, first to be replaced
        elif reg.score < cfg.min_match_score:
            self._dropped += 1
            log.debug("frame %d dropped: match score %.2f", frame.frame_id, reg.score)
            return "dropped"
        else:
            score = self._score = reg.score
            x = px + reg.shift_xy[0] + (reg.subpixel_xy[0] if cfg.subpixel else 0.0)
            y = py + reg.shift_xy[1] + (reg.subpixel_xy[1] if cfg.subpixel else 0.0)
            correction = np.array([x, y]) - np.asarray(frame.origin)
            self._corrections.append((frame.t_us, correction))
            if use_scene:
                self._anchors.append(correction + np.asarray(frame.scene_px))
            self._scores.append(score)
            self._registered += 1
            if search_roll:
                self._rolls.append(float(np.clip(reg.angle_deg, -cfg.max_roll_deg, cfg.max_roll_deg)))
                roll = _median(self._rolls)
        gaze_xy = (frame.gaze_px[0] + float(correction[0]), frame.gaze_px[1] + float(correction[1]))
        self._strip.add(mask, x, y, score, gaze_xy, frame.frame_id, cfg, roll, frame.frames)
        self._positions[frame.frame_id] = (x, y)
        self._used += 1
        return "placed" if reg is None else "registered"

    def _weak(self, score: float) -> bool:
        """A match well below the recent ones: likely the neighbouring line (one pitch off, a frame's
        lines meet other words), as when the head moved more than predicted."""
        return len(self._scores) >= 3 and score < _median(self._scores) - self.cfg.weak_match_drop

    def _doubtful(self, score: float) -> bool:
        """A match somewhat below the recent ones: as likely a letter or a word off as a worse view."""
        drop = self.cfg.doubtful_match_drop
        return drop > 0 and len(self._scores) >= 3 and score < _median(self._scores) - drop

    def _page_empty(self) -> bool:
        return self._page.canvas.empty and (self._strip is None or self._strip.empty)

    def _search_anchor(
        self, frame: FrameRecord, px: int, py: int, roll: float, current: Registration | None
    ) -> Registration | None:
        """The whole frame matched against everything seen within ``anchor_search_px`` of the
        prediction, for a frame that found no good match near it: under walking the head bobs tens
        of pixels between frames and across a saccade, a prediction can miss the page by several
        lines, and a frame placed there would start a second copy of text already stitched. The
        place is taken only if it scores ``anchor_min_score``, beats ``current`` by ``anchor_gain``
        and beats every place a line above or below by ``ambiguity_margin``."""
        cfg = self.cfg
        if cfg.anchor_search_px <= 0:
            return None
        h, w = frame.mask.shape
        a = cfg.anchor_search_px
        reference, seen = self._page.reference(self._strip, (px - a, py - a, px + w + a, py + h + a))
        found = locate_frame(
            reference, seen, frame.ink_probability(), a, cfg.blur_sigma_px, cfg.anchor_known_fraction, roll, cfg.ambiguity_rows
        )
        if found is None or found.score < cfg.anchor_min_score or found.vertical_margin < cfg.ambiguity_margin:
            return None
        if current is not None and found.score < current.score + cfg.anchor_gain:
            return None
        if self._corrections:  # the head cannot have moved faster than it does
            t_last, last = self._corrections[-1]
            moved = np.array([px + found.shift_xy[0], py + found.shift_xy[1]]) - np.asarray(frame.origin) - last
            reach = cfg.anchor_slack_px + cfg.max_head_speed_px_s * max(0, frame.t_us - t_last) / 1e6
            if float(np.hypot(*moved)) > reach:
                log.debug("frame %d: a match %s px away is beyond the head's reach", frame.frame_id, found.shift_xy)
                return None
        log.debug(
            "frame %d re-anchored %s px from its prediction: score %.2f (near it %s, recent %s)",
            frame.frame_id,
            found.shift_xy,
            found.score,
            "none" if current is None else f"{current.score:.2f}",
            f"{np.median(self._scores):.2f}" if self._scores else "none",
        )
        return found

    def _search_wide(self, frame: FrameRecord, px: int, py: int, roll: float) -> Registration | None:
        """Registration over ``wide_search_px`` around the prediction for a frame whose best match lay
        on the rim of the usual search or was weak (the head moved more than predicted); None, and
        the frame is dropped, unless the peak is a true maximum that beats every match a line above or below
        it by ``ambiguity_margin`` (a wide search reaches the neighbouring lines) and lies on at least
        ``wide_min_known`` of seen page."""
        cfg = self.cfg
        h, w = frame.mask.shape
        wide = cfg.wide_search_px
        reference, seen = self._page.reference(self._strip, (px - wide, py - wide, px + w + wide, py + h + wide))
        reg = register_frame(
            reference, seen, frame.ink_probability(), wide, cfg.blur_sigma_px, cfg.min_overlap_fraction, (roll,), cfg.ambiguity_rows
        )
        if reg is None or reg.on_rim or reg.vertical_margin < cfg.ambiguity_margin:
            log.debug("frame %d dropped: no unambiguous match within %d px", frame.frame_id, wide)
            return None
        if reg.overlap_at_peak < cfg.wide_min_known:
            log.debug("frame %d: its best match within %d px lies %.0f %% on seen page, too little to trust",
                      frame.frame_id, wide, 100 * reg.overlap_at_peak)
            return None
        return reg

    def page(self, positions: bool = True) -> StitchedPage:
        """The page so far: finished lines plus the line being read (``positions``: with every
        frame's place on it, ``frame_positions``)."""
        cfg = self.cfg
        lines = list(self._lines)
        if self._strip is not None and not self._strip.empty:
            lines.append(_FinishedLine.of(self._strip))
        if not lines:
            return StitchedPage(np.zeros((0, 0), np.uint8), [], [], self._used, self._dropped)
        box = union_box([ln.box for ln in lines])
        current = self._strip if self._strip is not None and not self._strip.empty else None
        avg, seen = self._page.reference(current, box)
        views = self._page.views(current, box)
        cover = covered_box(seen)
        if cover is None:
            return StitchedPage(np.zeros((0, 0), np.uint8), [], [], self._used, self._dropped)
        cx0, cy0, cx1, cy1 = cover
        avg, views = avg[cy0:cy1, cx0:cx1], views[cy0:cy1, cx0:cx1]
        to_image = np.array([[1.0, 0.0, -(box[0] + cx0)], [0.0, 1.0, -(box[1] + cy0)]])  # page -> image
        level = ink_level(avg, cfg, views)
        image = binarize(avg, cfg, views, level)
        skew = estimate_skew(image, cfg.deskew_max_deg)
        if abs(skew) >= cfg.deskew_min_deg:
            turn, size = rotation_to_fit(image.shape, skew)
            avg = cv2.warpAffine(avg, turn, size, flags=cv2.INTER_LINEAR)
            views = cv2.warpAffine(views, turn, size, flags=cv2.INTER_NEAREST)
            x0, y0, x1, y1 = covered_box(views > 0) or (0, 0, size[0], size[1])
            avg, views = avg[y0:y1, x0:x1], views[y0:y1, x0:x1]
            turn[:, 2] -= (x0, y0)
            to_image = turn @ np.vstack([to_image, [0.0, 0.0, 1.0]])
            image = binarize(avg, cfg, views, level)
        boxes, images = self._line_boxes(lines, image, to_image)
        return StitchedPage(
            image,
            boxes,
            images,
            self._used,
            self._dropped,
            _apply_all(to_image, self._positions) if positions else {},
            skew_deg=skew if abs(skew) >= cfg.deskew_min_deg else 0.0,
            ink_probability=np.where(views >= cfg.min_views, avg, 0.0).astype(np.float32),
            grey_saturation=level,
            views=views,
        )

    def _line_boxes(
        self, lines: list[_FinishedLine], image: np.ndarray, to_image: np.ndarray
    ) -> tuple[list[tuple[int, int, int, int]], list[np.ndarray]]:
        """One box per text line that was read: the page's text bands that the strips' gaze ran
        along, each spanning the band's main run of ink columns."""
        bands = text_bands(image)
        claims = assign_lines([_apply(to_image, ln.gaze_xy)[1] for ln in lines], [c for _, _, c in bands])
        boxes, images = [], []
        for band in sorted({c for c in claims if c >= 0}):
            top, bottom, _ = bands[band]
            span = main_column_span(np.asarray(image[top:bottom].any(axis=0)), self.cfg.line_gap_px)
            if span is None:
                continue
            boxes.append((span[0], top, span[1], bottom))
            images.append(image[top:bottom, span[0] : span[1]].copy())
        return boxes, images


def stitch_page(frames: Sequence[FrameRecord], cfg: StitchConfig = StitchConfig()) -> StitchedPage:
    """Stitch a whole reading pass (frames are taken in time order)."""
    stitcher = PageStitcher(cfg)
    for frame in sorted(frames, key=lambda f: f.t_us):
        stitcher.add(frame)
    stitcher.flush()
    return stitcher.page()
