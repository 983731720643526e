"""Real Prophesee recordings decode to the published figures, and equal the ``evt3`` package."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from darkread.edge.errors import RawFormatError
from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE
from darkread.edge.io.evt3 import Evt3Decoder
from darkread.edge.io.iterator import EventsIterator
from darkread.edge.io.raw import RawReader, make_decoder, read_raw
from darkread.edge.io.raw_header import format_raw_header

pytestmark = pytest.mark.shared

EVT3_FILES = [
    "gen41_hd_evt3__expelliarmus_evt3_sample.raw",
    "hd_evt3_trigger_erc__event_camera_codecs.raw",
    "vga_evt3_trigger__event_camera_py.raw",
]
ALL_FILES = [*EVT3_FILES, "gen3_vga_evt2__expelliarmus_evt2_sample.raw"]
_CACHE: dict[Path, bytes] = {}


def _bytes(path: Path) -> bytes:
    if path not in _CACHE:
        _CACHE[path] = path.read_bytes()
    return _CACHE[path]


def _figures(events: np.ndarray, triggers: np.ndarray) -> dict[str, object]:
    t = events["t"].astype(np.int64)
    return {
        "cd_events": len(events),
        "on": int(np.count_nonzero(events["p"] == 1)),
        "off": int(np.count_nonzero(events["p"] == 0)),
        "t_first_us": int(t[0]),
        "t_last_us": int(t[-1]),
        "span_us": int(t[-1] - t[0]),
        "x_min": int(events["x"].min()),
        "x_max": int(events["x"].max()),
        "y_min": int(events["y"].min()),
        "y_max": int(events["y"].max()),
        "sum_t_us": int(t.sum()),
        "sum_x": int(events["x"].astype(np.int64).sum()),
        "sum_y": int(events["y"].astype(np.int64).sum()),
        "ext_triggers": len(triggers),
        "trigger_rising": int(np.count_nonzero(triggers["p"] == 1)),
        "trigger_falling": int(np.count_nonzero(triggers["p"] == 0)),
        "trigger_ids": sorted({int(i) for i in triggers["id"]}),
        "sum_trigger_t_us": int(triggers["t"].astype(np.int64).sum()),
    }


@pytest.fixture(scope="module")
def expected(real_events_dir: Path) -> dict[str, dict[str, object]]:
    return json.loads((real_events_dir / "expected_stats.json").read_text())


@pytest.mark.parametrize("name", ALL_FILES)
def test_real_file_matches_every_expected_figure(real_events_dir: Path, expected: dict, name: str) -> None:
    raw = read_raw(real_events_dir / name)
    want = expected[name]
    got = _figures(raw.events, raw.triggers)
    compared = {key: got[key] for key in got if key in want}
    assert compared == {key: want[key] for key in compared}
    assert len(compared) >= 13  # the EVT2 entry has no trigger keys; every other one has all 18
    assert raw.stats.events == want["cd_events"]
    assert raw.stats.words == want.get("data_words_16bit", want.get("data_words_32bit"))
    assert (raw.stats.non_monotonic_time_high, raw.stats.vectors_out_of_range, raw.stats.trailing_bytes) == (0, 0, 0)


@pytest.mark.parametrize("name", EVT3_FILES)
def test_time_shift_matches_openeb(real_events_dir: Path, expected: dict, name: str) -> None:
    shifted = read_raw(real_events_dir / name, time_shift=True)
    assert int(shifted.events["t"][0]) == expected[name]["t_first_us"] - expected[name]["openeb_time_shift_us"]


@pytest.mark.parametrize("name", [*EVT3_FILES, "../sample_recording/events.raw"])
def test_evt3_package_gives_identical_arrays(real_events_dir: Path, name: str) -> None:
    evt3 = pytest.importorskip("evt3")
    ref, ref_triggers = evt3.decode_file_with_triggers(str(real_events_dir / name))
    raw = read_raw(real_events_dir / name)
    assert len(raw.events) == len(ref)
    np.testing.assert_array_equal(raw.events["x"], ref.x)
    np.testing.assert_array_equal(raw.events["y"], ref.y)
    np.testing.assert_array_equal(raw.events["p"], ref.polarity)
    np.testing.assert_array_equal(raw.events["t"], ref.timestamp.astype(np.int64))
    np.testing.assert_array_equal(raw.triggers["t"], np.asarray(ref_triggers.timestamp).astype(np.int64))
    np.testing.assert_array_equal(raw.triggers["p"], ref_triggers.value)
    np.testing.assert_array_equal(raw.triggers["id"], ref_triggers.id)


@pytest.mark.parametrize("name", EVT3_FILES)
def test_numpy_and_compiled_backends_agree_on_real_files(real_events_dir: Path, name: str) -> None:
    pytest.importorskip("numba")
    whole = read_raw(real_events_dir / name)
    payload = _bytes(real_events_dir / name)[whole.header.data_offset :]
    results = []
    for backend in ("numpy", "numba"):
        decoder = Evt3Decoder(whole.header.width, whole.header.height, backend=backend)
        results.append((*decoder.decode(payload), decoder.stats))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])
    assert results[0][2] == results[1][2]


@pytest.mark.parametrize("name", EVT3_FILES)
def test_events_iterator_windows_partition_a_real_file(real_events_dir: Path, name: str) -> None:
    whole = read_raw(real_events_dir / name)
    windows = list(EventsIterator(real_events_dir / name, delta_t=1000, chunk_bytes=1 << 16))
    assert sum(len(w) for w in windows) == len(whole.events)
    np.testing.assert_array_equal(np.concatenate(windows), whole.events)
    start = int(whole.events["t"][0]) // 1000 * 1000
    assert len(windows) == (int(whole.events["t"].max()) - start) // 1000 + 1


def test_sample_recording_decodes_all_events(shared_sample_recording: Path) -> None:
    raw = read_raw(shared_sample_recording / "events.raw")
    assert len(raw.events) == 488_780
    assert raw.header.format == "EVT3" and (raw.header.width, raw.header.height) == (1280, 720)
    assert np.all(np.diff(raw.events["t"]) >= 0)
    meta = json.loads((shared_sample_recording / "meta.json").read_text())
    assert meta["event_count"] == 488_780


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(ALL_FILES), data=st.data())
def test_random_chunking_equals_whole_file_decode(real_events_dir: Path, name: str, data: st.DataObject) -> None:
    path = real_events_dir / name
    whole = read_raw(path)
    blob = _bytes(path)
    payload = memoryview(blob)[whole.header.data_offset :]
    cuts = data.draw(st.lists(st.integers(0, len(payload)), max_size=30))
    small = data.draw(st.lists(st.integers(0, 200), max_size=5))
    bounds = sorted({*cuts, *small, 0, len(payload)})
    decoder = make_decoder(whole.header)
    parts = [decoder.decode(payload[a:b]) for a, b in zip(bounds, bounds[1:])]
    decoder.finish()
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts]), whole.events)
    np.testing.assert_array_equal(np.concatenate([p[1] for p in parts]), whole.triggers)


@pytest.mark.parametrize("chunk_bytes", [1 << 16, 4097])
def test_raw_reader_streams_the_same_events(real_events_dir: Path, chunk_bytes: int) -> None:
    name = EVT3_FILES[2]
    whole = read_raw(real_events_dir / name)
    reader = RawReader(real_events_dir / name, chunk_bytes=chunk_bytes)
    chunks = list(reader)
    assert max(len(c) for c in chunks) < chunk_bytes  # bounded: at most one event per two bytes
    np.testing.assert_array_equal(np.concatenate(chunks), whole.events)
    np.testing.assert_array_equal(reader.triggers, whole.triggers)
    assert reader.triggers.dtype == TRIGGER_DTYPE and all(c.dtype == EVENT_CD_DTYPE for c in chunks)
    assert reader.stats.events == len(whole.events)
    assert reader.get_size() == (480, 640)
    np.testing.assert_array_equal(np.concatenate(list(reader)), whole.events)  # a second pass starts over
    assert reader.stats.events == len(whole.events) and len(reader.triggers) == len(whole.triggers)


@pytest.mark.parametrize("name", ALL_FILES)
def test_truncated_files_decode_a_prefix_and_count_the_cut(real_events_dir: Path, tmp_path: Path, name: str) -> None:
    blob = _bytes(real_events_dir / name)
    whole = read_raw(real_events_dir / name)
    start = whole.header.data_offset
    for cut in (start + 1, start + (len(blob) - start) // 4 * 2 + 1, len(blob) - 1):  # odd data lengths
        path = tmp_path / "cut.raw"
        path.write_bytes(blob[:cut])
        raw = read_raw(path)
        assert raw.stats.trailing_bytes > 0
        assert len(raw.events) <= len(whole.events)
        np.testing.assert_array_equal(raw.events, whole.events[: len(raw.events)])


def test_header_only_missing_and_headerless_files(tmp_path: Path) -> None:
    header_only = tmp_path / "header_only.raw"
    header_only.write_bytes(format_raw_header(1280, 720))
    raw = read_raw(header_only)
    assert len(raw.events) == 0 and len(raw.triggers) == 0 and raw.stats.words == 0
    assert list(RawReader(header_only)) == []
    with pytest.raises(FileNotFoundError):
        read_raw(tmp_path / "missing.raw")
    with pytest.raises(FileNotFoundError):
        RawReader(tmp_path / "missing.raw")
    garbage = tmp_path / "garbage.raw"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 10_000, dtype=np.uint8).tobytes())
    with pytest.raises(RawFormatError):
        read_raw(garbage)


def test_garbage_after_a_valid_header_decodes_within_the_sensor(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    for fmt, (width, height) in (("EVT3", (640, 480)), ("EVT2", (640, 480))):
        path = tmp_path / f"{fmt}.raw"
        path.write_bytes(
            format_raw_header(width, height, fmt) + rng.integers(0, 256, 100_001, dtype=np.uint8).tobytes()
        )
        raw = read_raw(path)
        assert np.all(raw.events["x"] < width) and np.all(raw.events["y"] < height)
        assert np.all(raw.events["t"] >= 0)
        assert raw.stats.trailing_bytes == (1 if fmt == "EVT3" else 1)
        assert raw.stats.skipped_other > 0
