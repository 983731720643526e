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

from collections.abc import Iterator

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


def _pixel_words(u: dict[str, np.ndarray], previous_y: int = -1) -> np.ndarray:
    """(units, 6) candidate words; 0xFFFF marks an absent word (no real word has that value).
    ``previous_y``: the row of the pixel unit before these (-1: none), whose ``EVT_ADDR_Y`` still holds."""
    n = len(u["t"])
    words = np.full((n, _WORDS_PER_UNIT), 0xFFFF, dtype=np.int64)
    new_row = np.ones(n, dtype=bool)
    new_row[1:] = u["y"][1:] != u["y"][:-1]
    if n:
        new_row[0] = u["y"][0] != previous_y
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


def _encode_part(events: Events, triggers: Triggers, period: int, min_vector_run: int, first_beat: int,
                 previous_y: int) -> tuple[np.ndarray, int, int]:
    """The words of one stretch of the stream (every unit at or after ``first_beat``'s time high
    bits), the next beat not yet sent and the row of its last pixel unit (``previous_y`` if none)."""
    units = _pixel_units(events, min_vector_run)
    pixel = _pixel_words(units, previous_y)
    trig = np.full((len(triggers), _WORDS_PER_UNIT), 0xFFFF, dtype=np.int64)
    trig[:, 3] = (EXT_TRIGGER << 12) | (triggers["id"].astype(np.int64) << 8) | triggers["p"]
    unit_t = np.concatenate((units["t"], triggers["t"].astype(np.int64)))
    order = np.argsort(unit_t, kind="stable")
    unit_t, words = unit_t[order], np.concatenate((pixel, trig))[order]
    del pixel, trig, order
    new_time = np.ones(len(unit_t), dtype=bool)
    new_time[1:] = unit_t[1:] != unit_t[:-1]  # (the first unit's time always differs from the stretch before)
    words[new_time, 0] = (TIME_LOW << 12) | (unit_t[new_time] & 0xFFF)

    present = words != 0xFFFF
    per_unit = present.sum(axis=1)
    unit_start = np.cumsum(per_unit) - per_unit
    stream = words[present]
    del words, present
    beats = np.arange(first_beat, unit_t[-1] + 1, period, dtype=np.int64)
    before = np.searchsorted(unit_t, beats, side="left")
    at = np.where(before < len(unit_t), unit_start[np.minimum(before, len(unit_t) - 1)], len(stream))
    stream = np.insert(stream, at, (TIME_HIGH << 12) | ((beats >> 12) & 0xFFF))
    last_y = int(units["y"][-1]) if len(units["y"]) else previous_y
    return stream.astype("<u2"), int(beats[-1]) + period if len(beats) else first_beat, last_y


def encode_evt3_parts(
    events: Events,
    triggers: Triggers | None = None,
    *,
    width: int = 1280,
    time_high_period_us: int = 16,
    min_vector_run: int = 2,
    events_per_part: int = 1 << 18,
) -> Iterator[bytes]:
    """``encode_evt3``'s bytes in parts of about ``events_per_part`` events, for a writer that
    streams them: the encoding's working arrays cost several times the events' own memory, and
    a recording encoded whole fell out of cache (models/synth/STATUS.md, "Memory").
    Parts end between two event times, and each carries on the stream's state (the row whose
    ``EVT_ADDR_Y`` holds, the next ``TIME_HIGH``), so the parts joined are ``encode_evt3``'s
    bytes exactly."""
    triggers = np.zeros(0, TRIGGER_DTYPE) if triggers is None else triggers
    period = time_high_period_us
    _check(events, triggers, width, period)
    if not len(events) and not len(triggers):
        return
    if events_per_part < 1:
        raise ValueError(f"events_per_part must be positive, got {events_per_part}")
    t0 = min(int(events["t"][0]) if len(events) else 1 << 62, int(triggers["t"][0]) if len(triggers) else 1 << 62)
    # part boundaries: the first event of a new time after every events_per_part events
    cuts = [0]
    while cuts[-1] + events_per_part < len(events):
        at = int(np.searchsorted(events["t"], events["t"][cuts[-1] + events_per_part], side="left"))
        cuts.append(at if at > cuts[-1] else int(np.searchsorted(events["t"], events["t"][cuts[-1]], side="right")))
    cuts = [c for c in cuts if c < len(events)] or [0]
    bounds = [int(events["t"][c]) for c in cuts[1:]] if len(events) else []
    ends = [*cuts[1:], len(events)]
    trigger_cuts = np.searchsorted(triggers["t"], bounds, side="left") if len(triggers) else np.zeros(len(bounds), int)
    trigger_ends = [*map(int, trigger_cuts), len(triggers)]
    next_beat, row = t0 // period * period, -1
    trigger_start = 0
    for start, end, trigger_end in zip(cuts, ends, trigger_ends, strict=True):
        part_events, part_triggers = events[start:end], triggers[trigger_start:trigger_end]
        trigger_start = trigger_end
        if not len(part_events) and not len(part_triggers):
            continue
        words, next_beat, row = _encode_part(part_events, part_triggers, period, max(1, min_vector_run), next_beat, row)
        yield words.tobytes()


def encode_evt3(
    events: Events,
    triggers: Triggers | None = None,
    *,
    width: int = 1280,
    time_high_period_us: int = 16,
    min_vector_run: int = 2,
) -> bytes:
    """EVT 3.0 data bytes (no header) for time-sorted ``events`` and ``triggers``."""
    return b"".join(encode_evt3_parts(events, triggers, width=width, time_high_period_us=time_high_period_us,
                                      min_vector_run=min_vector_run))
