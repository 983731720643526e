"""Event ring: wrap-around, last(n), since(t), drop counter, one writer + one reader."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from factories import random_events

from darkread.edge.ring import EventRing


def stream(n: int, seed: int = 0) -> np.ndarray:
    events = random_events(n, seed=seed)
    events["t"] = np.arange(n)  # unique, sorted times make content checks exact
    return events


def test_many_small_pushes_wrap_around() -> None:
    events = stream(1000)
    ring = EventRing(64)
    for start in range(0, 1000, 7):
        ring.push(events[start : start + 7])
        held = ring.last(64)
        newest = events[: min(start + 7, 1000)][-64:]
        assert np.array_equal(held, newest)
    assert len(ring) == 64 and ring.total_pushed == 1000 and ring.overwritten == 1000 - 64
    assert ring.newest_t == 999


def test_push_larger_than_capacity_keeps_the_newest() -> None:
    events = stream(500)
    ring = EventRing(100)
    ring.push(events[:30])
    ring.push(events[30:])
    assert np.array_equal(ring.last(1000), events[-100:])
    assert ring.overwritten == 400 and ring.total_pushed == 500


def test_last_and_since() -> None:
    events = stream(250)
    ring = EventRing(100)
    ring.push(events[:90])
    ring.push(events[90:250])  # wraps, 150 overwritten
    assert np.array_equal(ring.last(10), events[240:])
    assert np.array_equal(ring.last(0), events[:0])
    assert np.array_equal(ring.since(200), events[200:])
    assert np.array_equal(ring.since(0), events[150:])  # older ones are gone
    assert ring.since(10_000).shape == (0,)
    # since() across the wrap point of the storage
    ring.push(events[:0])
    ring2 = EventRing(100)
    for chunk in np.array_split(events, 9):
        ring2.push(chunk)
    for t in (150, 170, 199, 249):
        assert np.array_equal(ring2.since(t), events[t:])


def test_empty_ring() -> None:
    ring = EventRing(8)
    assert len(ring) == 0 and ring.newest_t is None
    assert ring.last(5).shape == (0,) and ring.since(0).shape == (0,)
    with pytest.raises(ValueError):
        EventRing(0)


def test_returned_arrays_are_copies() -> None:
    events = stream(20)
    ring = EventRing(16)
    ring.push(events)
    snapshot = ring.last(16)
    ring.push(stream(16, seed=5))
    assert np.array_equal(snapshot, events[4:])


def test_concurrent_writer_and_reader() -> None:
    events = stream(200_000, seed=2)
    ring = EventRing(4096)
    done = threading.Event()
    problems: list[str] = []

    def reader() -> None:
        while not done.is_set():
            window = ring.last(1600)
            t = window["t"]
            # contiguous, ordered slices of the stream: a torn read would break this
            if t.size and not np.array_equal(t, np.arange(t[0], t[0] + t.size)):
                problems.append("torn read")
            recent = ring.since(int(t[-1]) - 10 if t.size else 0)
            if recent.size and np.any(np.diff(recent["t"]) != 1):
                problems.append("torn since")

    thread = threading.Thread(target=reader)
    thread.start()
    for chunk in np.array_split(events, 400):
        ring.push(chunk)
    done.set()
    thread.join(timeout=10)
    assert not problems
    assert ring.total_pushed == 200_000 and ring.overwritten == 200_000 - 4096
    assert np.array_equal(ring.last(4096), events[-4096:])
