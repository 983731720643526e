"""When to infer and when a view is complete: the gaze decides, not the event count.

The information arrives at fixation rate (about four a second when reading), not at event rate.
So nothing is inferred while the eye is in a saccade or a blink (the window moves and the voxels
smear); during a fixation a frame is inferred when enough new events arrived or the window moved,
at most every ``min_interval_ms`` while frames still change the view, and no more (within
``settled_interval_ms``) once a frame the network was sure of agreed with it: at 100 lux two frames
of a fixation register onto each other at 0.85-0.93 and a third adds nothing, while in dim light
(and on small text) frames that agree are still noisy, so every window's worth of new events is
inferred and averaged in, as the every-window mode would. The frames of one fixation are fused into one view that is
sent when the fixation ends, and every ``view_every_ms`` during a long one.

``GazeGate`` feeds the tracker's rows (from the :class:`~darkread.edge.gaze.GazeLookup`, on the
event clock) into the online classifier of :mod:`darkread.edge.gaze_events` and says what the eye
is doing at an event time. ``ViewTrigger`` is the pure decision on top of it. Both are owned by
one thread (the pipeline's processing step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from darkread.edge.config import PipelineConfig
from darkread.edge.gaze import GazeLookup
from darkread.edge.gaze_events import EventKind, GazeEventClassifier, GazeEventConfig, GazeStatus


class GazeGate:
    """The classifier fed from a gaze lookup's rows as the event clock advances."""

    def __init__(self, gaze: GazeLookup, cfg: GazeEventConfig | None = None) -> None:
        self.gaze = gaze
        rows = getattr(gaze, "rows", None)
        if rows is None:
            raise TypeError(f"{type(gaze).__name__} has no rows(t0, t1): the on-change mode needs the tracker's rows")
        self._rows = rows
        self.cfg = cfg or GazeEventConfig().for_rate(getattr(gaze, "rate_hz", GazeEventConfig().rate_hz))
        self.classifier = GazeEventClassifier(self.cfg)
        self._until: int | None = None
        self._last_row: int | None = None
        self._status = GazeStatus(None, 0, math.nan, math.nan, False)

    def update(self, t_event_us: int) -> GazeStatus:
        """Push the rows up to ``t_event_us`` and return what the eye does then (cached between rows)."""
        t_from = self._until if self._until is not None else t_event_us - 1_000_000
        if t_event_us <= t_from:
            return self._status
        t, yaw, pitch = self._rows(t_from, t_event_us)
        self._until = int(t_event_us)
        pushed = False
        if t.shape[0]:
            # CPF (x left, y up) -> degrees right and down, as ``angles_from_cpf`` (same arithmetic)
            rows = [(ti, -math.degrees(a), -math.degrees(b)) for ti, a, b in zip(t.tolist(), yaw.tolist(), pitch.tolist())]
            self.classifier.push_rows(rows)
            self._last_row, pushed = rows[-1][0], True
        if self._last_row is not None and t_event_us - self._last_row > self.cfg.blink_gap_us:
            # no rows for longer than a blink gap (a live feed drops invalid ones): the clock runs on
            self.classifier.push_rows([(int(t_event_us), math.nan, math.nan)])
            self._last_row, pushed = int(t_event_us), True
        if not pushed:
            return self._status
        self._status = self.classifier.status()
        return self._status


def fixation_key(status: GazeStatus) -> int | None:
    """An identity of the current fixation (its first row), None outside fixations."""
    return int(status.since_us) if status.kind == EventKind.FIXATION else None


@dataclass
class ViewTrigger:
    """The decision of one processing step, given what the eye does and what arrived since."""

    settings: PipelineConfig
    last_infer_us: int | None = None
    last_origin: tuple[int, int] | None = None
    settled: bool = False  # the last frame agreed with its view: the next may wait longer

    def reset(self) -> None:
        self.last_infer_us = None
        self.last_origin = None
        self.settled = False

    def interval_us(self) -> float:
        """The rate bound now: short while frames still change the view, longer once they agree."""
        s = self.settings
        return (s.settled_interval_ms if self.settled else s.min_interval_ms) * 1e3

    def due(self, t_us: int, fixation_start_us: int, new_events: int, in_fixation: int, origin: tuple[int, int]) -> bool:
        """Infer now? ``new_events``: window events since the last inference; ``in_fixation``: since
        the fixation started. The first frame comes ``first_wait_ms`` into the fixation with whatever
        it collected (at least ``min_events``, at most ``n_events``: fewer in low light); later ones
        when a window's worth is new or the window moved, ``interval_us()`` apart."""
        s = self.settings
        if self.last_infer_us is None:  # a landing the classifier may still revise: wait a little
            return in_fixation >= s.min_events and t_us - fixation_start_us >= s.first_wait_ms * 1e3
        if t_us - self.last_infer_us < self.interval_us():
            return False
        moved = self.last_origin is not None and math.dist(origin, self.last_origin) >= s.move_px
        return (moved and new_events > 0) or new_events >= s.renew_fraction * s.n_events

    def ready(self, t_us: int, fixation_start_us: int) -> bool:
        """The time conditions of ``due`` alone (cheap: checked before the gaze is looked up)."""
        s = self.settings
        if self.last_infer_us is None:
            return t_us - fixation_start_us >= s.first_wait_ms * 1e3
        return t_us - self.last_infer_us >= self.interval_us()

    def inferred(self, t_us: int, origin: tuple[int, int], match_score: float | None = None, doubt: float | None = None) -> None:
        """An inference at ``t_us``; ``match_score``: how well its frame registered onto the view
        (None: it started the view or was placed unmatched); ``doubt``: how unsure the network was
        of it (``view_fusion.doubt``). A frame agreeing with its view settles it only if the network
        was sure of it (``settle_max_doubt``): a doubtful one (dim light, small text) agrees with
        its view and is still noisy, and the view is better for every frame averaged in."""
        self.last_infer_us = int(t_us)
        self.last_origin = origin
        sure = doubt is None or doubt <= self.settings.settle_max_doubt
        self.settled = sure and match_score is not None and match_score >= self.settings.settled_score
