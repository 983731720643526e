"""EVT 3.0 decoder (vectorised) and encoder.

EVT 3.0 is a stream of little-endian 16-bit words whose meaning depends on a state (row ``y``,
time high/low, vector base and polarity) that earlier words set. Instead of a per-word loop, the
decoder resolves the state for a whole chunk with array operations:

1. The word type is ``w >> 12``. Each state variable is a *forward fill*: the value of the last
   word of its kind at or before a position. With the setting words' positions ``idx`` and values
   ``val``, the state at query positions ``q`` is ``[init, *val][searchsorted(idx, q, "right")]``
   (``init`` = the state carried from the previous chunk).
2. TIME_HIGH: the 24-bit base loops (+2^24 µs) when a value is >= 2048 below the previous one, as in
   OpenEB. A smaller drop is *non-monotonic*: counted in ``stats.non_monotonic_time_high``; events
   and triggers are dropped until the unrolled time high is back at or above its maximum so far
   (OpenEB's robust decoder drops them too), so output time never jumps back by a TIME_HIGH.
   A TIME_HIGH that changes the value resets the low 12 bits to 0; TIME_LOW only overwrites them.
3. Vectors: within the subsequence of VECT_BASE_X / VECT_12 / VECT_8 words, the base of a VECT word
   is ``base_at_last_VECT_BASE_X + (increments since then)``: a forward fill of
   ``base - cumsum(increments)`` plus the running ``cumsum``. Masks expand through ``unpackbits``;
   a VECT word whose pixels would pass the sensor width is dropped, like OpenEB's validator.
4. Single events (EVT_ADDR_X) and vector events keep stream order: the single events take the
   output slots at their word's offset, vector events fill the remaining slots in order.

Two backends decode identically (the tests run both on every input): this numpy path, and a
compiled one-pass loop (``evt3_jit.py``, numba) that the decoder uses when numba is installed
(``backend="auto"``). Profiling showed why both exist: the numpy path needs about twenty array
passes per chunk and reaches 0.2-0.3x the speed of the ``evt3`` package (Rust); the loop is on par.

Words before the first TIME_HIGH carry no time and are skipped; OTHERS, CONTINUED and reserved
types are skipped and counted. Pixels outside the sensor (only in corrupt data) are dropped and
counted. A stream that ends inside a word is counted in ``stats.trailing_bytes`` (and raises
:class:`CorruptRawError` with ``strict=True``), so a recording cut short still reads.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, fields

from types import ModuleType

import numpy as np

from darkread.edge.errors import CorruptRawError
from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE, Events
from darkread.edge.io.evt3_encode import Triggers, encode_evt3
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

log = logging.getLogger(__name__)

__all__ = ["DecodeStats", "Evt3Decoder", "Triggers", "decode_evt3", "encode_evt3"]


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

    def add(self, other: DecodeStats) -> None:
        for f in fields(self):
            setattr(self, f.name, getattr(self, f.name) + getattr(other, f.name))


@dataclass
class _State:
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


def _ffill(sets: np.ndarray, values: np.ndarray, init: int) -> np.ndarray:
    """Forward fill: at each position, the value of the last position where ``sets`` is True
    (``values`` lists those in order), or ``init`` before the first one."""
    table = np.empty(len(values) + 1, dtype=np.int64)
    table[0] = init
    table[1:] = values
    return table[np.cumsum(sets, dtype=np.int32)]


class Evt3Decoder:
    """Streaming EVT 3.0 decoder: feed chunks of any size; the state carries across calls."""

    def __init__(
        self,
        width: int = 1280,
        height: int = 720,
        *,
        time_shift: bool = False,
        path: str | None = None,
        y_range: tuple[int, int] | None = None,
        strict: bool = False,
        byte_offset: int = 0,
        backend: str = "auto",
    ) -> None:
        if not (0 < width <= 2048 and 0 < height <= 2048):
            raise ValueError(f"sensor size {width}x{height} is outside 1..2048")
        self.backend = _resolve_backend(backend)
        self._decode_words = _decode_words_jit if self.backend == "numba" else _decode_words
        self.width, self.height = width, height
        self.time_shift, self.path, self.strict = time_shift, path, strict
        self.y_range = (0, height) if y_range is None else (max(0, y_range[0]), min(height, y_range[1]))
        self.stats = DecodeStats()
        self._state = _State()
        self._pending = b""
        self._offset = byte_offset  # file offset of the next byte fed

    @property
    def time_shift_us(self) -> int:
        """OpenEB's time shift, (first_time_high - 1) * 4096 µs (0 until the first TIME_HIGH)."""
        first = self._state.first_high
        return max(first - 1, 0) << 12 if first is not None else 0

    def decode(self, chunk: bytes | memoryview) -> tuple[Events, Triggers]:
        data = bytes(chunk) if self._pending else chunk
        if self._pending:
            data = self._pending + data
        n_words = len(data) // 2
        self._pending = bytes(data[2 * n_words :])
        self._offset += len(chunk)
        words = np.frombuffer(data, dtype="<u2", count=n_words)
        events, triggers = self._decode_words(words, self._state, self.stats, self.width, self.height)
        lo, hi = self.y_range
        if lo > 0 or hi < self.height:
            events = events[(events["y"] >= lo) & (events["y"] < hi)]
        if self.time_shift:
            events["t"] -= self.time_shift_us
            triggers["t"] -= self.time_shift_us
        return events, triggers

    def finish(self) -> None:
        """End of stream: a dangling odd byte is counted (``strict=True``: CorruptRawError)."""
        if not self._pending:
            return
        offset = self._offset - len(self._pending)
        self._pending = b""
        self.stats.trailing_bytes += 1
        if self.strict:
            raise CorruptRawError("EVT3 data ends inside a 16-bit word (file cut short?)", self.path, offset)
        log.warning("%s: EVT3 data ends inside a 16-bit word at byte %d; ignored", self.path or "<bytes>", offset)


BACKENDS = ("auto", "numba", "numpy")
_STATE_FIELDS = ("started", "last_high", "loops", "max_high", "high", "low", "y", "base", "polarity", "first_high")
_COUNTER_FIELDS = (
    "skipped_before_time_high",
    "skipped_other",
    "non_monotonic_time_high",
    "vectors_out_of_range",
    "events_out_of_range",
    "dropped_non_monotonic",
)


@functools.cache
def _jit() -> ModuleType | None:
    """The compiled word loop, or None when numba is not installed."""
    try:
        from darkread.edge.io import evt3_jit
    except ImportError:  # numba missing: the numpy path decodes the same, slower
        return None
    return evt3_jit


def _resolve_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "numba" and _jit() is None:
        raise ImportError("backend='numba' needs the numba package (pip install numba)")
    return "numba" if backend == "auto" and _jit() is not None else "numpy" if backend == "auto" else backend


def _decode_words_jit(words: np.ndarray, state: _State, stats: DecodeStats, width: int, height: int) -> tuple[Events, Triggers]:
    jit = _jit()
    assert jit is not None  # guaranteed by _resolve_backend
    vector = np.array([int(getattr(state, f) or 0) for f in _STATE_FIELDS], dtype=np.int64)
    counters = np.zeros(len(_COUNTER_FIELDS), dtype=np.int64)
    events, triggers = jit.decode_words(words, vector, counters, width, height)
    for name, value in zip(_STATE_FIELDS, vector.tolist()):
        setattr(state, name, value)
    state.started = bool(state.started)
    state.first_high = state.first_high if state.started else None
    stats.add(DecodeStats(len(words), len(events), len(triggers), **dict(zip(_COUNTER_FIELDS, counters.tolist()))))
    return events, triggers


def _first_time_high(words: np.ndarray) -> int | None:
    """Index of the first TIME_HIGH word (looked for in growing windows: it is usually first)."""
    start, size = 0, 64
    while start < len(words):
        hits = np.flatnonzero((words[start : start + size] >> 12) == TIME_HIGH)
        if len(hits):
            return start + int(hits[0])
        start, size = start + size, size * 8
    return None


def _skip_until_time_high(words: np.ndarray, state: _State, stats: DecodeStats) -> np.ndarray:
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


def _time_high(th_val: np.ndarray, state: _State, stats: DecodeStats) -> tuple[np.ndarray, np.ndarray]:
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


def _times(t_val: np.ndarray, state: _State, stats: DecodeStats) -> np.ndarray:
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


def _vectors(words: np.ndarray, types: np.ndarray, state: _State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _decode_words(words: np.ndarray, state: _State, stats: DecodeStats, width: int, height: int) -> tuple[Events, Triggers]:
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
    if n_vect:
        events = _mixed_events(words, x_idx, *_vectors(words, types, state), state_at, stats, width)
    else:
        events = _single_events(words, x_idx, state_at)
    triggers = _triggers(words, np.flatnonzero(is_trigger), state_at, stats)
    return _drop_invalid(events, stats, width, height), triggers


def _single_events(words: np.ndarray, x_idx: np.ndarray, state_at) -> Events:  # noqa: ANN001
    x_val = words[x_idx]
    out = np.zeros(len(x_idx), dtype=EVENT_CD_DTYPE)
    out["x"] = x_val & 0x7FF
    out["p"] = x_val >> 11
    out["p"] &= 1
    out["t"], out["y"] = state_at(x_idx)
    return out


def _mixed_events(words, x_idx, v_idx, v_base, v_pol, state_at, stats, width) -> Events:  # noqa: ANN001
    """Single and vector events in stream order."""
    v_word = words[v_idx]
    is_12 = (v_word >> 12) == VECT_12
    masks = v_word & np.where(is_12, 0xFFF, 0xFF).astype(np.uint16)
    outside = v_base + np.where(is_12, 12, 8) > width
    stats.vectors_out_of_range += int(np.count_nonzero(outside))
    masks[outside] = 0
    bits = np.unpackbits(masks.astype("<u2").view(np.uint8).reshape(-1, 2), axis=1, bitorder="little")
    row, bit = np.nonzero(bits)
    per_word = bits.sum(axis=1, dtype=np.intp)

    word_pos = np.concatenate((x_idx, v_idx))
    order = np.argsort(word_pos, kind="stable")
    count = np.concatenate((np.ones(len(x_idx), np.intp), per_word))[order]
    slot = np.cumsum(count) - count  # first output slot of each event word, in stream order
    single_slot = np.empty(len(x_idx), dtype=np.intp)
    single_slot[order[order < len(x_idx)]] = slot[order < len(x_idx)]
    is_single = np.zeros(int(count.sum()), dtype=bool)
    is_single[single_slot] = True
    vector_slot = np.flatnonzero(~is_single)

    out = np.zeros(len(is_single), dtype=EVENT_CD_DTYPE)
    out[single_slot] = _single_events(words, x_idx, state_at)
    t_v, y_v = state_at(v_idx)
    vec = np.zeros(len(row), dtype=EVENT_CD_DTYPE)
    vec["x"], vec["p"], vec["t"], vec["y"] = v_base[row] + bit, v_pol[row], t_v[row], y_v[row]
    out[vector_slot] = vec
    return out


def _drop_invalid(out: Events, stats: DecodeStats, width: int, height: int) -> Events:
    timeless = out["t"] < 0
    outside = (out["x"] >= width) | (out["y"] >= height)
    stats.dropped_non_monotonic += int(np.count_nonzero(timeless))
    stats.events_out_of_range += int(np.count_nonzero(outside & ~timeless))
    if timeless.any() or outside.any():
        out = out[~(timeless | outside)]
    stats.events += len(out)
    return out


def _triggers(words, trig_idx, state_at, stats) -> Triggers:  # noqa: ANN001
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


def decode_evt3(data: bytes, width: int = 1280, height: int = 720, **kw: object) -> tuple[Events, Triggers]:
    """Decode a whole EVT 3.0 byte string (data only, no header)."""
    decoder = Evt3Decoder(width, height, **kw)  # type: ignore[arg-type]
    events, triggers = decoder.decode(data)
    decoder.finish()
    return events, triggers
