"""The contract every event source meets, so the real-time loop runs on a camera or a recording."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

from darkread.edge.events import Events

EventSink = Callable[[Events], None]
"""Receives decoded event chunks (sorted by ``t``, never empty) on the source's own thread."""


@runtime_checkable
class EventSource(Protocol):
    width: int
    height: int

    def start(self, sink: EventSink) -> None:
        """Start delivering decoded event chunks to ``sink`` from a reader thread; returns at once."""
        ...

    def stop(self) -> None:
        """Stop delivery; once it returns, ``sink`` is not called again."""
        ...

    def set_roi(self, x0: int, y0: int, width: int, height: int) -> None:
        """Restrict the sensor to a window (sources that cannot may ignore it)."""
        ...

    @property
    def stats(self) -> dict[str, float]:
        """Counters for logs and metrics; keys carry their unit."""
        ...
