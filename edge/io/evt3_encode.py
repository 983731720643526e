"""EVT 3.0 encoder: writes events the way an IMX636 streams them (vectorised, no per-event loop).

The stream is built from *units* in time order: a run of events with the same time, row and
polarity inside one 32-pixel block (increasing x) becomes a vector group ``VECT_BASE_X, VECT_12,
VECT_12, VECT_8`` (the base is omitted when the group continues the previous one), any other event
an ``EVT_ADDR_X`` word, a trigger an ``EXT_TRIGGER`` word. Each unit is preceded by ``TIME_LOW``
when the time differs from the previous unit's and by ``EVT_ADDR_Y`` when the row differs from the
previous pixel unit's. ``TIME_HIGH`` is re-sent every ``time_high_period_us`` of sensor time, also
while idle, as sensors do; the period divides 4096 µs, so every change of the high bits is sent and
the decoder sees each 2^24 µs wrap as a drop of 4095.

The stream carries time modulo 2^24 µs: a decoder returns ``t - (t0 >> 24 << 24)`` with ``t0`` the
first time in the stream, i.e. exactly ``t`` when the recording starts below 2^24 µs.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from darkread.edge.events import TRIGGER_DTYPE, Events
from darkread.edge.io.evt3_words import ADDR_X, ADDR_Y, EXT_TRIGGER, TIME_HIGH, TIME_LOW, VECT_8, VECT_12, VECT_BASE_X

Triggers = npt.NDArray[np.void]
"""A 1-D structured array of ``TRIGGER_DTYPE`` (p = edge value, id = channel)."""

_WORDS_PER_UNIT = 6  # TIME_LOW, ADDR_Y, VECT_BASE_X, and up to three payload words


def _check(events: Events, triggers: Triggers, width: int, period: int) -> None:
    if not 0 < width <= 2048:
        raise ValueError(f"width {width} is outside 1..2048")
    if not (0 < period <= 4096 and 4096 % period == 0):
        raise ValueError(f"time_high_period_us {period} must divide 4096")
    for name, arr in (("events", events), ("triggers", triggers)):
        if len(arr) and (arr["t"].min() < 0 or np.any(np.diff(arr["t"]) < 0)):
            raise ValueError(f"{name} must have non-negative, non-decreasing times")
    if len(events) and (events["x"].max() >= width or events["y"].max() >= 2048):
        raise ValueError(f"event x must be < width ({width}) and y < 2048")
    if len(events) and not np.isin(events["p"], (0, 1)).all():
        raise ValueError("event polarity must be 0 or 1")
    if len(triggers) and not (
        np.isin(triggers["p"], (0, 1)).all() and triggers["id"].min() >= 0 and triggers["id"].max() < 16
    ):
        raise ValueError("trigger p must be 0 or 1 and id in 0..15")


def _pixel_units(events: Events, min_vector_run: int) -> dict[str, np.ndarray]:
    """One unit per vector run or single event, in event order."""
    t, x, y, p = (events[k].astype(np.int64) for k in ("t", "x", "y", "p"))
    starts_run = np.ones(len(t), dtype=bool)
    starts_run[1:] = (t[1:] != t[:-1]) | (y[1:] != y[:-1]) | (p[1:] != p[:-1])
    starts_run[1:] |= (x[1:] >> 5 != x[:-1] >> 5) | (x[1:] <= x[:-1])
    run_start = np.flatnonzero(starts_run)
    run_len = np.diff(np.append(run_start, len(t)))
    is_vector_run = run_len >= min_vector_run
    single = np.flatnonzero(~np.repeat(is_vector_run, run_len))
    vec_start = run_start[is_vector_run]
    bits = np.left_shift(np.uint32(1), (x & 31).astype(np.uint32))
    masks = np.bitwise_or.reduceat(bits, run_start)[is_vector_run] if len(t) else bits
    first = np.concatenate((single, vec_start))
    order = np.argsort(first, kind="stable")
    kind = np.concatenate((np.zeros(len(single), np.int8), np.ones(len(vec_start), np.int8)))[order]
    x_or_base = np.concatenate((x[single], x[vec_start] & ~31))[order]
    mask = np.concatenate((np.zeros(len(single), np.int64), masks.astype(np.int64)))[order]
    return {
        "t": t[first[order]],
        "y": y[first[order]],
        "p": p[first[order]],
        "kind": kind,
        "x": x_or_base,
        "mask": mask,
    }


def _pixel_words(u: dict[str, np.ndarray]) -> np.ndarray:
    """(units, 6) candidate words; 0xFFFF marks an absent word (no real word has that value)."""
    n = len(u["t"])
    words = np.full((n, _WORDS_PER_UNIT), 0xFFFF, dtype=np.int64)
    new_row = np.ones(n, dtype=bool)
    new_row[1:] = u["y"][1:] != u["y"][:-1]
    words[new_row, 1] = (ADDR_Y << 12) | u["y"][new_row]
    single, vector = u["kind"] == 0, u["kind"] == 1
    words[single, 3] = (ADDR_X << 12) | (u["p"][single] << 11) | u["x"][single]
    continues = np.zeros(n, dtype=bool)
    continues[1:] = vector[1:] & vector[:-1] & ~new_row[1:] & (u["t"][1:] == u["t"][:-1])
    continues[1:] &= (u["p"][1:] == u["p"][:-1]) & (u["x"][1:] == u["x"][:-1] + 32)
    with_base = vector & ~continues
    words[with_base, 2] = (VECT_BASE_X << 12) | (u["p"][with_base] << 11) | u["x"][with_base]
    m = u["mask"][vector]
    words[vector, 3] = (VECT_12 << 12) | (m & 0xFFF)
    words[vector, 4] = (VECT_12 << 12) | ((m >> 12) & 0xFFF)
    words[vector, 5] = (VECT_8 << 12) | ((m >> 24) & 0xFF)
    return words


def encode_evt3(
    events: Events,
    triggers: Triggers | None = None,
    *,
    width: int = 1280,
    time_high_period_us: int = 16,
    min_vector_run: int = 2,
) -> bytes:
    """EVT 3.0 data bytes (no header) for time-sorted ``events`` and ``triggers``."""
    triggers = np.zeros(0, TRIGGER_DTYPE) if triggers is None else triggers
    _check(events, triggers, width, time_high_period_us)
    if not len(events) and not len(triggers):
        return b""
    units = _pixel_units(events, max(1, min_vector_run))
    pixel = _pixel_words(units)
    trig = np.full((len(triggers), _WORDS_PER_UNIT), 0xFFFF, dtype=np.int64)
    trig[:, 3] = (EXT_TRIGGER << 12) | (triggers["id"].astype(np.int64) << 8) | triggers["p"]
    unit_t = np.concatenate((units["t"], triggers["t"].astype(np.int64)))
    order = np.argsort(unit_t, kind="stable")
    unit_t, words = unit_t[order], np.concatenate((pixel, trig))[order]
    new_time = np.ones(len(unit_t), dtype=bool)
    new_time[1:] = unit_t[1:] != unit_t[:-1]
    words[new_time, 0] = (TIME_LOW << 12) | (unit_t[new_time] & 0xFFF)

    present = words != 0xFFFF
    per_unit = present.sum(axis=1)
    unit_start = np.cumsum(per_unit) - per_unit
    stream = words[present]
    period = time_high_period_us
    beats = np.arange(unit_t[0] // period * period, unit_t[-1] + 1, period, dtype=np.int64)
    before = np.searchsorted(unit_t, beats, side="left")
    at = np.where(before < len(unit_t), unit_start[np.minimum(before, len(unit_t) - 1)], len(stream))
    stream = np.insert(stream, at, (TIME_HIGH << 12) | ((beats >> 12) & 0xFFF))
    return stream.astype("<u2").tobytes()
