"""A fixed-size ring of the newest events between the sensor drain thread and the pipeline.

The drain thread must never block on the pipeline (the sensor's own FIFO would overflow), so the
ring overwrites its oldest events instead of waiting, and counts what it dropped. Storage is one
preallocated structured array; a push is at most two slice copies.

Events are assumed to be pushed in time order (as a sensor or a file delivers them); ``since``
relies on it.
"""

from __future__ import annotations

import threading

import numpy as np

from darkread.edge.events import Events, empty_events


class EventRing:
    """Newest ``capacity`` events; one writer and any number of readers (a lock guards each call)."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"ring capacity must be positive, got {capacity}")
        self.capacity = int(capacity)
        self._buffer = empty_events(self.capacity)
        # the same bytes as opaque 16-byte records: numpy copies a structured dtype with padding
        # field by field (~25x slower than a plain copy of the records)
        self._records = self._buffer.view(np.dtype((np.void, self._buffer.dtype.itemsize)))
        self._head = 0  # next slot to write
        self._count = 0
        self._lock = threading.Lock()
        self.total_pushed = 0
        self.dropped = 0  # events pushed and overwritten (or never stored) before anyone could read them
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
                self.dropped += self._count + n - self.capacity
                self._records[:] = events[n - self.capacity :]
                self._head, self._count = 0, self.capacity
            else:
                self.dropped += max(0, self._count + n - self.capacity)
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

    def last(self, n: int) -> Events:
        """A copy of the newest ``n`` events, oldest first (fewer if fewer are held)."""
        with self._lock:
            n = max(0, min(int(n), self._count))
            if n == 0:
                return empty_events()
            older, newer = self._segments()
            if n <= newer.shape[0]:
                return newer[newer.shape[0] - n :].copy()
            return np.concatenate([older[older.shape[0] - (n - newer.shape[0]) :], newer])

    def since(self, t_us: int) -> Events:
        """A copy of the held events with ``t >= t_us``, oldest first."""
        with self._lock:
            older, newer = self._segments()
            parts = [seg[np.searchsorted(seg["t"], t_us, side="left") :] for seg in (older, newer)]
            return np.concatenate(parts) if parts[0].shape[0] else parts[1].copy()

    def clear(self) -> None:
        with self._lock:
            self._head = self._count = 0
