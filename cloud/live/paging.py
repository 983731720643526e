"""A session as a sequence of pages: each frame is stitched once, into the current page.

Pure and deterministic (no threads, no clocks): the same frames and page breaks in seq order
give the same pages, which is how pages are rebuilt after a restart. A new page starts

* at an explicit page break from the glasses (``PageBreak``),
* when registration is lost for a while: inked frames of a page that has settled find no
  match (dropped), nothing to match against (placed where predicted: the gaze left the page),
  or only a weak one (``weak_drop`` below the page's typical score: other text shares the line
  layout, so it correlates, but less) for ``lost_after_s`` of event time and at least
  ``lost_min_frames`` frames. The page goes back to its state before that stretch (a
  checkpoint taken when the stretch began), and the stretch starts the new page, so the old
  page keeps none of the new text and the new page loses none of it,
* when the page's canvas would outgrow ``max_page_pixels`` (bounds a live session's memory).
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.stitch import PageStitcher, StitchConfig
from darkread.stitch.page import text_bands
from darkread.stitch.stitcher import MIN_FRAME_SIDE

from ..store import StoredFrame

Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class PagingConfig:
    lost_after_s: float = 0.5  # registration lost this long (event time) starts a new page ...
    # (at 10 lux while walking, every-window frames of one page failed for up to 0.27 s and then registered again)
    lost_min_frames: int = 8  # ... after at least this many inked frames failed
    weak_drop: float = 0.2  # a match this far below the page's median score counts as failed
    score_window: int = 50  # registered frames the page's median score is taken over
    settled_frames: int = 10  # a page needs this many registered frames before it can be lost
    max_page_pixels: int = 2_000_000  # ~56 MB of stitcher canvases at most; a bigger page starts anew
    min_stitch_gap_us: int = 0  # frames closer than this to the last stitched one at the same ...
    same_place_px: float = 12.0  # ... gaze (within this) add nothing new and are skipped; 0 = all


@dataclass(frozen=True)
class RenderedPage:
    """One version of a page as OCR reads it."""

    index: int
    version: int  # frames integrated into the page
    grey: np.ndarray = field(repr=False)  # uint8 black text on white, grey where frames disagreed
    ink: np.ndarray = field(repr=False)  # uint8 ink mask (1 = ink), same shape
    bands: tuple[Box, ...]  # text lines found on the page (x0, y0, x1, y1), top to bottom
    first_seq: int
    last_seq: int
    views: np.ndarray | None = field(default=None, repr=False)  # frames that covered each pixel, same shape
    motion: PageMotion | None = None  # how the frames of the page came


@dataclass
class PageMotion:
    """How fast the frames of a page came and how far the head moved meanwhile (event time): in
    dim light the glasses make fewer frames a second (each needs its events), and a fast head
    smears what they show."""

    frames: int = 0  # reconstructions (a view counts the frames fused into it)
    first_us: int | None = None
    last_us: int | None = None
    path_px: float = 0.0  # the scene's travel in the sensor
    last_scene: tuple[float, float] | None = None
    records: int = 0  # frames and views as they came
    shed_sum: int = 0  # their shedding levels summed (a live edge falling behind says how far: edge.load)
    log_lux_sum: float = 0.0  # the light the glasses measured at them, log lux summed ...
    lit_records: int = 0  # ... over the frames and views that said it

    def add(self, frame: FrameRecord) -> None:
        self.frames += frame.frames
        self.records += 1
        self.shed_sum += frame.shed_level
        if frame.light_lux is not None:
            self.log_lux_sum += math.log(frame.light_lux)
            self.lit_records += 1
        self.first_us = frame.t_us if self.first_us is None else min(self.first_us, frame.t_us)
        self.last_us = frame.t_us if self.last_us is None else max(self.last_us, frame.t_us)
        if frame.scene_px is not None:
            if self.last_scene is not None:
                self.path_px += float(np.hypot(frame.scene_px[0] - self.last_scene[0], frame.scene_px[1] - self.last_scene[1]))
            self.last_scene = frame.scene_px

    def span_s(self) -> float:
        return (self.last_us - self.first_us) / 1e6 if self.first_us is not None and self.last_us is not None else 0.0

    def frame_rate_hz(self) -> float | None:
        span = self.span_s()
        return self.frames / span if span > 0 else None

    def shed_level(self) -> float | None:
        """The mean shedding level of the page's frames and views (0: the glasses kept up)."""
        return self.shed_sum / self.records if self.records else None

    def light_lux(self) -> float | None:
        """The light at the page while it was read, as the glasses measured it: the geometric mean
        over the frames and views that said it (None: none did)."""
        return math.exp(self.log_lux_sum / self.lit_records) if self.lit_records else None

    def head_speed_px_s(self) -> float | None:
        span = self.span_s()
        return self.path_px / span if span > 0 and self.last_scene is not None else None


@dataclass
class LivePage:
    index: int
    first_seq: int
    started_by: str  # "first", "break", "lost", "size"
    stitcher: PageStitcher | None
    last_seq: int = -1
    version: int = 0
    registered: int = 0
    rendered: RenderedPage | None = None  # the latest render; a finished page keeps only this
    motion: PageMotion = field(default_factory=PageMotion)

    @property
    def finished(self) -> bool:
        return self.stitcher is None


def find_bands(ink: np.ndarray, pad: int = 3) -> tuple[Box, ...]:
    """Text lines of a page as boxes: the row bands of its ink, each over its own ink columns."""
    boxes = []
    h, w = ink.shape
    for top, bottom, _ in text_bands(ink):
        cols = np.flatnonzero(ink[top:bottom].any(axis=0))
        if cols.size == 0:
            continue
        boxes.append((max(0, int(cols[0]) - pad), max(0, top - pad), min(w, int(cols[-1]) + 1 + pad), min(h, bottom + pad)))
    return tuple(boxes)


class Paginator:
    """Frames (in seq order) -> pages. Not thread-safe: one worker at a time."""

    def __init__(self, stitch: StitchConfig = StitchConfig(), cfg: PagingConfig = PagingConfig()) -> None:
        self.stitch_cfg = stitch
        self.cfg = cfg
        self.pages: list[LivePage] = []
        self._break_pending = False
        self._undecided: deque[tuple[int, FrameRecord]] = deque()  # added, not yet decided by the stitcher
        self._lost: list[tuple[int, FrameRecord]] = []  # the current stretch of failed frames
        self._checkpoint: tuple[PageStitcher, int, int, int] | None = None  # the page before the stretch
        self._scores: deque[float] = deque(maxlen=cfg.score_window)
        self._last_stitched: FrameRecord | None = None
        self.skipped = 0

    @property
    def current(self) -> LivePage | None:
        return self.pages[-1] if self.pages else None

    def page_break(self) -> None:
        """The next frame starts a new page (the glasses said so)."""
        if self.pages:
            self._break_pending = True

    def add(self, record: StoredFrame) -> None:
        """Stitch one frame; ValueError (and no change) for a frame the stitcher cannot use."""
        frame: FrameRecord = record
        if min(frame.mask.shape) < MIN_FRAME_SIDE:
            raise ValueError(f"frame seq {record.seq}: a {frame.mask.shape} mask is too small to stitch")
        if self._redundant(frame):
            self.skipped += 1
            return
        self._last_stitched = frame
        if not self.pages or self._break_pending:
            self._start(record.seq, "break" if self.pages else "first")
        page = self.pages[-1]
        assert page.stitcher is not None  # the last page is live
        if page.version and page.stitcher.canvas_pixels > self.cfg.max_page_pixels:
            page = self._start(record.seq, "size")
        self._feed(page, record.seq, frame)

    def _redundant(self, frame: FrameRecord) -> bool:
        last, cfg = self._last_stitched, self.cfg
        if last is None or cfg.min_stitch_gap_us <= 0 or self._break_pending:
            return False
        near = np.hypot(frame.gaze_px[0] - last.gaze_px[0], frame.gaze_px[1] - last.gaze_px[1]) <= cfg.same_place_px
        return bool(near and 0 <= frame.t_us - last.t_us < cfg.min_stitch_gap_us)

    def _start(self, seq: int, reason: str) -> LivePage:
        if self.pages:
            self._finish(self.pages[-1])
        page = LivePage(len(self.pages), seq, reason, PageStitcher(self.stitch_cfg))
        self.pages.append(page)
        self._break_pending = False
        self._undecided.clear()
        self._lost = []
        self._checkpoint = None
        self._scores.clear()
        return page

    def _finish(self, page: LivePage) -> None:
        """A page no frame will reach again: render it once and free its stitcher."""
        if page.stitcher is not None and page.version:
            page.rendered = self.render(page)
        page.stitcher = None

    def _feed(self, page: LivePage, seq: int, frame: FrameRecord) -> None:
        assert page.stitcher is not None
        placements = page.stitcher.add(frame)  # decides earlier frames (first in, first out)
        page.motion.add(frame)
        self._undecided.append((seq, frame))
        page.last_seq = seq
        for placement in placements:
            decided_seq, _ = self._undecided.popleft()
            if placement.outcome == "blank":
                continue
            weak = bool(self._scores) and placement.score < statistics.median(self._scores) - self.cfg.weak_drop
            if placement.outcome == "registered" and not weak:
                page.registered += 1
                self._scores.append(placement.score)
                self._lost, self._checkpoint = [], None
            elif page.registered >= self.cfg.settled_frames:
                if not self._lost:
                    self._checkpoint = (page.stitcher.fork(), page.version, page.registered, page.last_seq)
                self._lost.append((decided_seq, placement.frame))
                if self._is_lost():
                    self._restart_from_lost()
                    return
        page.version = page.stitcher.frames_used

    def _is_lost(self) -> bool:
        lost, cfg = self._lost, self.cfg
        return len(lost) >= cfg.lost_min_frames and lost[-1][1].t_us - lost[0][1].t_us >= cfg.lost_after_s * 1e6

    def _restart_from_lost(self) -> None:
        """Registration is lost: the wearer reads other text. The failed stretch and the frames
        still undecided start the new page."""
        replay = self._lost + list(self._undecided)
        if self._checkpoint is not None:
            old = self.pages[-1]
            old.stitcher, old.version, old.registered, _ = self._checkpoint
            old.last_seq = replay[0][0] - 1
        page = self._start(replay[0][0], "lost")
        for seq, frame in replay:
            self._feed(page, seq, frame)

    def render(self, page: LivePage) -> RenderedPage | None:
        """The page's current version (cached: rendering costs about 100 ms)."""
        if page.stitcher is None or (page.rendered is not None and page.rendered.version == page.version):
            return page.rendered
        stitched = page.stitcher.snapshot(positions=False)
        if stitched.image.size == 0:
            return None
        ink = stitched.image
        page.rendered = RenderedPage(
            page.index, page.version, stitched.to_grey(), ink, find_bands(ink), page.first_seq, page.last_seq,
            views=stitched.views, motion=replace(page.motion),
        )
        return page.rendered
