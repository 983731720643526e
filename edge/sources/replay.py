"""Replay of a recorded RAW file as a live :class:`EventSource` (CI, benchmarks, demos).

A reader thread decodes the file into ``slice_us`` time slices and hands them to the sink, paced
at wall-clock speed (``speed=1``), N times faster (``speed=N``) or as fast as the sink takes them
(``speed=None``). ``set_roi`` crops in software, as the sensor's ROI would.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from darkread.edge.events import Events, empty_events
from darkread.edge.io.plausibility import TimeCheck
from darkread.edge.io.raw_header import read_raw_header
from darkread.edge.sources.base import EventSink

logger = logging.getLogger(__name__)

DEFAULT_SLICE_US = 1_000


def parse_speed(text: str | float | None) -> float | None:
    """``"max"``/``0``/None -> None (as fast as possible); otherwise a positive factor."""
    if text is None or (isinstance(text, str) and text.strip().lower() in {"max", "inf", ""}):
        return None
    value = float(text)
    if value < 0:
        raise ValueError(f"replay speed must be positive or 'max', got {text!r}")
    return None if value == 0 else value


class ReplaySource:
    """Plays ``raw_path`` into a sink from its own thread; ``finished`` is set at the end."""

    def __init__(
        self,
        raw_path: str | Path,
        *,
        speed: float | None = 1.0,
        slice_us: int = DEFAULT_SLICE_US,
        chunk_bytes: int = 1 << 18,
    ) -> None:
        self.raw_path = Path(raw_path)
        header = read_raw_header(self.raw_path)  # fails early on a missing or unknown file
        self.width, self.height = int(header.width), int(header.height)
        if speed is not None and speed <= 0:
            raise ValueError(f"replay speed must be positive (or None for as fast as possible), got {speed}")
        if slice_us <= 0:
            raise ValueError(f"slice_us must be positive, got {slice_us}")
        self.speed = speed
        self.slice_us = int(slice_us)
        self.chunk_bytes = int(chunk_bytes)
        self.finished = threading.Event()
        self.error: BaseException | None = None
        self.problems: list[str] = []  # what makes the stream implausible (set when the replay ends)
        self._reader: Any = None
        self._time_check = TimeCheck()
        self._roi: tuple[int, int, int, int] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._events_out = 0
        self._slices = 0
        self._first_t: int | None = None
        self._last_t: int | None = None
        self._wall_s = 0.0
        self._anchor: tuple[float, int] | None = None  # (wall clock, event time) of the first slice

    def start(self, sink: EventSink) -> None:
        if self._thread is not None:
            raise RuntimeError("a replay source plays once; make a new one to replay again")
        self._thread = threading.Thread(target=self._run, args=(sink,), name="replay-reader", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=10.0)

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until the replay reached the end of the file (or was stopped)."""
        return self.finished.wait(timeout_s)

    def set_roi(self, x0: int, y0: int, width: int, height: int) -> None:
        if width <= 0 or height <= 0 or x0 < 0 or y0 < 0:
            raise ValueError(f"ROI must be non-negative with a positive size, got ({x0}, {y0}, {width}, {height})")
        full = (x0, y0, width, height) == (0, 0, self.width, self.height)
        self._roi = None if full else (x0, y0, width, height)

    @property
    def stats(self) -> dict[str, float]:
        span_s = (self._last_t - self._first_t) / 1e6 if self._first_t is not None and self._last_t is not None else 0.0
        return {
            "events_out": float(self._events_out),
            "slices": float(self._slices),
            "recording_s": span_s,
            "wall_s": self._wall_s,
            "realtime_factor": span_s / self._wall_s if self._wall_s > 0 else 0.0,
        }

    def _slice_iter(self) -> Iterable[Events]:
        from darkread.edge.io.raw import RawReader

        self._reader = RawReader(self.raw_path, chunk_bytes=self.chunk_bytes)
        return time_slices(self._reader, self.slice_us)

    def _judge(self) -> None:
        """After the replay: name what makes the stream implausible (``problems``)."""
        from darkread.edge.io.plausibility import problems

        if self._reader is None:
            return
        header = self._reader.header
        self.problems = problems(self._reader.stats, header.format, header.width, header.height, self._time_check)
        for problem in self.problems:
            logger.warning("%s: %s", self.raw_path, problem)

    def _apply_roi(self, events: Events) -> Events:
        if self._roi is None:
            return events
        x0, y0, w, h = self._roi
        dx = events["x"] - np.uint16(x0)
        dy = events["y"] - np.uint16(y0)
        return events[(dx < w) & (dy < h)]

    def _run(self, sink: EventSink) -> None:
        started = time.perf_counter()
        try:
            for events in self._slice_iter():
                if self._stop.is_set():
                    break
                self._slices += 1
                if self._first_t is None:
                    self._first_t = int(events["t"][0])
                if self.speed is not None and not self._wait_until(events):
                    break
                self._last_t = int(events["t"][-1])
                self._time_check.add(events["t"])
                events = self._apply_roi(events)
                if events.shape[0] == 0:
                    continue
                self._events_out += int(events.shape[0])
                sink(events)
        except BaseException as exc:  # surfaced through ``error``; the daemon exits non-zero
            self.error = exc
            logger.exception("replay of %s failed", self.raw_path)
        finally:
            self._wall_s = time.perf_counter() - started
            if self.error is None and not self._stop.is_set():
                self._judge()
            self.finished.set()
            logger.info("replay of %s ended: %s", self.raw_path.name, {k: round(v, 3) for k, v in self.stats.items()})

    def _wait_until(self, events: Events) -> bool:
        """Sleep until the wall clock reaches the slice's last event; False when stopped meanwhile.

        The clock is anchored at the first slice, so opening and decoding the file does not make
        the first slices late.
        """
        assert self.speed is not None
        t_last = int(events["t"][-1])
        if self._anchor is None:
            self._anchor = (time.perf_counter(), t_last)
        anchor_wall, anchor_t = self._anchor
        due = anchor_wall + (t_last - anchor_t) / 1e6 / self.speed
        delay = due - time.perf_counter()
        return delay <= 0 or not self._stop.wait(delay)


def time_slices(chunks: Iterable[Events], slice_us: int) -> Iterator[Events]:
    """Re-cut decoded chunks into slices on a ``slice_us`` time grid; empty slices are skipped.

    A slice is yielded once a later event proves it complete (or at the end of the stream).
    """
    carry = empty_events()
    for chunk in chunks:
        events = np.concatenate([carry, chunk]) if carry.shape[0] else chunk
        if events.shape[0] == 0:
            continue
        t = events["t"]
        open_from = (int(t[-1]) // slice_us) * slice_us  # the newest slice may still grow
        cut = int(np.searchsorted(t, open_from, side="left"))
        carry = events[cut:]
        yield from _split_on_grid(events[:cut], slice_us)
    yield from _split_on_grid(carry, slice_us)


def _split_on_grid(events: Events, slice_us: int) -> Iterator[Events]:
    if events.shape[0] == 0:
        return
    keys = events["t"] // slice_us
    starts = np.flatnonzero(np.diff(keys)) + 1
    yield from np.split(events, starts)
