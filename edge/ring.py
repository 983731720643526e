"""A fixed-size ring of the newest events between the sensor drain thread and the pipeline.

The drain thread must never block on the pipeline (the sensor's own FIFO would overflow), so the
ring overwrites its oldest events instead of waiting, and counts how many it overwrote. That is
history, not loss: every event went through ``Pipeline.sink`` (the scene tracker, the window's
count) as it arrived, and a window reads only its newest events; a window that was never
inferred because inference fell behind is counted as ``frames_skipped``. Storage is one
preallocated structured array; a push is at most two slice copies.

Events are assumed to be pushed in time order (as a sensor or a file delivers them); ``since``
relies on it.
"""

from __future__ import annotations

import threading

import numpy as np

from darkread.edge.events import Events, concat_events, copy_events, empty_events


class EventRing:
    """Newest ``capacity`` events; one writer and any number of readers (a lock guards each call)."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"ring capacity must be positive, got {capacity}")
        self.capacity = int(capacity)
        self._buffer = empty_events(self.capacity)
        # touch every page now: a fresh zeroed array is mapped lazily, and its first pass would
        # page-fault on the hot path (2048 faults for the default 8 MB, ~1 ms per 100k events)
        self._buffer.view(np.uint8).fill(0)
        # the same bytes as opaque 16-byte records: numpy copies a structured dtype with padding
        # field by field (~25x slower than a plain copy of the records)
        self._records = self._buffer.view(np.dtype((np.void, self._buffer.dtype.itemsize)))
        self._head = 0  # next slot to write
        self._count = 0
        self._lock = threading.Lock()
        self.total_pushed = 0
        self.overwritten = 0  # events pushed and later overwritten by newer ones (or never stored: a push larger than the ring)
        self.newest_t: int | None = None

    def __len__(self) -> int:
        return self._count

    def push(self, events: Events) -> None:
        n = int(events.shape[0])
        if n == 0:
            return
        if events.dtype != self._buffer.dtype:
            events = events.astype(self._buffer.dtype)
        events = np.ascontiguousarray(events).view(self._records.dtype)
        with self._lock:
            self.total_pushed += n
            if n >= self.capacity:  # only the newest `capacity` survive
                self.overwritten += self._count + n - self.capacity
                self._records[:] = events[n - self.capacity :]
                self._head, self._count = 0, self.capacity
            else:
                self.overwritten += max(0, self._count + n - self.capacity)
                first = min(n, self.capacity - self._head)
                self._records[self._head : self._head + first] = events[:first]
                self._records[: n - first] = events[first:]
                self._head = (self._head + n) % self.capacity
                self._count = min(self.capacity, self._count + n)
            self.newest_t = int(self._buffer["t"][(self._head - 1) % self.capacity])

    def _segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Held events as (older, newer) views, oldest first; call with the lock held."""
        start = (self._head - self._count) % self.capacity
        if start + self._count <= self.capacity:
            return self._buffer[start : start + self._count], self._buffer[:0]
        return self._buffer[start:], self._buffer[: self._head]

    def last(self, n: int, until_t: int | None = None) -> Events:
        """A copy of the newest ``n`` events, oldest first (fewer if fewer are held); with
        ``until_t`` the newest ``n`` of those with ``t <= until_t`` (the events after it are not copied)."""
        with self._lock:
            older, newer = self._segments()
            if until_t is not None and self._count and self.newest_t is not None and self.newest_t > until_t:
                if newer.shape[0] and newer["t"][0] <= until_t:
                    newer = newer[: int(np.searchsorted(newer["t"], until_t, side="right"))]
                else:
                    older, newer = older[: int(np.searchsorted(older["t"], until_t, side="right"))], older[:0]
            n = max(0, min(int(n), older.shape[0] + newer.shape[0]))
            if n == 0:
                return empty_events()
            if n <= newer.shape[0]:
                return copy_events(newer[newer.shape[0] - n :])
            return concat_events([older[older.shape[0] - (n - newer.shape[0]) :], newer])

    def since(self, t_us: int) -> Events:
        """A copy of the held events with ``t >= t_us``, oldest first."""
        with self._lock:
            older, newer = self._segments()
            parts = [seg[np.searchsorted(seg["t"], t_us, side="left") :] for seg in (older, newer)]
            return concat_events(parts) if parts[0].shape[0] else copy_events(parts[1])

    def clear(self) -> None:
        with self._lock:
            self._head = self._count = 0
