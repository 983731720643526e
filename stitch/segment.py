"""Lines from the gaze track: a return sweep (a long jump left, not up) starts a new line.

The rule compares the launch point (the right edge of the last few samples) with the first sample
after the jump and the median of a few more, so tracker noise of 25-50 px neither starts nor hides
a line; an undershooting sweep and its corrective saccade left
count as one break (``min_line_frames``). The rule looks at the gaze track thinned to one frame per
``sweep_sample_ms``: frames come up to 300 a second while the tracker's rows come 60 a second, so
a frame-count context of consecutive frames would see only a slice of the (interpolated) saccade.
The same streaming decision serves the batch ``segment_lines`` and the incremental ``PageStitcher``.
"""

from __future__ import annotations

import copy
from collections import deque
from collections.abc import Sequence

import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.stitch.config import StitchConfig

LAUNCH_PCT = 75
CONFIRM_FRAC = 1.0


class LineSegmenter:
    """Streaming return-sweep detector.

    ``push`` returns the frames it has decided, each with ``True`` when it starts a new line; a
    frame is decided once ``sweep_confirm_frames`` later frames are known (``flush`` decides the
    rest with what there is).
    """

    def __init__(self, cfg: StitchConfig = StitchConfig()) -> None:
        self.cfg = cfg
        self._pending: deque[tuple[FrameRecord, bool]] = deque()  # (frame, is a sample of the track)
        self._sampled_ahead = 0  # samples among the pending frames after the first
        self._last_sample_us: int | None = None
        self._recent: deque[tuple[float, float]] = deque(maxlen=cfg.sweep_context_frames)
        self._line_x: list[float] = []
        self._since_break = 0
        self._started = False

    def fork(self) -> LineSegmenter:
        """An independent copy that shares the (immutable) frames: O(frames of the line), no mask copied."""
        twin = copy.copy(self)
        twin._pending = deque(self._pending)
        twin._recent = deque(self._recent, maxlen=self._recent.maxlen)
        twin._line_x = list(self._line_x)
        return twin

    def push(self, frame: FrameRecord) -> list[tuple[FrameRecord, bool]]:
        last = self._last_sample_us
        sample = last is None or frame.t_us - last >= self.cfg.sweep_sample_ms * 1000.0 or frame.t_us < last
        if sample:
            self._last_sample_us = frame.t_us
        if self._pending and sample:
            self._sampled_ahead += 1
        self._pending.append((frame, sample))
        decided = []
        while self._pending and (not self._pending[0][1] or self._sampled_ahead >= self.cfg.sweep_confirm_frames):
            decided.append(self._decide())
        return decided

    @property
    def pending(self) -> int:
        """Frames pushed but not yet decided."""
        return len(self._pending)

    def flush(self) -> list[tuple[FrameRecord, bool]]:
        decided = []
        while self._pending:
            decided.append(self._decide())
        return decided

    def _line_extent(self) -> float:
        if len(self._line_x) < 2:
            return 0.0
        lo, hi = np.percentile(self._line_x, [10, 90])
        return float(hi - lo)

    def _is_sweep(self) -> bool:
        cfg = self.cfg
        if not self._recent or self._since_break < cfg.min_line_frames:
            return False
        recent = np.asarray(self._recent)
        # where the eye was: the right edge of its last few samples (a sweep launches from the
        # line's end; a median would lag behind the last forward saccades)
        launch_x = float(np.percentile(recent[:, 0], LAUNCH_PCT))
        launch_y = float(np.median(recent[:, 1]))
        after = np.asarray([f.gaze_px for f, sample in self._pending if sample][: cfg.sweep_confirm_frames + 1])
        needed = max(cfg.sweep_min_px, cfg.sweep_line_fraction * self._line_extent())
        jumped_left = launch_x - after[0, 0] > needed
        # confirmed unless the eye came straight back (one wild sample); reading on to the right
        # along the new line is fine, hence half the jump
        stayed_left = launch_x - float(np.median(after[:, 0])) > needed * CONFIRM_FRAC
        went_up = launch_y - float(np.median(after[:, 1])) > cfg.sweep_max_rise_px
        return bool(jumped_left and stayed_left and not went_up)

    def _decide(self) -> tuple[FrameRecord, bool]:
        frame, sample = self._pending[0]
        rider = not sample and self._started  # rides along with the line of the sample before it
        new_line = False if rider else (not self._started) or self._is_sweep()
        self._pending.popleft()
        if self._pending and self._pending[0][1]:
            self._sampled_ahead -= 1
        if rider:
            return frame, False
        self._started = True
        if new_line:
            self._recent.clear()
            self._line_x = []
            self._since_break = 0
        self._recent.append(frame.gaze_px)
        self._line_x.append(frame.gaze_px[0])
        self._since_break += 1
        return frame, new_line


def segment_lines(frames: Sequence[FrameRecord], cfg: StitchConfig = StitchConfig()) -> list[list[FrameRecord]]:
    """Split frames (in time order) into lines at return sweeps."""
    segmenter = LineSegmenter(cfg)
    decided = [d for f in frames for d in segmenter.push(f)] + segmenter.flush()
    lines: list[list[FrameRecord]] = []
    for frame, new_line in decided:
        if new_line:
            lines.append([])
        lines[-1].append(frame)
    return lines
