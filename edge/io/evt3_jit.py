"""Compiled EVT 3.0 word loop (numba), the fast path of :class:`Evt3Decoder`.

The numpy decoder (``evt3_numpy.py``) needs some twenty array passes and temporaries per chunk and
reaches a fraction of a compiled decoder's speed; this loop makes one pass (after a cheap pass that
sizes the output) and writes straight into the output records.
It follows exactly the rules of the numpy path (the tests decode every input with both and compare):
same time rules, same drops, same counters. Requires numba; ``evt3.py`` falls back to numpy without it.
"""

from __future__ import annotations

import numpy as np

from darkread.edge.compiled import compiled
from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE

# Slots of the state vector and of the counters vector (evt3.py maps them to its dataclasses).
STARTED, LAST_HIGH, LOOPS, MAX_HIGH, HIGH, LOW, Y, BASE, POLARITY, FIRST_HIGH = range(10)
SKIPPED_BEFORE, SKIPPED_OTHER, NON_MONOTONIC, VECTORS_OUT, EVENTS_OUT, DROPPED, OUTSIDE_ROI = range(7)


# Most events a word can carry, by type (ADDR_X 1, VECT_12 12, VECT_8 8), and triggers (EXT_TRIGGER).
_PIXELS_PER_TYPE = np.array([0, 0, 1, 0, 12, 8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0], dtype=np.int64)
_POPCOUNT_12 = np.array([bin(m).count("1") for m in range(4096)], dtype=np.int64)  # set bits of a 12-bit mask
_TRIGGERS_PER_TYPE = np.array([0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0], dtype=np.int64)


@compiled
def _bounds(words: np.ndarray) -> tuple[int, int]:  # pragma: no cover - compiled
    """Upper bounds of the pixel events and triggers in ``words`` (branch-free, one pass)."""
    n_pixels = 0
    n_triggers = 0
    for w in words:
        n_pixels += _PIXELS_PER_TYPE[w >> 12]
        n_triggers += _TRIGGERS_PER_TYPE[w >> 12]
    return n_pixels, n_triggers


@compiled
def _decode(words, state, counters, width, height, x0, x1, y0, y1, ev64, tr16, tr64):  # pragma: no cover
    """Decode ``words`` into flat views of the records (EVENT_CD: x | y << 16 | p << 32 and t in the
    two i64 slots of each 16 bytes; TRIGGER: p, id at u16 slots 0 and 8, t at i64 slot 1 of 24 bytes);
    returns the numbers of events and triggers written. Only pixels in columns ``x0..x1`` and rows
    ``y0..y1`` (half-open: the sensor's ROI) are written; an event word wholly outside is counted and
    its pixels never looked at."""
    last_high, loops, max_high = state[LAST_HIGH], state[LOOPS], state[MAX_HIGH]
    high, low, y, base, polarity = state[HIGH], state[LOW], state[Y], state[BASE], state[POLARITY]
    n = len(words)
    i = 0
    if state[STARTED] == 0:
        while i < n and (words[i] >> 12) != 8:
            i += 1
        counters[SKIPPED_BEFORE] += i
        if i == n:
            return 0, 0
        last_high = np.int64(words[i] & 0xFFF)
        high = max_high = last_high
        state[STARTED], state[FIRST_HIGH] = 1, last_high
    rows_in = y0 <= y < y1
    ne = 0
    nt = 0
    for j in range(i, n):
        w = np.int64(words[j])
        kind = w >> 12
        v = w & 0xFFF
        if kind == 0:
            y = v & 0x7FF
            rows_in = y0 <= y < y1
        elif kind == 2:
            x = v & 0x7FF
            if high < 0:
                counters[DROPPED] += 1
            elif x >= width or y >= height:
                counters[EVENTS_OUT] += 1
            elif not rows_in or x < x0 or x >= x1:
                counters[OUTSIDE_ROI] += 1
            else:
                ev64[2 * ne] = x | (y << 16) | ((v >> 11) << 32)  # x, y, p and the padding
                ev64[2 * ne + 1] = (high << 12) | low
                ne += 1
        elif kind == 6:
            low = v
        elif kind == 8:
            drop = last_high - v
            if drop >= 2048:
                loops += 1
            elif drop > 0:
                counters[NON_MONOTONIC] += 1
            unrolled = (loops << 12) | v
            if unrolled >= max_high:
                high = max_high = unrolled
            else:
                high = -1
            if drop != 0:
                low = 0
            last_high = v
        elif kind == 3:
            base, polarity = v & 0x7FF, v >> 11
        elif kind == 4 or kind == 5:
            n_bits = 12 if kind == 4 else 8
            mask = v if kind == 4 else v & 0xFF
            if base + n_bits > width:
                counters[VECTORS_OUT] += 1
            elif high < 0:
                counters[DROPPED] += _POPCOUNT_12[mask]
            elif y >= height:
                counters[EVENTS_OUT] += _POPCOUNT_12[mask]
            elif not rows_in or base + n_bits <= x0 or base >= x1:
                counters[OUTSIDE_ROI] += 1
            else:
                if base < x0:  # the columns left of the ROI
                    mask &= ~((1 << (x0 - base)) - 1)
                if base + n_bits > x1:  # and right of it
                    mask &= (1 << (x1 - base)) - 1
                t = (high << 12) | low
                x = base
                while mask:  # set bits, lowest first
                    if mask & 1:
                        ev64[2 * ne] = x | (y << 16) | (polarity << 32)  # x, y, p and the padding
                        ev64[2 * ne + 1] = t
                        ne += 1
                    mask >>= 1
                    x += 1
            base += n_bits
        elif kind == 10:
            if high < 0:
                counters[DROPPED] += 1
            else:
                for k in range(12):  # zero the padding too
                    tr16[12 * nt + k] = 0
                tr16[12 * nt], tr16[12 * nt + 8] = v & 1, (v >> 8) & 0xF
                tr64[3 * nt + 1] = (high << 12) | low
                nt += 1
        else:
            counters[SKIPPED_OTHER] += 1
    state[LAST_HIGH], state[LOOPS], state[MAX_HIGH] = last_high, loops, max_high
    state[HIGH], state[LOW], state[Y], state[BASE], state[POLARITY] = high, low, y, base, polarity
    return ne, nt


def decode_words(
    words: np.ndarray, state: np.ndarray, counters: np.ndarray, width: int, height: int,
    bounds: tuple[int, int, int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Events and triggers of ``words``; ``state`` and ``counters`` (int64 vectors) are updated.
    ``bounds``: (x0, x1, y0, y1), only the events inside (the sensor's ROI)."""
    x0, x1, y0, y1 = bounds if bounds is not None else (0, width, 0, height)
    n_pixels, n_triggers = _bounds(words)
    events = np.empty(n_pixels, dtype=EVENT_CD_DTYPE)  # every byte is written, padding included
    triggers = np.empty(n_triggers, dtype=TRIGGER_DTYPE)
    ev64 = events.view(np.int64)  # flat views of the records
    tr16, tr64 = triggers.view(np.uint16), triggers.view(np.int64)
    ne, nt = _decode(words, state, counters, width, height, x0, x1, y0, y1, ev64, tr16, tr64)
    # A view, not a copy: copying costs as much as decoding, and the unused tail of the buffer
    # (vectors with few bits set) is never written, so it takes address space but no memory.
    return events[:ne], triggers[:nt]
