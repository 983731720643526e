"""The live data path: fake board → pyusb → drain thread → decoder → sink."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from factories import random_events

from darkread.edge.errors import DeviceError
from darkread.edge.events import EVENT_CD_DTYPE, Events
from darkread.edge.io.evt3 import Evt3Decoder
from darkread.edge.sources.evk4.camera import Evk4Camera
from darkread.edge.sources.evk4.fake import FakeEvk4, FakeUsbBackend, strip_raw_header


class Collector:
    """A sink that keeps every chunk and notes the thread it was called on."""

    def __init__(self, delay_s: float = 0.0) -> None:
        self.chunks: list[Events] = []
        self.threads: set[str] = set()
        self.delay_s = delay_s
        self.lock = threading.Lock()

    def __call__(self, events: Events) -> None:
        if self.delay_s:
            time.sleep(self.delay_s)
        with self.lock:
            self.chunks.append(events.copy())
            self.threads.add(threading.current_thread().name)

    @property
    def count(self) -> int:
        with self.lock:
            return sum(len(c) for c in self.chunks)

    def events(self) -> Events:
        with self.lock:
            return np.concatenate(self.chunks) if self.chunks else np.zeros(0, EVENT_CD_DTYPE)


def wait_for(condition: Callable[[], bool], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError("condition not met in time")
        time.sleep(0.002)


def event_keys(events: Events) -> np.ndarray:
    """One integer per event (t, x, y, p), for set comparisons."""
    t, x, y, p = (events[k].astype(np.int64) for k in ("t", "x", "y", "p"))
    return (((t << 11) | x) << 10 | y) << 1 | p


def camera_on(fake: FakeEvk4, **kwargs: Any) -> Evk4Camera:
    return Evk4Camera(backend=FakeUsbBackend([fake]), sleep=lambda s: None, **kwargs)


@pytest.mark.parametrize("chunk_bytes", [4099, 65536])
def test_sink_receives_exactly_the_served_events(chunk_bytes: int) -> None:
    events = random_events(30_000, t0=5_000_000, rate_hz=2e6, seed=chunk_bytes)
    fake = FakeEvk4.from_events(events, chunk_bytes=chunk_bytes)
    sink = Collector()
    camera = camera_on(fake, transfer_bytes=32 * 1024)
    camera.start(sink)
    wait_for(lambda: fake.exhausted)
    camera.stop()  # returns after every byte read so far has reached the sink
    camera.close()
    got = sink.events()
    np.testing.assert_array_equal(got, events)
    assert sink.threads == {"evk4-decode"}
    stats = camera.stats
    assert stats["bytes_read"] == len(fake.recording) and stats["events"] == len(events)
    assert stats["dropped_bytes"] == 0 and stats["event_rate_ev_s"] > 0


def test_nothing_is_served_before_start() -> None:
    fake = FakeEvk4.from_events(random_events(1000))
    camera = camera_on(fake)
    camera.open()
    time.sleep(0.01)
    assert fake.served_bytes == 0 and camera.stats["bytes_read"] == 0
    camera.close()


def test_stop_halts_the_stream() -> None:
    fake = FakeEvk4.from_events(random_events(200_000, seed=1), chunk_bytes=1024, rate_bytes_s=1e6)
    sink = Collector()
    camera = camera_on(fake, transfer_bytes=1024)
    camera.start(sink)
    wait_for(lambda: sink.count > 10_000)
    camera.stop()
    served, delivered, calls = fake.served_bytes, sink.count, len(sink.chunks)
    time.sleep(0.05)
    assert (fake.served_bytes, sink.count, len(sink.chunks)) == (served, delivered, calls)
    assert not fake.streaming and not camera.is_running and camera.stats["running"] == 0
    assert served < len(fake.recording)
    camera.start(sink)  # a stopped camera starts again where the sensor is
    wait_for(lambda: sink.count > delivered + 10_000)
    camera.close()


def test_slow_sink_never_stalls_the_endpoint() -> None:
    events = random_events(40_000, seed=2)
    fake = FakeEvk4.from_events(events, chunk_bytes=2048, rate_bytes_s=1e6)
    sink = Collector(delay_s=0.02)
    camera = camera_on(fake, transfer_bytes=2048, max_queue_bytes=8192)
    camera.start(sink)
    wait_for(lambda: fake.exhausted)
    camera.stop()
    stats = camera.stats
    assert stats["bytes_read"] == len(fake.recording)
    assert 0 < stats["dropped_bytes"] < stats["bytes_read"] and stats["stream_gaps"] > 0
    got = sink.events()
    assert 0 < len(got) < len(events)
    # Dropping costs events, never correctness: what arrives are exact original events, in order.
    assert np.isin(event_keys(got), event_keys(events)).all()
    assert (np.diff(got["t"]) >= 0).all()
    camera.close()


def test_sink_errors_are_counted_and_the_stream_goes_on() -> None:
    calls: list[int] = []

    def failing_once(events: Events) -> None:
        calls.append(len(events))
        if len(calls) == 1:
            raise RuntimeError("downstream broke")

    events = random_events(20_000, seed=3)
    fake = FakeEvk4.from_events(events, chunk_bytes=8192, rate_bytes_s=2e6)
    camera = camera_on(fake, transfer_bytes=8192)
    camera.start(failing_once)
    wait_for(lambda: fake.exhausted)
    camera.stop()
    assert camera.stats["sink_errors"] == 1 and len(calls) > 1
    assert sum(calls) == len(events)  # only the failed chunk is lost downstream, nothing upstream
    camera.close()


def test_unplugged_camera_ends_the_stream_with_a_clear_error() -> None:
    fake = FakeEvk4.from_events(random_events(50_000, seed=4), chunk_bytes=1024, rate_bytes_s=1e6)
    sink = Collector()
    camera = camera_on(fake, transfer_bytes=1024)
    camera.start(sink)
    wait_for(lambda: sink.count > 0)
    fake.unplug()
    wait_for(lambda: camera.error is not None)
    assert "disappeared" in str(camera.error) and camera.stats["reader_failed"] == 1
    with pytest.raises(DeviceError, match="disappeared"):
        camera.stop()
    camera.close()  # best effort after an unplug: logs, does not raise
    assert not camera.is_open and not fake.claimed


@pytest.mark.shared
def test_real_recording_streams_like_one_whole_decode(real_events_dir: Path) -> None:
    path = real_events_dir / "hd_evt3_trigger_erc__event_camera_codecs.raw"
    payload = strip_raw_header(path.read_bytes())
    expected, _ = Evt3Decoder(width=1280, height=720).decode(payload)
    fake = FakeEvk4.from_raw(path, chunk_bytes=16 * 1024 + 1)
    sink = Collector()
    camera = camera_on(fake, transfer_bytes=32 * 1024)
    camera.start(sink)
    wait_for(lambda: fake.exhausted)
    camera.close()
    np.testing.assert_array_equal(sink.events(), expected)
    assert len(expected) == 82_469
