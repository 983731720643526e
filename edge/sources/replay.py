"""Replay of a recorded RAW file as a live :class:`EventSource` (CI, benchmarks, demos).

A reader thread cuts the file into ``slice_us`` time slices with the OpenEB-style
:class:`~darkread.edge.io.iterator.EventsIterator` and hands the non-empty ones to the sink, paced
by :class:`~darkread.edge.io.iterator.PacedReplay` at wall-clock speed (``speed=1``), N times
faster (``speed=N``) or as fast as the sink takes them (``speed=None``). ``set_roi`` delivers
what the sensor's ROI would: the decoder skips the file's words outside it (``edge.io.evt3``), so
``events_out`` counts what would have crossed USB and ``words_outside_roi`` what never did. A new
ROI applies from the next chunk the decoder reads; while one is set the chunks are smaller
(``ROI_CHUNK_BYTES``), so a move takes effect within a few milliseconds of events, as a register
write does on the camera.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from darkread.core.errors import DarkreadError
from darkread.edge.events import Events
from darkread.edge.io.iterator import EventsIterator, PacedReplay
from darkread.edge.io.plausibility import TimeCheck, problems
from darkread.edge.io.raw import RawReader
from darkread.edge.io.raw_header import read_raw_header
from darkread.edge.sources.base import EventSink

logger = logging.getLogger(__name__)

DEFAULT_SLICE_US = 1_000
# a paced replay sleeps until a slice is due and this much longer, then hands over what came due
# meanwhile: as a camera's USB buffer delivers (late, never early), and one wake-up per 2 ms, not per slice
PACE_BATCH_S = 0.002
ROI_CHUNK_BYTES = 1 << 15  # a chunk of a full-sensor stream at 300 kev/s: about 18 ms of events


def parse_speed(text: str | float | None) -> float | None:
    """``"max"``/``0``/None -> None (as fast as possible); otherwise a positive factor."""
    if text is None or (isinstance(text, str) and text.strip().lower() in {"max", "inf", ""}):
        return None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if value < 0:
        raise ValueError(f"replay speed must be a positive number (1 = wall clock, 2 = twice as fast) or 'max', not {text!r}")
    return None if value == 0 else value


class ReplaySource:
    """Plays ``raw_path`` into a sink from its own thread; ``finished`` is set at the end."""

    def __init__(
        self,
        raw_path: str | Path,
        *,
        speed: float | None = 1.0,
        slice_us: int | None = DEFAULT_SLICE_US,
        chunk_bytes: int = 1 << 18,
    ) -> None:
        """``slice_us=None`` hands over the decoder's chunks as they are (``chunk_bytes`` of the file
        each): for an as-fast-as-possible replay into a sink that cuts them itself, which saves
        re-slicing and re-joining every chunk."""
        self.raw_path = Path(raw_path)
        header = read_raw_header(self.raw_path)  # fails early on a missing or unknown file
        self.width, self.height = int(header.width), int(header.height)
        if speed is not None and speed <= 0:
            raise ValueError(f"replay speed must be positive (or None for as fast as possible), got {speed}")
        if slice_us is not None and slice_us <= 0:
            raise ValueError(f"slice_us must be positive, got {slice_us}")
        if slice_us is None and speed is not None:
            raise ValueError("a paced replay needs time slices (slice_us); whole chunks replay as fast as possible")
        self.speed = speed
        self.slice_us = None if slice_us is None else int(slice_us)
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
        if self._reader is not None:
            self._apply_roi(self._reader)

    @property
    def roi(self) -> tuple[int, int, int, int]:
        """The window the replay delivers (x0, y0, width, height): the whole sensor without a ROI."""
        return self._roi or (0, 0, self.width, self.height)

    @property
    def roi_since_us(self) -> int | None:
        """The first event delivered under the ROI set last (None: none yet): events decoded before
        the ROI moved are still in flight after ``set_roi``, as a camera's are."""
        return self._reader.roi_since_us if self._reader is not None else None

    def _apply_roi(self, reader: RawReader) -> None:
        """The decoder's ROI, and its chunk size: small while a ROI is set (a move applies sooner)."""
        reader.set_roi(self._roi)
        reader.chunk_bytes = min(self.chunk_bytes, ROI_CHUNK_BYTES) if self._roi is not None else self.chunk_bytes

    @property
    def stats(self) -> dict[str, float]:
        span_s = (self._last_t - self._first_t) / 1e6 if self._first_t is not None and self._last_t is not None else 0.0
        return {
            "events_out": float(self._events_out),  # delivered: inside the ROI while one is set
            "words_outside_roi": float(self._reader.stats.words_outside_roi if self._reader is not None else 0),
            "slices": float(self._slices),
            "recording_s": span_s,
            "wall_s": self._wall_s,
            "realtime_factor": span_s / self._wall_s if self._wall_s > 0 else 0.0,
        }

    def _slice_iter(self) -> Iterable[Events]:
        """The file's time slices, paced; the pause between two slices ends early on ``stop``.

        The clock is anchored at the first slice, so opening and decoding the file does not make
        the first slices late.
        """
        if self.slice_us is None:
            self._reader = RawReader(self.raw_path, chunk_bytes=self.chunk_bytes)
            self._apply_roi(self._reader)
            return self._reader
        slices = EventsIterator(self.raw_path, delta_t=self.slice_us, chunk_bytes=self.chunk_bytes)
        self._reader = slices.reader
        assert self._reader is not None  # (a file's iterator has its reader)
        self._apply_roi(self._reader)
        return PacedReplay(slices, self.speed, clock=time.perf_counter, sleep=self._stop.wait, batch_s=PACE_BATCH_S,
                           coalesce=True)

    def _judge(self) -> None:
        """After the replay: name what makes the stream implausible (``problems``)."""
        if self._reader is None:
            return
        header = self._reader.header
        self.problems = problems(self._reader.stats, header.format, header.width, header.height, self._time_check)
        for problem in self.problems:
            logger.warning("%s: %s", self.raw_path, problem)

    def _run(self, sink: EventSink) -> None:
        started = time.perf_counter()
        try:
            for events in self._slice_iter():
                if self._stop.is_set():
                    break
                if events.shape[0] == 0:
                    continue
                self._slices += 1
                if self._first_t is None:
                    self._first_t = int(events["t"][0])
                self._last_t = int(events["t"][-1])
                self._time_check.add(events["t"])
                self._events_out += int(events.shape[0])
                sink(events)
        except BaseException as exc:  # surfaced through ``error``; the daemon exits non-zero
            self.error = exc
            if isinstance(exc, DarkreadError):  # says what failed in words (a corrupt RAW, a full spool disk)
                logger.error("replay of %s failed: %s", self.raw_path, exc)
            else:
                logger.exception("replay of %s failed", self.raw_path)
        finally:
            self._wall_s = time.perf_counter() - started
            if self.error is None and not self._stop.is_set():
                self._judge()
            self.finished.set()
            logger.info("replay of %s ended: %s", self.raw_path.name, {k: round(v, 3) for k, v in self.stats.items()})

