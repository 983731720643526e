"""What a live edge that cannot keep up gives up: fewer inferences per view, never events.

On a wearable's CPU budget the reconstruction thread may fall behind the events. The ring is of a
fixed size, so memory never grows with the lag; but views would come later and later, and their
frames would be cut from events the ring has already overwritten. The lag is visible at each live
step (:meth:`darkread.edge.pipeline.Pipeline._step_now`): how long the oldest data it takes has
waited. When it stays too long the edge sheds the work it can best afford to lose, a view's later
frames: first a view takes at most its dithered pair, then only its first frame, then a fixation
whose window the last view already mostly covers gets no view of its own (reading moves the gaze
a third to a half of a window per fixation, so every other view still covers the line, and the
stitcher registers views that overlap by half). What was already made and handed to the uplink
(the spool's promise) is never touched. It recovers a level at a time once the steps are prompt
again for a while.

The decision is the pure :func:`shed_level`; :class:`LoadShedder` keeps its state, counts and logs.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

logger = logging.getLogger(__name__)

LEVELS = ("none", "a view's frames capped at its dithered pair", "one frame per view",
          "one frame per view, and none where the last view covers the window")
FRAMES_PER_VIEW = (None, 2, 1, 1)  # a view's frame budget at each level (None: as the view trigger decides)
SKIP_COVERED_FROM = 3  # the level from which a fixation inside the last view gets no view
COVERED_SHARE = 0.5  # "inside the last view": this share of the window or more lies in the last view's


@dataclass(frozen=True)
class ShedConfig:
    high_lag_s: float = 0.3  # a step that waited this long sheds one level more (a CFS quota alone delays a burst by up to its 100-ms period) ...
    low_lag_s: float = 0.05  # ... and steps this prompt ...
    calm_steps: int = 200  # ... this many in a row (a few hundred ms of live steps) give one level back


def shed_level(lag_s: float, level: int, calm: int, cfg: ShedConfig = ShedConfig()) -> tuple[int, int]:
    """The shedding level after a step that waited ``lag_s``, from ``level`` and the run of ``calm``
    prompt steps before it: (new level, new run of prompt steps)."""
    top = len(LEVELS) - 1
    if lag_s >= cfg.high_lag_s:
        return min(level + 1, top), 0
    if lag_s > cfg.low_lag_s:
        return level, 0
    calm += 1
    if level > 0 and calm >= cfg.calm_steps:
        return level - 1, 0
    return level, calm


def frames_per_view(level: int) -> int | None:
    """How many frames a view may take at ``level`` (None: no cap)."""
    return FRAMES_PER_VIEW[level]


def overlap_share(window: tuple[int, int, int, int], other: tuple[int, int, int, int]) -> float:
    """The share of ``window``'s area (x0, y0, width, height) that lies inside ``other``."""
    x0, y0, w, h = window
    ox, oy, ow, oh = other
    dx = max(0, min(x0 + w, ox + ow) - max(x0, ox))
    dy = max(0, min(y0 + h, oy + oh) - max(y0, oy))
    return dx * dy / max(w * h, 1)


def skip_covered(level: int, window: tuple[int, int, int, int], last_view: tuple[int, int, int, int] | None) -> bool:
    """Whether, at ``level``, a new fixation's ``window`` gets no view: the last view sent covers
    at least ``COVERED_SHARE`` of it."""
    return level >= SKIP_COVERED_FROM and last_view is not None and overlap_share(window, last_view) >= COVERED_SHARE


class LoadShedder:
    """The current level, updated after every live step; a change is logged (and counted by the caller)."""

    def __init__(self, cfg: ShedConfig = ShedConfig()) -> None:
        self.cfg = cfg
        self.level = 0
        self._calm = 0

    def observe(self, lag_s: float) -> bool:
        """One live step waited ``lag_s``; True when the level changed."""
        level, self._calm = shed_level(lag_s, self.level, self._calm, self.cfg)
        if level == self.level:
            return False
        if level > self.level:
            logger.warning("edge falling behind (a step waited %.0f ms): shedding, %s", lag_s * 1e3, LEVELS[level])
        else:
            logger.info("edge keeping up again: shedding %s", LEVELS[level])
        self.level = level
        return True
