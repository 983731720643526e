"""Slicing an event stream into windows, and replaying the windows at recording speed.

``EventsIterator`` follows OpenEB's ``metavision_core.event_io.EventsIterator``: ``delta_t`` mode
yields fixed time windows ``[s, s + delta_t)`` (an empty window is a zero-length array, never
``None``), ``n_events`` mode yields fixed counts (the last slice may be shorter). Unlike OpenEB,
times are absolute sensor time, so by default the first window starts at the first event's time
rounded down to a multiple of ``delta_t`` rather than at 0. The source is a RAW file (read in
bounded memory with :class:`RawReader`) or any iterable of time-sorted event chunks.

``PacedReplay`` yields those windows at wall-clock speed; its clock and sleep are injectable so tests
run on a fake clock.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Generator, Iterable, Iterator

import numpy as np

from darkread.edge.events import Events, concat_events, empty_events
from darkread.edge.io.raw import RawReader

__all__ = ["EventsIterator", "PacedReplay"]

MODES = ("delta_t", "n_events")
DEFAULT_SIZE = (720, 1280)  # (height, width) of the IMX636, for sources that do not say


class EventsIterator:
    """Windows of events from a RAW file or an iterable of event chunks (iterable once)."""

    def __init__(
        self,
        source: str | os.PathLike[str] | Iterable[Events],
        mode: str = "delta_t",
        delta_t: int = 10_000,
        n_events: int = 10_000,
        start_ts: int | None = None,
        max_duration: int | None = None,
        *,
        sensor_size: tuple[int, int] | None = None,
        chunk_bytes: int = 1 << 20,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if delta_t <= 0 or n_events <= 0:
            raise ValueError("delta_t and n_events must be positive")
        if max_duration is not None and max_duration <= 0:
            raise ValueError("max_duration must be positive")
        if isinstance(source, (str, os.PathLike)):
            self.reader: RawReader | None = RawReader(source, chunk_bytes=chunk_bytes)
            self._chunks: Iterable[Events] = self.reader
            size = self.reader.get_size()
        else:
            self.reader, self._chunks = None, source
            get_size = getattr(source, "get_size", None)
            size = get_size() if callable(get_size) else DEFAULT_SIZE
        self._size = sensor_size or size
        self.mode, self.delta_t, self.n_events = mode, delta_t, n_events
        self.start_ts, self.max_duration = start_ts, max_duration
        self.current_time: int | None = None  # end of the last window yielded (µs)

    def get_size(self) -> tuple[int, int]:
        """(height, width), as OpenEB's iterator reports it."""
        return self._size

    def get_current_time(self) -> int | None:
        return self.current_time

    def __iter__(self) -> Iterator[Events]:
        chunks = (c for c in self._chunks if len(c))
        if self.mode == "delta_t":
            return self._by_time(chunks)
        return self._by_count(chunks)

    def _bounds(self, first_t: int) -> tuple[int, int | None]:
        start = self.start_ts if self.start_ts is not None else first_t // self.delta_t * self.delta_t
        return start, (start + self.max_duration if self.max_duration is not None else None)

    def _by_time(self, chunks: Iterator[Events]) -> Iterator[Events]:
        pending, start, stop = empty_events(), 0, None
        for chunk in chunks:
            if self.current_time is None:
                start, stop = self._bounds(int(chunk["t"][0]))
                self.current_time = start
            buf = concat_events((pending, chunk)) if len(pending) else chunk
            buf = buf[np.searchsorted(buf["t"], start) :] if buf["t"][0] < start else buf
            if not len(buf):
                continue
            last = int(buf["t"][-1])
            done = stop is not None and last >= stop
            end = last if stop is None else min(last, stop)  # windows ending at or before `end` are complete
            n_windows = -(-(end - start) // self.delta_t) if done else max(0, (end - start) // self.delta_t)
            pending = yield from self._windows(buf, start, n_windows, stop)
            start += n_windows * self.delta_t
            if done:
                return
        if len(pending):
            last = int(pending["t"][-1])
            yield from self._windows(pending, start, (last - start) // self.delta_t + 1, stop)

    def _windows(self, buf: Events, start: int, count: int, stop: int | None) -> Generator[Events, None, Events]:
        """Yield ``count`` windows from ``start``; returns the events after them."""
        ends = start + self.delta_t * np.arange(1, count + 1, dtype=np.int64)
        if stop is not None:
            ends = np.minimum(ends, stop)
        # a running maximum keeps the cuts ordered when times jitter back by a few µs (real sensors)
        cuts = np.maximum.accumulate(np.searchsorted(buf["t"], ends, side="left"))
        begin = 0
        for end_t, cut in zip(ends.tolist(), cuts.tolist()):
            self.current_time = end_t
            yield buf[begin:cut]
            begin = cut
        return buf[begin:]

    def _by_count(self, chunks: Iterator[Events]) -> Iterator[Events]:
        pending, start, stop = empty_events(), None, None
        for chunk in chunks:
            if start is None:
                start, stop = self._bounds(int(chunk["t"][0]))
            buf = concat_events((pending, chunk)) if len(pending) else chunk
            t = buf["t"]
            if t[0] < start:
                buf = buf[np.searchsorted(t, start) :]
            done = stop is not None and len(buf) > 0 and buf["t"][-1] >= stop
            if done and stop is not None:
                buf = buf[: np.searchsorted(buf["t"], stop)]
            whole = len(buf) // self.n_events * self.n_events
            for begin in range(0, whole, self.n_events):
                window = buf[begin : begin + self.n_events]
                self.current_time = int(window["t"][-1]) + 1
                yield window
            pending = buf[whole:]
            if done:
                break
        if len(pending):
            self.current_time = int(pending["t"][-1]) + 1
            yield pending


class PacedReplay:
    """Yield slices no faster than the recording ran, times ``speed`` (``None``: no pacing).

    A slice's time is the source's ``get_current_time()`` when it has one (the window end, so empty
    windows pace too), else its last event's time. ``max_lag_s`` records how far behind the
    consumer fell (wall-clock seconds), beyond ``batch_s``: when a slice is due the replay sleeps
    that much longer and then hands over every slice due meanwhile at once, as a camera's buffer
    does (never early, at most ``batch_s`` late), so a replay of short slices wakes no more often.
    ``coalesce`` (paced only): those slices are handed over joined, one array per wake-up (empty ones dropped,
    at most ``MAX_COALESCED`` slices each), as a camera's driver hands over what its USB transfers
    queued: a consumer that fell behind gets fewer, larger chunks and catches up.
    """

    MAX_COALESCED = 64

    def __init__(
        self,
        slices: Iterable[Events],
        speed: float | None = 1.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], object] = time.sleep,
        batch_s: float = 0.0,
        coalesce: bool = False,
    ) -> None:
        if speed is not None and speed <= 0:
            raise ValueError(f"speed must be positive or None, got {speed}")
        if batch_s < 0:
            raise ValueError(f"batch_s must not be negative, got {batch_s}")
        self.slices, self.speed, self.clock, self.sleep = slices, speed, clock, sleep
        self.batch_s = batch_s
        self.coalesce = coalesce
        self.max_lag_s = 0.0

    def _slice_time(self, events: Events) -> int | None:
        get_time = getattr(self.slices, "get_current_time", None)
        now = get_time() if callable(get_time) else None
        if now is None and len(events):
            now = int(events["t"][-1])
        return now

    def __iter__(self) -> Iterator[Events]:
        origin: tuple[float, int] | None = None  # (wall clock, sensor µs) of the first timed slice
        due_now: list[Events] = []  # (coalescing) the slices due at this wake-up
        for events in self.slices:
            sensor_us = self._slice_time(events)
            if self.speed is not None and sensor_us is not None:
                if origin is None:
                    origin = (self.clock(), sensor_us)
                due = origin[0] + (sensor_us - origin[1]) / 1e6 / self.speed
                wait = due - self.clock()
                if wait > 0:
                    if due_now:
                        yield _joined(due_now)
                        due_now = []
                    self.sleep(wait + self.batch_s)
                elif -wait > self.batch_s:
                    self.max_lag_s = max(self.max_lag_s, -wait - self.batch_s)
            if not self.coalesce or self.speed is None:  # (unpaced: each slice as it comes, for a lossless replay)
                yield events
            elif events.shape[0]:
                due_now.append(events)
                if len(due_now) >= self.MAX_COALESCED:
                    yield _joined(due_now)
                    due_now = []
        if due_now:
            yield _joined(due_now)


def _joined(slices: list[Events]) -> Events:
    return slices[0] if len(slices) == 1 else concat_events(slices)
