"""EVT 2.0 decoder (Gen3 sensors; the IMX636 cannot emit it), vectorised like the EVT 3.0 one.

Little-endian 32-bit words, type in bits 31..28: CD_OFF (0x0) / CD_ON (0x1) carry the 6 low time
bits (27..22), x (21..11) and y (10..0); TIME_HIGH (0x8) carries time bits 33..6 in 27..0;
EXT_TRIGGER (0xA) carries the 6 low time bits, the channel (12..8) and the edge (bit 0). The time
base (34 bits, about 4 h 46 min) never wraps within a recording, so the only state is the last
TIME_HIGH, resolved for a whole chunk by a forward fill. A TIME_HIGH below the highest one so far is
counted as non-monotonic and the events under it are dropped; words before the first TIME_HIGH,
OTHERS (0xE), CONTINUED (0xF) and reserved types are skipped and counted.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE, Events
from darkread.edge.io.evt3 import Triggers
from darkread.edge.io.word_stream import WordStreamDecoder

CD_OFF, CD_ON, TIME_HIGH, EXT_TRIGGER = 0x0, 0x1, 0x8, 0xA


class Evt2Decoder(WordStreamDecoder):
    """Streaming EVT 2.0 decoder with the same interface as :class:`Evt3Decoder`."""

    FORMAT = "EVT2"
    WORD_DTYPE = "<u4"

    def __init__(
        self,
        width: int = 640,
        height: int = 480,
        *,
        time_shift: bool = False,
        path: str | None = None,
        y_range: tuple[int, int] | None = None,
        strict: bool = False,
        byte_offset: int = 0,
    ) -> None:
        super().__init__(
            width, height, time_shift=time_shift, path=path, y_range=y_range, strict=strict, byte_offset=byte_offset
        )
        self._high = -1  # last TIME_HIGH in force (-1: none yet, or dropping after a step back)
        self._max_high = -1
        self._first_high: int | None = None

    @property
    def time_shift_us(self) -> int:
        """OpenEB's EVT 2.0 time shift: the first TIME_HIGH's time."""
        return self._first_high << 6 if self._first_high is not None else 0

    def decode(self, chunk: bytes | memoryview) -> tuple[Events, Triggers]:
        words = self._whole_words(chunk)
        self.stats.words += len(words)
        words = self._skip_until_time_high(words)
        types = (words >> 28).astype(np.uint8)
        is_cd, is_high, is_trigger = types <= CD_ON, types == TIME_HIGH, types == EXT_TRIGGER
        high_at = self._highs(words, is_high)
        self.stats.skipped_other += len(words) - int(np.count_nonzero(is_cd | is_high | is_trigger))
        events = self._cropped(self._events(words, np.flatnonzero(is_cd), high_at))
        triggers = self._triggers(words, np.flatnonzero(is_trigger), high_at)
        return self._shifted(events, triggers)

    def _skip_until_time_high(self, words: np.ndarray) -> np.ndarray:
        if self._first_high is not None:
            return words
        hits = np.flatnonzero((words >> 28) == TIME_HIGH)
        first = int(hits[0]) if len(hits) else len(words)
        self.stats.skipped_before_time_high += first
        if len(hits):
            self._first_high = int(words[first] & 0x0FFFFFFF)
        return words[first:]

    def _highs(self, words: np.ndarray, is_high: np.ndarray) -> np.ndarray:
        """TIME_HIGH in force at each word, in µs (-1 where events are dropped)."""
        value = (np.compress(is_high, words) & 0x0FFFFFFF).astype(np.int64)
        best_before = np.maximum.accumulate(np.concatenate(([self._max_high], value)))
        backwards = value < best_before[:-1]
        self.stats.non_monotonic_time_high += int(np.count_nonzero(backwards))
        table = np.concatenate(([self._high], np.where(backwards, -1, value)))
        if len(value):
            self._high, self._max_high = int(table[-1]), int(best_before[-1])
        high = table[np.cumsum(is_high, dtype=np.intp)]
        return np.where(high >= 0, high << 6, -1)

    def _events(self, words: np.ndarray, idx: np.ndarray, high_at: np.ndarray) -> Events:
        val = words[idx]
        out = np.zeros(len(idx), dtype=EVENT_CD_DTYPE)
        out["x"], out["y"], out["p"] = (val >> 11) & 0x7FF, val & 0x7FF, val >> 28
        out["t"] = high_at[idx] | ((val >> 22) & 0x3F)
        timeless = high_at[idx] < 0
        outside = (out["x"] >= self.width) | (out["y"] >= self.height)
        lo, hi = self.y_range
        self.stats.dropped_non_monotonic += int(np.count_nonzero(timeless))
        self.stats.events_out_of_range += int(np.count_nonzero(outside & ~timeless))
        keep = ~(timeless | outside) & (out["y"] >= lo) & (out["y"] < hi)
        out = out if keep.all() else out[keep]
        self.stats.events += len(out)
        return out

    def _triggers(self, words: np.ndarray, idx: np.ndarray, high_at: np.ndarray) -> Triggers:
        val = words[idx]
        out = np.zeros(len(idx), dtype=TRIGGER_DTYPE)
        out["p"], out["id"] = val & 1, (val >> 8) & 0x1F
        out["t"] = high_at[idx] | ((val >> 22) & 0x3F)
        out = out[high_at[idx] >= 0]
        self.stats.triggers += len(out)
        return out


def decode_evt2(data: bytes, width: int = 640, height: int = 480, **kw: Any) -> tuple[Events, Triggers]:
    """Decode a whole EVT 2.0 byte string (data only, no header)."""
    decoder = Evt2Decoder(width, height, **kw)
    events, triggers = decoder.decode(data)
    decoder.finish()
    return events, triggers
