from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from factories import random_events

from darkread.edge.events import Events, empty_events
from darkread.edge.io.raw import read_raw, write_raw
from darkread.edge.sources.base import EventSource
from darkread.edge.sources.replay import ReplaySource, parse_speed


def unique_events(n: int, duration_us: int, seed: int = 0) -> Events:
    """Time-sorted events with no pixel firing twice at one timestamp (as EVT3 requires)."""
    ev = random_events(n, t0=5_000, rate_hz=n / (duration_us / 1e6), seed=seed)
    _, keep = np.unique(np.stack([ev["t"], ev["y"].astype(np.int64), ev["x"].astype(np.int64)]), axis=1, return_index=True)
    return ev[np.sort(keep)]


@pytest.fixture
def raw_file(tmp_path: Path) -> tuple[Path, Events]:
    ev = unique_events(20_000, duration_us=200_000)
    path = tmp_path / "events.raw"
    write_raw(path, ev)
    return path, read_raw(path).events


class Collector:
    def __init__(self) -> None:
        self.chunks: list[Events] = []
        self.times: list[float] = []
        self.threads: set[str] = set()

    def __call__(self, events: Events) -> None:
        self.chunks.append(events.copy())
        self.times.append(time.perf_counter())
        self.threads.add(threading.current_thread().name)

    def events(self) -> Events:
        return np.concatenate(self.chunks) if self.chunks else empty_events()


def test_replay_as_fast_as_possible_delivers_every_event(raw_file) -> None:
    path, expected = raw_file
    source = ReplaySource(path, speed=None)
    assert isinstance(source, EventSource)
    assert (source.width, source.height) == (1280, 720)
    sink = Collector()
    source.start(sink)
    assert source.wait(5)
    source.stop()
    assert np.array_equal(sink.events(), expected)
    assert sink.threads == {"replay-reader"}
    assert source.stats["events_out"] == expected.shape[0]
    assert source.stats["realtime_factor"] > 1


def test_replay_is_paced_at_the_requested_speed(raw_file) -> None:
    path, expected = raw_file  # 0.2 s of events
    source = ReplaySource(path, speed=2.0)
    sink = Collector()
    started = time.perf_counter()
    source.start(sink)
    assert source.wait(5)
    elapsed = time.perf_counter() - started
    span_s = (expected["t"][-1] - expected["t"][0]) / 1e6
    assert elapsed >= span_s / 2 * 0.9  # not faster than asked
    # each slice is handed over no earlier than its last event's (scaled) time
    t0, w0 = int(sink.chunks[0]["t"][0]), sink.times[0]
    lateness = [(w - w0) - (int(c["t"][-1]) - t0) / 2e6 for c, w in zip(sink.chunks, sink.times)]
    assert min(lateness) > -0.005
    assert np.array_equal(sink.events(), expected)


def test_stop_interrupts_a_slow_replay(raw_file) -> None:
    path, _ = raw_file
    source = ReplaySource(path, speed=0.05)  # 4 s of wall time
    sink = Collector()
    source.start(sink)
    time.sleep(0.05)
    started = time.perf_counter()
    source.stop()
    assert time.perf_counter() - started < 1.0
    assert source.finished.is_set()


@pytest.mark.parametrize("slice_us", [1_000, None])
def test_roi_is_applied_in_the_decoder_as_the_sensor_would_deliver_it(raw_file, slice_us) -> None:
    path, expected = raw_file
    source = ReplaySource(path, speed=None, slice_us=slice_us)
    assert source.roi == (0, 0, source.width, source.height)  # read out as the camera's: the whole sensor
    source.set_roi(100, 50, 200, 100)
    assert source.roi == (100, 50, 200, 100)
    sink = Collector()
    source.start(sink)
    source.wait(5)
    got = sink.events()
    inside = expected[(expected["x"] >= 100) & (expected["x"] < 300) & (expected["y"] >= 50) & (expected["y"] < 150)]
    assert np.array_equal(got, inside)
    stats = source.stats
    assert stats["events_out"] == len(inside)  # what crossed USB, not what the file holds
    assert stats["words_outside_roi"] >= len(expected) - len(inside)  # (EVT3 vectors: a word may hold several)
    with pytest.raises(ValueError):
        source.set_roi(0, 0, 0, 10)


def test_a_roi_set_while_replaying_applies_from_the_next_chunk(raw_file) -> None:
    path, expected = raw_file
    source = ReplaySource(path, speed=None, slice_us=None, chunk_bytes=1 << 12)
    chunks: list[Events] = []

    def sink(events: Events) -> None:
        chunks.append(events)
        if len(chunks) == 3:
            source.set_roi(0, 0, 640, 360)  # from the fourth chunk on: the top-left quarter only
        if len(chunks) == 6:
            source.set_roi(0, 0, 1280, 720)  # and the whole sensor again from the seventh

    source.start(sink)
    source.wait(5)
    assert len(chunks) > 7
    quarter = np.concatenate(chunks[3:6])
    assert quarter["x"].max() < 640 and quarter["y"].max() < 360
    assert np.concatenate(chunks[6:])["x"].max() >= 640
    kept = np.concatenate(chunks)
    assert kept.shape[0] < expected.shape[0] and kept.shape[0] == source.stats["events_out"]


def test_bad_arguments(raw_file, tmp_path: Path) -> None:
    path, _ = raw_file
    with pytest.raises(ValueError):
        ReplaySource(path, speed=-1)
    with pytest.raises(FileNotFoundError):
        ReplaySource(tmp_path / "missing.raw")
    source = ReplaySource(path, speed=None)
    source.start(Collector())
    with pytest.raises(RuntimeError):
        source.start(Collector())
    source.stop()


@pytest.mark.parametrize(("text", "expected"), [("max", None), ("0", None), ("2", 2.0), (None, None), ("0.5", 0.5)])
def test_parse_speed(text, expected) -> None:
    assert parse_speed(text) == expected


def test_parse_speed_rejects_negative() -> None:
    with pytest.raises(ValueError):
        parse_speed("-2")


def test_replay_of_the_sample_recording(shared_sample_recording: Path) -> None:
    source = ReplaySource(shared_sample_recording / "events.raw", speed=None)
    sink = Collector()
    source.start(sink)
    assert source.wait(20)
    assert source.error is None
    assert source.stats["events_out"] == 488_780
