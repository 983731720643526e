"""Keeping an EVT3 byte stream decodable when USB chunks had to be dropped.

EVT3 is stateful (row, time and polarity persist between words) and 16-bit aligned, while USB
reads can end on any byte. ``ChunkAligner`` hands the decoder whole words only, and after a gap
in the stream it skips ahead to a point where the state is fully known again: the first
``EVT_ADDR_Y`` that follows a ``TIME_HIGH`` and a ``TIME_LOW``. Those two words are replayed in
front of it, so every event after the restart point decodes exactly as without the gap, and the
decoder keeps its 2^24 µs loop count (a fresh decoder would restart time at zero).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from darkread.edge.io.evt3_words import ADDR_Y, TIME_HIGH, TIME_LOW

Words = npt.NDArray[np.uint16]
_NO_WORDS: Words = np.zeros(0, dtype="<u2")


class _Resync:
    """Search state after a gap: the newest TIME_HIGH and the newest TIME_LOW after it."""

    def __init__(self) -> None:
        self.high: int | None = None
        self.low: int | None = None

    def feed(self, words: Words) -> Words | None:
        """Decodable words from the restart point on, or None while still searching."""
        types = words >> 12
        highs = np.flatnonzero(types == TIME_HIGH)
        lows = np.flatnonzero(types == TIME_LOW)
        rows = np.flatnonzero(types == ADDR_Y)
        for j in rows:
            context = self._context_before(words, highs, lows, int(j))
            if context is not None:
                return np.concatenate((np.array(context, dtype="<u2"), words[j:]))
        self._remember(words, highs, lows)
        return None

    def _context_before(self, words: Words, highs: np.ndarray, lows: np.ndarray, j: int) -> tuple[int, int] | None:
        highs_before = highs[highs < j]
        if highs_before.size:
            h = int(highs_before[-1])
            lows_between = lows[(lows > h) & (lows < j)]
            return (int(words[h]), int(words[lows_between[-1]])) if lows_between.size else None
        if self.high is None:
            return None
        lows_before = lows[lows < j]
        low = int(words[lows_before[-1]]) if lows_before.size else self.low
        return (self.high, low) if low is not None else None

    def _remember(self, words: Words, highs: np.ndarray, lows: np.ndarray) -> None:
        if highs.size:
            h = int(highs[-1])
            self.high = int(words[h])
            after = lows[lows > h]
            self.low = int(words[after[-1]]) if after.size else None
        elif lows.size and self.high is not None:
            self.low = int(words[lows[-1]])


class ChunkAligner:
    """Turns USB chunks, tagged with their byte offset in the stream, into whole decodable words."""

    def __init__(self) -> None:
        self._next_offset = 0
        self._carry = b""
        self._resync: _Resync | None = None
        self.gaps = 0
        self.skipped_bytes = 0  # bytes after gaps that could not be decoded safely

    def push(self, offset: int, data: bytes) -> bytes:
        """Bytes safe to feed to a decoder (whole 16-bit words; may be empty)."""
        end = offset + len(data)
        if offset != self._next_offset:
            self.gaps += 1
            self._carry = b""
            self._resync = _Resync()
            if offset % 2:  # words start on even stream offsets
                data = data[1:]
                self.skipped_bytes += 1
        elif self._carry:
            data = self._carry + data
        self._next_offset = end
        whole = len(data) // 2 * 2
        self._carry = data[whole:]
        words = np.frombuffer(data, dtype="<u2", count=whole // 2)
        if self._resync is None:
            return words.tobytes()
        restarted = self._resync.feed(words)
        if restarted is None:
            self.skipped_bytes += whole
            return b""
        self._resync = None
        self.skipped_bytes += whole - 2 * (len(restarted) - 2)
        return restarted.tobytes()
