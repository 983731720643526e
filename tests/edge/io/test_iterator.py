"""EventsIterator slicing (exact windows) and PacedReplay on a fake clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from factories import random_events

from darkread.edge.events import EVENT_CD_DTYPE, empty_events, make_events
from darkread.edge.io.iterator import EventsIterator, PacedReplay
from darkread.edge.io.raw import read_raw, write_raw

T = [1003, 1005, 1011, 1040, 1041, 1069, 1070]


def stream(times: list[int] = T) -> np.ndarray:
    return make_events(np.arange(len(times)) % 640, 1, 1, times)


def chunked(events: np.ndarray, sizes: list[int]) -> list[np.ndarray]:
    cuts = np.cumsum(sizes)[:-1]
    return np.split(events, cuts)


@pytest.mark.parametrize("sizes", [[7], [1, 1, 1, 1, 1, 1, 1], [2, 0, 5], [4, 3]])
def test_delta_t_windows_are_fixed_and_empty_ones_are_zero_length(sizes: list[int]) -> None:
    it = EventsIterator(chunked(stream(), sizes), delta_t=10)
    windows = list(it)
    assert [list(w["t"]) for w in windows] == [[1003, 1005], [1011], [], [], [1040, 1041], [], [1069], [1070]]
    assert all(w.dtype == EVENT_CD_DTYPE for w in windows)
    assert it.get_current_time() == 1080


def test_delta_t_with_start_ts_and_max_duration() -> None:
    windows = list(EventsIterator([stream()], delta_t=20, start_ts=1004, max_duration=50))
    assert [list(w["t"]) for w in windows] == [[1005, 1011], [1040, 1041], []]  # last window clipped at 1054


def test_n_events_slices_have_fixed_counts() -> None:
    it = EventsIterator(chunked(stream(), [2, 2, 3]), mode="n_events", n_events=3)
    assert [list(w["t"]) for w in it] == [[1003, 1005, 1011], [1040, 1041, 1069], [1070]]


def test_n_events_with_start_and_duration() -> None:
    it = EventsIterator([stream()], mode="n_events", n_events=2, start_ts=1004, max_duration=66)
    assert [list(w["t"]) for w in it] == [[1005, 1011], [1040, 1041], [1069]]


def test_bad_arguments_raise_value_error() -> None:
    with pytest.raises(ValueError, match="mode"):
        EventsIterator([], mode="mixed-up")
    with pytest.raises(ValueError):
        EventsIterator([], delta_t=0)


def test_empty_source_yields_nothing_and_size_defaults() -> None:
    it = EventsIterator([])
    assert list(it) == []
    assert it.get_size() == (720, 1280)
    assert EventsIterator([], sensor_size=(480, 640)).get_size() == (480, 640)


def test_file_source_windows_cover_every_event_in_order(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    times = np.sort(rng.integers(3_000_000, 3_200_000, 5000))
    events = make_events(rng.integers(0, 640, 5000), rng.integers(0, 480, 5000), rng.integers(0, 2, 5000), times)
    path = tmp_path / "rec.raw"
    write_raw(path, events, width=640, height=480)
    it = EventsIterator(path, delta_t=10_000, chunk_bytes=4096)
    windows = list(it)
    assert it.get_size() == (480, 640)
    assert len(windows) == 20  # 3.00 s .. 3.20 s in 10 ms windows
    for k, w in enumerate(windows):
        assert np.all((w["t"] >= 3_000_000 + k * 10_000) & (w["t"] < 3_010_000 + k * 10_000))
    np.testing.assert_array_equal(np.concatenate(windows), read_raw(path).events)


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(round(seconds, 9))
        self.now += seconds


def test_paced_replay_sleeps_to_match_recording_time() -> None:
    clock = FakeClock()
    it = EventsIterator([stream()], delta_t=10)
    out = list(PacedReplay(it, speed=1.0, clock=clock, sleep=clock.sleep))
    assert len(out) == 8
    assert clock.sleeps == [10e-6] * 7  # one window of 10 µs each after the first, empty ones too
    assert clock.now == pytest.approx(100.0 + 70e-6)


def test_paced_replay_speed_scales_and_none_never_sleeps() -> None:
    clock = FakeClock()
    slices = [make_events(0, 0, 0, [0]), make_events(0, 0, 0, [1_000_000]), make_events(0, 0, 0, [1_500_000])]
    list(PacedReplay(slices, speed=2.0, clock=clock, sleep=clock.sleep))
    assert clock.sleeps == [0.5, 0.25]
    clock2 = FakeClock()
    assert len(list(PacedReplay(slices, speed=None, clock=clock2, sleep=clock2.sleep))) == 3
    assert clock2.sleeps == []


def test_paced_replay_in_batches_hands_over_late_never_early() -> None:
    """With ``batch_s`` the replay sleeps past a slice's time by that much and hands over every slice
    due meanwhile at once: fewer wake-ups, each slice at most ``batch_s`` late and never early."""
    clock = FakeClock()
    times_us = [0, 1_000, 2_000, 3_000, 4_000, 10_000]
    slices = [make_events(0, 0, 0, [t]) for t in times_us]
    handed: list[float] = []
    replay = PacedReplay(slices, speed=1.0, clock=clock, sleep=clock.sleep, batch_s=0.002)
    for _ in replay:
        handed.append(clock.now - 100.0)
    assert clock.sleeps == [0.003, 0.003, 0.006]  # 1 ms due at 0: 1 + 2; 4 ms due at 3 ms: 1 + 2; 10 ms due at 6 ms: 4 + 2
    assert handed == pytest.approx([0.0, 0.003, 0.003, 0.003, 0.006, 0.012])
    assert all(0 <= h - t / 1e6 <= 0.002 + 1e-12 for h, t in zip(handed, times_us))
    assert replay.max_lag_s == 0.0  # lateness within the batch is not the consumer's lag
    with pytest.raises(ValueError):
        PacedReplay(slices, batch_s=-0.001)


def test_a_coalescing_replay_joins_what_came_due_at_one_wake_up() -> None:
    """As a camera's driver hands over what its transfers queued: one array per wake-up, every event
    once and in order, empty slices dropped; a consumer that fell behind gets larger chunks."""
    clock = FakeClock()
    times_us = [0, 1_000, 2_000, 3_000, 4_000, 10_000]
    slices = [make_events(0, 0, 0, [t]) for t in times_us] + [make_events(0, 0, 0, [])]
    replay = PacedReplay(slices, speed=1.0, clock=clock, sleep=clock.sleep, batch_s=0.002, coalesce=True)
    chunks = [(chunk["t"].tolist(), round(clock.now - 100.0, 6)) for chunk in replay]
    # due at 0 ms; woken at 3 ms: 1, 2, 3 ms due; woken at 6 ms: 4 ms; woken at 12 ms: 10 ms
    assert chunks == [([0], 0.0), ([1_000, 2_000, 3_000], 0.003), ([4_000], 0.006), ([10_000], 0.012)]
    late = FakeClock()
    many = [make_events(0, 0, 0, [t]) for t in range(0, 200_000, 1_000)]
    behind = PacedReplay(many, speed=1.0, clock=late, sleep=late.sleep, batch_s=0.002, coalesce=True)
    sizes = []
    for chunk in behind:
        sizes.append(chunk.shape[0])
        late.now += 0.1  # each chunk takes the consumer 100 ms: more came due than a chunk holds
    assert sum(sizes) == 200 and max(sizes) == PacedReplay.MAX_COALESCED and len(sizes) < 20
    unpaced = list(PacedReplay(many, speed=None, coalesce=True))  # a lossless replay: slice by slice, as before
    assert len(unpaced) == 200 and all(a is b for a, b in zip(unpaced, many))


def test_paced_replay_does_not_sleep_when_the_consumer_is_late() -> None:
    clock = FakeClock()
    slices = [make_events(0, 0, 0, [0]), make_events(0, 0, 0, [100_000]), make_events(0, 0, 0, [200_000])]
    replay = PacedReplay(slices, clock=clock, sleep=clock.sleep)
    for _ in replay:
        clock.now += 0.3  # processing takes longer than the recording
    assert clock.sleeps == []
    assert replay.max_lag_s == pytest.approx(0.4)
    with pytest.raises(ValueError):
        PacedReplay(slices, speed=0)


def test_non_empty_windows_cut_on_the_grid_and_keep_every_event() -> None:
    ev = random_events(10_000, rate_hz=1e6, seed=3)
    chunks = [ev[i : i + 777] for i in range(0, len(ev), 777)]
    slices = [w for w in EventsIterator(chunks, delta_t=1000) if len(w)]  # what the replay delivers
    assert np.array_equal(np.concatenate(slices), ev)
    for piece in slices:
        assert piece.shape[0] > 0
        assert piece["t"][0] // 1000 == piece["t"][-1] // 1000
    keys = [int(p["t"][0]) // 1000 for p in slices]
    assert keys == sorted(set(keys))


def test_windows_of_nothing() -> None:
    assert list(EventsIterator([], delta_t=1000)) == []
    assert list(EventsIterator([empty_events()], delta_t=1000)) == []
