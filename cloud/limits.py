"""Bounded cost per request: one reading per page however many ask at once, and a rate per key.

``SingleFlight`` keeps, per session, the task reading its current page (keyed by the session's
last stored seq): concurrent asks await the same task, a later ask of the unchanged page gets its
result, and a caller that gives up (the ask time limit) does not cancel it for the others.
``RateLimiter`` is a token bucket per API key; ``PerKeyCap`` bounds what one key holds at once.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Awaitable, Callable, Hashable
from typing import Any


class SingleFlight:
    """One running (or finished) computation per name; a new version replaces the old one."""

    def __init__(self) -> None:
        self._tasks: dict[Hashable, tuple[Hashable, asyncio.Task[Any]]] = {}

    def run(self, name: Hashable, version: Hashable, compute: Callable[[], Awaitable[Any]]) -> asyncio.Task[Any]:
        held = self._tasks.get(name)
        if held is not None and held[0] == version:
            task = held[1]
            if not (task.done() and (task.cancelled() or task.exception() is not None)):
                return task  # running, or finished well: share it
        task = asyncio.ensure_future(compute())
        self._tasks[name] = (version, task)
        return task

    def forget(self, name: Hashable) -> None:
        self._tasks.pop(name, None)


class RateLimiter:
    """Token bucket per key: ``per_minute`` sustained, ``burst`` at once."""

    def __init__(self, per_minute: float, burst: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.rate_s = per_minute / 60.0
        self.burst = burst
        self._clock = clock
        self._buckets: dict[str, tuple[float, float]] = {}  # key -> (tokens, when)

    def take(self, key: str) -> float:
        """0 when allowed (a token is taken); else the seconds until the next token."""
        now = self._clock()
        tokens, when = self._buckets.get(key, (float(self.burst), now))
        tokens = min(float(self.burst), tokens + (now - when) * self.rate_s)
        if tokens >= 1.0:
            self._buckets[key] = (tokens - 1.0, now)
            return 0.0
        self._buckets[key] = (tokens, now)
        return (1.0 - tokens) / self.rate_s if self.rate_s > 0 else math.inf


class PerKeyCap:
    """At most ``limit`` of something held at once per key (open event streams, syntheses)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._held: dict[str, int] = {}

    def try_acquire(self, key: str) -> bool:
        held = self._held.get(key, 0)
        if held >= self.limit:
            return False
        self._held[key] = held + 1
        return True

    def release(self, key: str) -> None:
        held = self._held.get(key, 0) - 1
        if held > 0:
            self._held[key] = held
        else:
            self._held.pop(key, None)
