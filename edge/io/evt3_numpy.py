"""EVT 3.0 decoding with numpy array passes: the fallback when numba is not installed.

EVT 3.0 is a stream of little-endian 16-bit words whose meaning depends on a state (row ``y``,
time high/low, vector base and polarity) that earlier words set. Instead of a per-word loop, this
module resolves the state for a whole chunk with array operations:

1. The word type is ``w >> 12``. Each state variable is a *forward fill*: the value of the last
   word of its kind at or before a position, ``[init, *values][cumsum(is_setter)]`` (``init`` =
   the state carried from the previous chunk).
2. Time: a forward fill over the TIME_LOW / TIME_HIGH subsequence. TIME_HIGH values are unrolled
   first (a loop when a value is >= 2048 below the previous one; a smaller drop is non-monotonic
   and marks the time invalid, -1, until it is back at its maximum); a TIME_HIGH that repeats its
   value sets nothing, one that changes it resets the low bits to 0.
3. Vectors: within the subsequence of VECT_BASE_X / VECT_12 / VECT_8 words, the base of a VECT word
   is ``base_at_last_VECT_BASE_X + (increments since then)``: a forward fill of
   ``base - cumsum(increments)`` plus the running ``cumsum``. Masks expand through ``unpackbits``;
   a VECT word whose pixels would pass the sensor width is dropped, like OpenEB's validator.
4. Single events (EVT_ADDR_X) and vector events keep stream order: the single events take the
   output slots at their word's offset, vector events fill the remaining slots in order.

It needs about twenty array passes per chunk; the compiled loop in ``evt3_jit.py`` needs one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE, Events
from darkread.edge.io.evt3_words import (
    ADDR_X,
    ADDR_Y,
    EXT_TRIGGER,
    LOOP_DROP,
    TIME_HIGH,
    TIME_LOW,
    VECT_8,
    VECT_12,
    VECT_BASE_X,
)

if TYPE_CHECKING:
    from darkread.edge.io.evt3_encode import Triggers
    from darkread.edge.io.word_stream import DecodeStats


@dataclass
class DecoderState:
    """What a decoder carries from one chunk to the next."""

    started: bool = False
    last_high: int = 0  # raw 12-bit value of the last TIME_HIGH
    loops: int = 0
    max_high: int = -1  # highest unrolled time high so far
    high: int = -1  # unrolled time high in force, -1 while dropping after a non-monotonic one
    low: int = 0
    y: int = 0
    base: int = 0
    polarity: int = 0
    first_high: int | None = None


_POPCOUNT_12 = np.array([bin(m).count("1") for m in range(4096)], dtype=np.int64)  # set bits of a 12-bit mask


def _ffill(sets: np.ndarray, values: np.ndarray, init: int) -> np.ndarray:
    """Forward fill: at each position, the value of the last position where ``sets`` is True
    (``values`` lists those in order), or ``init`` before the first one."""
    table = np.empty(len(values) + 1, dtype=np.int64)
    table[0] = init
    table[1:] = values
    return table[np.cumsum(sets, dtype=np.int32)]


def _first_time_high(words: np.ndarray) -> int | None:
    """Index of the first TIME_HIGH word (looked for in growing windows: it is usually first)."""
    start, size = 0, 64
    while start < len(words):
        hits = np.flatnonzero((words[start : start + size] >> 12) == TIME_HIGH)
        if len(hits):
            return start + int(hits[0])
        start, size = start + size, size * 8
    return None


def _skip_until_time_high(words: np.ndarray, state: DecoderState, stats: DecodeStats) -> np.ndarray:
    if state.started:
        return words
    first = _first_time_high(words)
    if first is None:
        stats.skipped_before_time_high += len(words)
        return words[:0]
    stats.skipped_before_time_high += first
    state.started, state.last_high = True, int(words[first] & 0xFFF)
    state.first_high = state.high = state.max_high = state.last_high
    return words[first:]


def _time_high(th_val: np.ndarray, state: DecoderState, stats: DecodeStats) -> tuple[np.ndarray, np.ndarray]:
    """Unrolled time high per TIME_HIGH word (-1 = non-monotonic) and whether it changed value."""
    prev = np.empty_like(th_val)
    prev[:1] = state.last_high
    prev[1:] = th_val[:-1]
    drop = prev - th_val
    loops = state.loops + np.cumsum(drop >= LOOP_DROP)
    unrolled = (loops << 12) | th_val
    n_back = int(np.count_nonzero((drop > 0) & (drop < LOOP_DROP)))
    if n_back == 0 and unrolled[0] >= state.max_high:  # the usual case: never back in time
        high, state.max_high = unrolled, int(unrolled[-1])
    else:
        stats.non_monotonic_time_high += n_back
        best_before = np.maximum.accumulate(np.concatenate(([state.max_high], unrolled)))
        high = np.where(unrolled >= best_before[:-1], unrolled, -1)
        state.max_high = int(best_before[-1])
    state.last_high, state.loops = int(th_val[-1]), int(loops[-1])
    return high, drop != 0


def _times(t_val: np.ndarray, state: DecoderState, stats: DecodeStats) -> np.ndarray:
    """Absolute time (-1 while dropping) after each TIME_LOW / TIME_HIGH word, in stream order."""
    is_high = t_val >= TIME_HIGH << 12
    value = (t_val & 0xFFF).astype(np.int64)
    high_idx = np.flatnonzero(is_high)
    if len(high_idx):
        unrolled, changed = _time_high(value[high_idx], state, stats)
        high = _ffill(is_high, unrolled, state.high)
    else:
        changed, high = high_idx.astype(bool), np.full(len(value), state.high, dtype=np.int64)
    value[high_idx] = 0  # a TIME_HIGH that changes the value resets the low bits
    sets = ~is_high
    sets[high_idx] = changed  # a TIME_HIGH that repeats the value changes nothing
    time = np.where(high >= 0, (high << 12) | value, -1)
    init = (state.high << 12) | state.low if state.high >= 0 else -1
    time = _ffill(sets, np.compress(sets, time), init)
    if len(value):
        state.high = int(high[-1])
        low = np.compress(sets, value)
        state.low = int(low[-1]) if len(low) else state.low
    return time


def _vectors(words: np.ndarray, types: np.ndarray, state: DecoderState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, x base and polarity of every VECT_12/VECT_8 word (in stream order)."""
    v_idx = np.flatnonzero((types >= VECT_BASE_X) & (types <= VECT_8))
    v_types, v_val = types[v_idx], (words[v_idx] & 0xFFF).astype(np.int64)
    step = np.where(v_types == VECT_12, 12, np.where(v_types == VECT_8, 8, 0))
    done = np.cumsum(step)  # pixels advanced up to and including each word
    is_base = v_types == VECT_BASE_X
    key = _ffill(is_base, (v_val & 0x7FF)[is_base] - done[is_base], state.base)
    polarity = _ffill(is_base, v_val[is_base] >> 11, state.polarity)
    base = key + done - step
    if len(v_idx):
        state.base, state.polarity = int(key[-1] + done[-1]), int(polarity[-1])
    is_vect = ~is_base
    return v_idx[is_vect], base[is_vect], polarity[is_vect]


def decode_words(
    words: np.ndarray, state: DecoderState, stats: DecodeStats, width: int, height: int,
    bounds: tuple[int, int, int, int] | None = None,
) -> tuple[Events, Triggers]:
    """Decode one chunk of words, updating ``state`` and ``stats``; with ``bounds`` (x0, x1, y0, y1,
    the sensor's ROI) only the events inside them, the event words wholly outside counted
    (``stats.words_outside_roi``, as the compiled loop skips them)."""
    stats.words += len(words)
    words = _skip_until_time_high(words, state, stats)
    types = (words >> 12).astype(np.uint8)
    is_y, is_x, is_trigger = types == ADDR_Y, types == ADDR_X, types == EXT_TRIGGER
    is_time = (types == TIME_LOW) | (types == TIME_HIGH)
    n_vect = sum(int(np.count_nonzero(types == k)) for k in (VECT_BASE_X, VECT_12, VECT_8))
    n_handled = n_vect + sum(int(np.count_nonzero(m)) for m in (is_y, is_x, is_trigger, is_time))
    stats.skipped_other += len(words) - n_handled

    t_idx = np.flatnonzero(is_time)
    t_val = words[t_idx]
    time_table = np.empty(len(t_idx) + 1, dtype=np.int64)
    time_table[0] = (state.high << 12) | state.low if state.high >= 0 else -1
    time_table[1:] = _times(t_val, state, stats)
    time_rank = np.cumsum(is_time, dtype=np.int32)
    y_table = np.empty(int(np.count_nonzero(is_y)) + 1, dtype=np.uint16)
    y_table[0] = state.y
    y_table[1:] = np.compress(is_y, words) & 0x7FF
    y_rank = np.cumsum(is_y, dtype=np.int32)
    state.y = int(y_table[-1])

    def state_at(query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return time_table[time_rank[query]], y_table[y_rank[query]]

    x_idx = np.flatnonzero(is_x)
    vectors = _vectors(words, types, state) if n_vect else None
    if vectors is not None:
        events = _mixed_events(words, types, x_idx, *vectors, state_at, stats, width)
    else:
        events = _single_events(words, x_idx, state_at)
    triggers = _triggers(words, np.flatnonzero(is_trigger), state_at, stats)
    if bounds is not None:
        stats.words_outside_roi += _words_outside(words, x_idx, vectors, state_at, bounds, width, height)
    return _drop_invalid(events, stats, width, height, bounds), triggers


def _words_outside(words, x_idx, vectors, state_at, bounds, width, height) -> int:
    """Valid event words (a time, on the sensor) whose row or columns all lie outside ``bounds``."""
    x0, x1, y0, y1 = bounds
    t, y = state_at(x_idx)
    x = (words[x_idx] & 0x7FF).astype(np.int64)
    valid = (t >= 0) & (x < width) & (y < height)
    away = (y < y0) | (y >= y1) | (x < x0) | (x >= x1)
    n = int(np.count_nonzero(valid & away))
    if vectors is not None:
        v_idx, base, _ = vectors
        n_bits = np.where((words[v_idx] >> 12) == VECT_12, 12, 8)
        t, y = state_at(v_idx)
        valid = (base + n_bits <= width) & (t >= 0) & (y < height)
        away = (y < y0) | (y >= y1) | (base + n_bits <= x0) | (base >= x1)
        n += int(np.count_nonzero(valid & away))
    return n


def _single_events(words: np.ndarray, x_idx: np.ndarray, state_at) -> Events:
    out = np.zeros(len(x_idx), dtype=EVENT_CD_DTYPE)
    _fill_singles(out, slice(None), words[x_idx], *state_at(x_idx))
    return out


def _fill_singles(out: Events, slots: np.ndarray | slice, x_val: np.ndarray, t: np.ndarray, y: np.ndarray) -> None:
    out["x"][slots] = x_val & 0x7FF
    out["p"][slots] = (x_val >> 11) & 1
    out["t"][slots], out["y"][slots] = t, y


def _mixed_events(words, types, x_idx, v_idx, v_base, v_pol, state_at, stats, width) -> Events:
    """Single and vector events in stream order."""
    v_word = words[v_idx]
    is_12 = (v_word >> 12) == VECT_12
    masks = np.where(is_12, v_word & 0xFFF, v_word & 0xFF).astype("<u2")
    outside = v_base + np.where(is_12, 12, 8) > width
    stats.vectors_out_of_range += int(np.count_nonzero(outside))
    masks[outside] = 0
    row, bit = np.nonzero(np.unpackbits(masks.view(np.uint8).reshape(-1, 2), axis=1, bitorder="little"))
    per_word = _POPCOUNT_12[masks]

    # output slots: every event word in stream order takes 1 (single) or popcount (vector) slots
    e_idx = np.flatnonzero((types == ADDR_X) | (types == VECT_12) | (types == VECT_8))
    single = types[e_idx] == ADDR_X
    count = np.ones(len(e_idx), dtype=np.int64)
    count[~single] = per_word
    slot = np.cumsum(count) - count
    first_of_word = np.cumsum(per_word) - per_word
    vector_slot = slot[~single][row] + np.arange(len(row)) - first_of_word[row]

    out = np.zeros(int(count.sum()), dtype=EVENT_CD_DTYPE)
    _fill_singles(out, slot[single], words[x_idx], *state_at(x_idx))
    t_v, y_v = state_at(v_idx)
    out["x"][vector_slot], out["p"][vector_slot] = v_base[row] + bit, v_pol[row]
    out["t"][vector_slot], out["y"][vector_slot] = t_v[row], y_v[row]
    return out


def _drop_invalid(out: Events, stats: DecodeStats, width: int, height: int,
                  bounds: tuple[int, int, int, int] | None = None) -> Events:
    timeless = out["t"] < 0
    outside = (out["x"] >= width) | (out["y"] >= height)
    bad = timeless | outside
    if bad.any():  # only after a step back in time or in corrupt data
        stats.dropped_non_monotonic += int(np.count_nonzero(timeless))
        stats.events_out_of_range += int(np.count_nonzero(outside & ~timeless))
        out = out[~bad]
    if bounds is not None:
        x0, x1, y0, y1 = bounds
        out = out[(out["x"] >= x0) & (out["x"] < x1) & (out["y"] >= y0) & (out["y"] < y1)]
    stats.events += len(out)
    return out


def _triggers(words, trig_idx, state_at, stats) -> Triggers:
    val = words[trig_idx]
    out = np.zeros(len(trig_idx), dtype=TRIGGER_DTYPE)
    out["p"], out["id"] = val & 1, (val >> 8) & 0xF
    out["t"] = state_at(trig_idx)[0]
    timeless = out["t"] < 0
    if timeless.any():
        stats.dropped_non_monotonic += int(np.count_nonzero(timeless))
        out = out[~timeless]
    stats.triggers += len(out)
    return out
