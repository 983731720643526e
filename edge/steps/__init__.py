"""What the pipeline does with the events it gets: one interface, two strategies.

A :class:`Step` is handed what arrived since its last step (:class:`Pending`) and the event time
``t_us`` to act at; it makes frames from the ring's events (:class:`~darkread.edge.windows.Windows`)
and passes them, or views fused from them, to ``on_frame``. Where and when a step runs, on a
reconstruction thread (live) or on the reader's thread (lossless replays), is the pipeline's
business (:mod:`darkread.edge.pipeline`), not the step's.

- :class:`~darkread.edge.steps.on_change.OnChangeStep` (``[pipeline] infer = "on-change"``, the
  product): the gaze decides; one fused view per fixation.
- :class:`~darkread.edge.steps.every_window.EveryWindowStep` (``"every-window"``, for research and
  evaluation): a frame every ``n_events`` new events inside the window, sent as it is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from darkread.edge.frame import FrameResult
from darkread.edge.view_fusion import ViewRecord

FrameHandler = Callable[[FrameResult | ViewRecord, float], None]
"""Receives each frame (every-window) or view (on-change) and the ``time.monotonic()`` at which the
data that completed it arrived (its newest event, or the chunk that ended the fixation)."""


@dataclass
class Pending:
    """What the reader handed over since the last step: the events inside the window (every event
    before the first window is placed), all events, when the newest arrived (``time.monotonic()``)
    and when the oldest did (0.0: nothing since the last step; how long a live step lags)."""

    foveated: int = 0
    events: int = 0
    arrival: float = 0.0
    first_arrival: float = 0.0

    def add(self, foveated: int, events: int, arrival: float | None = None) -> None:
        self.foveated += foveated
        self.events += events
        if arrival is not None:
            self.arrival = arrival
            if not self.first_arrival and events:
                self.first_arrival = arrival

    def take(self) -> Pending:
        """The counts so far, reset to none (the newest arrival is kept: it stamps later steps too)."""
        taken = Pending(self.foveated, self.events, self.arrival, self.first_arrival)
        self.foveated = self.events = 0
        self.first_arrival = 0.0
        return taken


class Step(Protocol):
    """One inference strategy of the pipeline."""

    replay_grid_us: int | None
    """Lossless replays: one step per this much event time, whatever the chunking (a step may then
    wait for the next chunk to complete its slice); None: a step after a chunk whenever one is due."""

    def due(self, pending: Pending) -> bool:
        """Whether what arrived calls for a step now (else the period's timer brings the next)."""
        ...

    def skipped(self, pending: Pending) -> int:
        """The windows a step that comes this late jumps over (live: inference fell behind)."""
        ...

    def step(self, t_us: int, pending: Pending, final: bool = False) -> None:
        """One processing step at event time ``t_us`` (``final``: the stream ended)."""
        ...
