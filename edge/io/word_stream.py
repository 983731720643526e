"""What every RAW data decoder shares, whatever its word format.

A decoder is fed chunks of any size: the partial word at a chunk's end waits for the next chunk,
the file offset is kept so errors name the byte, and the output gets OpenEB's time shift when
asked. The formats (``evt3.py``, ``evt2.py``) only turn whole words into events.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from darkread.edge.errors import CorruptRawError
from darkread.edge.events import Events

log = logging.getLogger(__name__)

MAX_SENSOR_SIDE = 2048


@dataclass
class DecodeStats:
    """Counters a user can read after decoding (they add up over all chunks)."""

    words: int = 0
    events: int = 0
    triggers: int = 0
    skipped_before_time_high: int = 0
    skipped_other: int = 0  # OTHERS, CONTINUED and reserved words
    non_monotonic_time_high: int = 0
    vectors_out_of_range: int = 0
    trailing_bytes: int = 0
    events_out_of_range: int = 0  # pixels outside the sensor (corrupt data), dropped
    dropped_non_monotonic: int = 0  # events and triggers dropped after a non-monotonic TIME_HIGH
    # event words wholly outside the sensor's ROI (``set_roi``): a replay's stand-in for what the
    # sensor never reads out, skipped without decoding their pixels (``events`` counts those inside)
    words_outside_roi: int = 0

    def add(self, other: DecodeStats) -> None:
        for f in fields(self):
            setattr(self, f.name, getattr(self, f.name) + getattr(other, f.name))


class WordStreamDecoder:
    """Chunk handling, counters and time shift; subclasses set the word format and decode words."""

    FORMAT: ClassVar[str]  # "EVT3", "EVT2"
    WORD_DTYPE: ClassVar[str]  # numpy dtype of one little-endian word, e.g. "<u2"

    def __init__(
        self,
        width: int,
        height: int,
        *,
        time_shift: bool = False,
        path: str | None = None,
        y_range: tuple[int, int] | None = None,
        strict: bool = False,
        byte_offset: int = 0,
    ) -> None:
        if not (0 < width <= MAX_SENSOR_SIDE and 0 < height <= MAX_SENSOR_SIDE):
            raise ValueError(f"sensor size {width}x{height} is outside 1..{MAX_SENSOR_SIDE}")
        self.width, self.height = width, height
        self.time_shift, self.path, self.strict = time_shift, path, strict
        self.y_range = (0, height) if y_range is None else (max(0, y_range[0]), min(height, y_range[1]))
        self.stats = DecodeStats()
        self.roi: tuple[int, int, int, int] | None = None  # (x0, y0, width, height); None: the whole sensor
        self._pending = b""
        self._offset = byte_offset  # file offset of the next byte fed

    @property
    def time_shift_us(self) -> int:
        raise NotImplementedError

    def set_roi(self, roi: tuple[int, int, int, int] | None) -> None:
        """Decode only the events inside ``roi`` (x0, y0, width, height) from the next chunk on, as
        a sensor with that ROI would deliver them; None (or the whole sensor): every event."""
        if roi is not None:
            x0, y0, w, h = roi
            if w <= 0 or h <= 0 or x0 < 0 or y0 < 0:
                raise ValueError(f"ROI must be non-negative with a positive size, got {roi}")
            if (x0, y0) == (0, 0) and x0 + w >= self.width and y0 + h >= self.height:
                roi = None
        self.roi = roi

    def roi_bounds(self) -> tuple[int, int, int, int] | None:
        """The ROI as half-open bounds (x0, x1, y0, y1), or None for the whole sensor."""
        if self.roi is None:
            return None
        x0, y0, w, h = self.roi
        return x0, x0 + w, y0, y0 + h

    def _cropped(self, events: Events) -> Events:
        """``events`` inside the ROI (for formats whose word loop does not skip), the rest counted:
        one word per event (EVT 2.0)."""
        bounds = self.roi_bounds()
        if bounds is None:
            return events
        x0, x1, y0, y1 = bounds
        inside = (events["x"] >= x0) & (events["x"] < x1) & (events["y"] >= y0) & (events["y"] < y1)
        n_outside = int(inside.size - np.count_nonzero(inside))
        self.stats.words_outside_roi += n_outside
        self.stats.events -= n_outside
        return events[inside]

    def _whole_words(self, chunk: bytes | memoryview) -> np.ndarray:
        """The chunk's whole words, after the partial word left by the previous chunk."""
        data = self._pending + bytes(chunk) if self._pending else chunk
        size = np.dtype(self.WORD_DTYPE).itemsize
        n_words = len(data) // size
        self._pending = bytes(data[size * n_words :])
        self._offset += len(chunk)
        return np.frombuffer(data, dtype=self.WORD_DTYPE, count=n_words)

    def _shifted(self, events: Events, triggers: np.ndarray) -> tuple[Events, np.ndarray]:
        if self.time_shift:
            events["t"] -= self.time_shift_us
            triggers["t"] -= self.time_shift_us
        return events, triggers

    def finish(self) -> None:
        """End of stream: a partial word is counted (``strict=True``: CorruptRawError)."""
        if not self._pending:
            return
        offset, n = self._offset - len(self._pending), len(self._pending)
        self._pending = b""
        self.stats.trailing_bytes += n
        bits = 8 * np.dtype(self.WORD_DTYPE).itemsize
        message = f"{self.FORMAT} data ends inside a {bits}-bit word"
        if self.strict:
            raise CorruptRawError(f"{message} (file cut short?)", self.path, offset)
        log.warning("%s: %s at byte %d; ignored", self.path or "<bytes>", message, offset)
