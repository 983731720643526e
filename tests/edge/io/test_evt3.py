"""EVT 3.0 decoder: word-level rules, chunking, bad input (the encoder has its own section below)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.errors import CorruptRawError
from darkread.edge.events import TRIGGER_DTYPE, empty_events, make_events
from darkread.edge.io.evt3 import Evt3Decoder, decode_evt3, encode_evt3
from darkread.edge.io.raw import RawReader, read_raw, write_raw


def w(kind: int, payload: int) -> int:
    return (kind << 12) | payload


def pack(*words: int) -> bytes:
    return np.array(words, dtype="<u2").tobytes()


HAVE_NUMBA = importlib.util.find_spec("numba") is not None
BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed"))]
CHUNKED_BACKEND = "auto"


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    return request.param


TH, TL, Y, X, BASE, V12, V8, TRIG, OTHERS, CONT12, CONT4 = 8, 6, 0, 2, 3, 4, 5, 0xA, 0xE, 0xF, 0x7


def columns(events: np.ndarray) -> list[tuple[int, int, int, int]]:
    return [(int(e["x"]), int(e["y"]), int(e["p"]), int(e["t"])) for e in events]


def test_single_events_take_row_time_and_polarity(backend: str) -> None:
    data = pack(w(TH, 5), w(TL, 7), w(Y, 10), w(X, 3 | 0x800), w(X, 4), w(TL, 9), w(Y, 11), w(X, 1279))
    events, triggers = decode_evt3(data, backend=backend)
    assert columns(events) == [(3, 10, 1, 5 * 4096 + 7), (4, 10, 0, 5 * 4096 + 7), (1279, 11, 0, 5 * 4096 + 9)]
    assert len(triggers) == 0


def test_vector_group_expands_bits_from_base_and_advances_it(backend: str) -> None:
    # base 64 ON; VECT_12 bits 0 and 11; VECT_12 bit 0 (-> 76); VECT_8 bit 7 (-> 88 + 7); then a continuation group
    data = pack(w(TH, 1), w(TL, 2), w(Y, 3), w(BASE, 64 | 0x800), w(V12, 0x801), w(V12, 0x001), w(V8, 0xF80), w(V12, 1))
    events, _ = decode_evt3(data, backend=backend)
    assert [e[0] for e in columns(events)] == [64, 75, 76, 95, 96]
    assert set(events["p"]) == {1} and set(events["y"]) == {3}
    assert set(events["t"]) == {4096 + 2}


def test_vectors_and_single_events_keep_stream_order(backend: str) -> None:
    data = pack(w(TH, 0), w(TL, 1), w(Y, 0), w(X, 500), w(BASE, 32), w(V12, 3), w(X, 7), w(V12, 1), w(X, 8))
    events, _ = decode_evt3(data, backend=backend)
    assert [e[0] for e in columns(events)] == [500, 32, 33, 7, 44, 8]


def test_vector_beyond_width_is_dropped_and_counted(backend: str) -> None:
    decoder = Evt3Decoder(640, 480, backend=backend)
    events, _ = decoder.decode(pack(w(TH, 0), w(Y, 1), w(BASE, 636), w(V12, 0xFFF), w(V8, 1), w(X, 639)))
    assert columns(events) == [(639, 1, 0, 0)]
    assert decoder.stats.vectors_out_of_range == 2


def test_time_high_change_resets_low_and_repeat_keeps_it(backend: str) -> None:
    data = pack(w(TH, 1), w(TL, 100), w(TH, 1), w(X, 0), w(TH, 2), w(X, 1), w(TL, 5), w(TL, 3), w(X, 2))
    events, _ = decode_evt3(data, backend=backend)
    assert list(events["t"]) == [4096 + 100, 2 * 4096, 2 * 4096 + 3]


def test_time_high_wrap_adds_a_loop_and_small_drop_is_non_monotonic(backend: str) -> None:
    decoder = Evt3Decoder(backend=backend)
    data = pack(w(TH, 4095), w(TL, 1), w(X, 0), w(TH, 0), w(TL, 2), w(X, 1), w(TH, 1), w(X, 2))
    events, _ = decoder.decode(data)
    assert list(events["t"]) == [4095 * 4096 + 1, (1 << 24) + 2, (1 << 24) + 4096]
    assert decoder.stats.non_monotonic_time_high == 0
    # a drop smaller than 2048 is counted; events are dropped until time is back at its maximum
    events, _ = decoder.decode(pack(w(TH, 0), w(X, 3), w(TH, 1), w(TL, 7), w(X, 4)))
    assert list(events["t"]) == [(1 << 24) + 4096 + 7]
    assert decoder.stats.non_monotonic_time_high == 1
    assert decoder.stats.dropped_non_monotonic == 1


def test_words_before_first_time_high_are_skipped(backend: str) -> None:
    decoder = Evt3Decoder(backend=backend)
    events, _ = decoder.decode(pack(w(Y, 5), w(X, 1), w(TL, 3), w(TH, 7), w(X, 2)))
    assert columns(events) == [(2, 0, 0, 7 * 4096)]
    assert decoder.stats.skipped_before_time_high == 3
    assert decoder.stats.words == 5


def test_triggers_others_and_continued_words(backend: str) -> None:
    decoder = Evt3Decoder(backend=backend)
    data = pack(
        w(TH, 3),
        w(TL, 9),
        w(TRIG, 0x601),
        w(OTHERS, 0x14),
        w(CONT12, 0xFFF),
        w(CONT12, 1),
        w(CONT4, 2),
        w(0xB, 0),
        w(0xD, 1),
        w(Y, 2),
        w(X, 5),
        w(TRIG, 0x600),
    )
    events, triggers = decoder.decode(data)
    assert columns(events) == [(5, 2, 0, 3 * 4096 + 9)]
    assert [(int(t["p"]), int(t["id"]), int(t["t"])) for t in triggers] == [(1, 6, 3 * 4096 + 9), (0, 6, 3 * 4096 + 9)]
    assert decoder.stats.skipped_other == 6
    assert (decoder.stats.events, decoder.stats.triggers) == (1, 2)


def test_time_shift_subtracts_openeb_offset(backend: str) -> None:
    events, _ = decode_evt3(pack(w(TH, 10), w(TL, 5), w(X, 0), w(TH, 11), w(X, 1)), time_shift=True, backend=backend)
    assert list(events["t"]) == [4096 + 5, 2 * 4096]


def test_y_range_keeps_only_those_rows(backend: str) -> None:
    data = pack(w(TH, 0), w(Y, 9), w(X, 0), w(Y, 10), w(X, 1), w(Y, 19), w(X, 2), w(Y, 20), w(X, 3))
    events, _ = decode_evt3(data, y_range=(10, 20), backend=backend)
    assert list(events["y"]) == [10, 19]


def test_pixels_outside_the_sensor_are_dropped_and_counted(backend: str) -> None:
    decoder = Evt3Decoder(640, 480, backend=backend)
    events, _ = decoder.decode(pack(w(TH, 0), w(Y, 479), w(X, 640), w(X, 639), w(Y, 480), w(X, 0)))
    assert columns(events) == [(639, 479, 0, 0)]
    assert decoder.stats.events_out_of_range == 2


def test_odd_trailing_byte_is_counted_or_raises_in_strict_mode(backend: str) -> None:
    data = pack(w(TH, 0), w(X, 1)) + b"\x01"
    decoder = Evt3Decoder(path="cut.raw", byte_offset=100, backend=backend)
    events, _ = decoder.decode(data)
    decoder.finish()
    assert len(events) == 1 and decoder.stats.trailing_bytes == 1
    strict = Evt3Decoder(path="cut.raw", byte_offset=100, strict=True, backend=backend)
    strict.decode(data)
    with pytest.raises(CorruptRawError, match=r"cut\.raw at byte 104"):
        strict.finish()


def test_empty_and_garbage_input_never_crash(backend: str) -> None:
    assert len(decode_evt3(b"", backend=backend)[0]) == 0
    rng = np.random.default_rng(1)
    decoder = Evt3Decoder(640, 480, backend=backend)
    for _ in range(20):
        events, triggers = decoder.decode(rng.integers(0, 256, int(rng.integers(0, 5000)), dtype=np.uint8).tobytes())
        assert np.all(events["x"] < 640) and np.all(events["y"] < 480)
        assert np.all(events["t"] >= 0) and np.all(triggers["t"] >= 0)
    decoder.finish()
    assert decoder.stats.words > 0


@settings(max_examples=80, deadline=None)
@given(cuts=st.lists(st.integers(0, 80), max_size=12), seed=st.integers(0, 2**16))
def test_chunked_decode_equals_whole_decode_on_random_words(cuts: list[int], seed: int) -> None:
    rng = np.random.default_rng(seed)
    kinds = rng.choice([TH, TL, Y, X, BASE, V12, V8, TRIG, OTHERS, CONT12], size=40)
    payload = rng.integers(0, 4096, size=40)
    # TIME_HIGH as a walk with repeats, steps, small steps back (non-monotonic) and wraps
    steps = rng.choice([0, 0, 1, 1, 3, -1, -40, -3000, 2500], size=int(np.sum(kinds == TH)))
    payload[kinds == TH] = (rng.integers(0, 4096) + np.cumsum(steps)) % 4096
    data = pack(*((kinds << 12) | payload).tolist())
    whole, whole_trig = decode_evt3(data, 640, 480, backend="numpy")
    for other in ("numba",) if HAVE_NUMBA else ():
        numpy_decoder, jit_decoder = Evt3Decoder(640, 480, backend="numpy"), Evt3Decoder(640, 480, backend=other)
        ev_np, tr_np = numpy_decoder.decode(data)
        ev_jit, tr_jit = jit_decoder.decode(data)
        assert np.array_equal(ev_jit, ev_np) and np.array_equal(tr_jit, tr_np)
        assert jit_decoder.stats == numpy_decoder.stats
    decoder = Evt3Decoder(640, 480, backend=CHUNKED_BACKEND)
    bounds = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    parts = [decoder.decode(data[a:b]) for a, b in zip(bounds, bounds[1:])]
    decoder.finish()
    assert np.array_equal(np.concatenate([whole[:0]] + [p[0] for p in parts]), whole)
    assert np.array_equal(np.concatenate([whole_trig[:0]] + [p[1] for p in parts]), whole_trig)


# --- encoder -------------------------------------------------------------------------------------


def random_stream(seed: int, n: int, t0: int, max_gap: int, run_share: float, width: int = 1280) -> np.ndarray:
    """Sorted events with bursts: runs on one row (vectors), repeated times, idle gaps."""
    rng = np.random.default_rng(seed)
    gaps = rng.integers(0, max_gap + 1, n) * (rng.random(n) < 0.3)
    gaps[:1] = 0  # the stream starts at t0
    t = t0 + np.cumsum(gaps)
    x = rng.integers(0, width, n)
    y = rng.integers(0, 720, n)
    p = rng.integers(0, 2, n)
    in_run = np.flatnonzero(rng.random(n) < run_share)[:-1]
    in_run = in_run[in_run > 0]
    t[in_run] = t[in_run - 1]  # same time, row, polarity, next column: the makings of a vector
    for i in in_run:
        y[i], p[i], x[i] = y[i - 1], p[i - 1], min(x[i - 1] + 1 + rng.integers(0, 3), width - 1)
    t = np.maximum.accumulate(t)
    return make_events(x, y, p, t)


def random_triggers(seed: int, events: np.ndarray, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed + 1)
    triggers = np.zeros(n, dtype=TRIGGER_DTYPE)
    if len(events):
        triggers["t"] = np.sort(rng.integers(int(events["t"][0]), int(events["t"][-1]) + 1, n))
    triggers["p"], triggers["id"] = rng.integers(0, 2, n), rng.integers(0, 16, n)
    return triggers


# a random stream of events and triggers (``random_stream``, ``random_triggers``)
STREAMS = {
    "seed": st.integers(0, 2**32 - 1),
    "n": st.integers(0, 400),
    "t0": st.one_of(st.integers(0, (1 << 24) - 1), st.integers((1 << 24) - 20_000, (1 << 24) - 1)),
    "max_gap": st.sampled_from([0, 3, 50, 2000, 30_000]),
    "run_share": st.floats(0, 0.95),
    "n_triggers": st.integers(0, 5),
}


@settings(max_examples=60, deadline=None)
@given(**STREAMS, cuts=st.lists(st.integers(0, 10_000), max_size=8))
def test_encode_then_decode_round_trips_in_any_chunking(
    seed: int, n: int, t0: int, max_gap: int, run_share: float, n_triggers: int, cuts: list[int]
) -> None:
    events = random_stream(seed, n, t0, max_gap, run_share)
    triggers = random_triggers(seed, events, n_triggers if n else 0)
    data = encode_evt3(events, triggers)
    decoded, decoded_triggers = decode_evt3(data)
    np.testing.assert_array_equal(decoded, events)
    np.testing.assert_array_equal(decoded_triggers, triggers)
    decoder = Evt3Decoder()
    bounds = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    parts = [decoder.decode(data[a:b]) for a, b in zip(bounds, bounds[1:])]
    np.testing.assert_array_equal(np.concatenate([events[:0]] + [p[0] for p in parts]), events)


@settings(max_examples=80, deadline=None)
@given(**STREAMS, per_part=st.integers(1, 60), rows=st.sampled_from([1, 3, 720]))
def test_the_encoding_in_parts_joins_to_the_whole(
    seed: int, n: int, t0: int, max_gap: int, run_share: float, n_triggers: int, per_part: int, rows: int
) -> None:
    """A writer streams a long recording part by part; the parts carry the row whose EVT_ADDR_Y
    holds and the next TIME_HIGH across, so joined they are the one-part stream byte for byte
    (few rows: a part often starts on the row the last one ended on)."""
    from darkread.edge.io.evt3_encode import encode_evt3_parts

    events = random_stream(seed, n, t0, max_gap, run_share)
    events["y"] %= rows
    triggers = random_triggers(seed, events, n_triggers if n else 0)
    whole = encode_evt3(events, triggers)
    parts = list(encode_evt3_parts(events, triggers, events_per_part=per_part))
    assert b"".join(parts) == whole
    if len(events) and not len(triggers):  # one event a part: a part per distinct time (a time is never split)
        assert len(list(encode_evt3_parts(events, events_per_part=1))) == len(np.unique(events["t"]))


def test_encoder_writes_the_stream_like_a_sensor() -> None:
    events = make_events([64, 65, 95, 96, 100, 7], 3, 1, [10, 10, 10, 10, 10, 40])
    words = np.frombuffer(encode_evt3(events, time_high_period_us=16), dtype="<u2")
    kinds = list(words >> 12)
    # TIME_HIGH at 0; TIME_LOW 10; ADDR_Y 3; group 64..95 with base; continuation 96..127 without base;
    # TIME_HIGH at 16 and 32 (repeats); TIME_LOW 40; single ADDR_X
    assert kinds == [TH, TL, Y, BASE, V12, V12, V8, V12, V12, V8, TH, TH, TL, X]
    assert words[3] & 0x7FF == 64 and words[3] >> 11 & 1 == 1
    assert list(words[4:7] & 0xFFF) == [0b11, 0, 0x80]
    assert list(words[7:10] & 0xFFF) == [0b10001, 0, 0]


def test_encoder_re_sends_time_high_while_idle_and_across_the_wrap() -> None:
    start = (1 << 24) - 100
    events = make_events([1, 2], 0, 0, [start, start + 200])
    words = np.frombuffer(encode_evt3(events), dtype="<u2")
    highs = words[(words >> 12) == TH] & 0xFFF
    assert len(highs) == len(range(start // 16 * 16, start + 201, 16))
    assert list(np.unique(highs)) == [0, 4095]
    assert list(decode_evt3(encode_evt3(events))[0]["t"]) == [start, start + 200]


@pytest.mark.parametrize(
    ("events", "kw", "message"),
    [
        (make_events(0, 0, 0, [5, 4]), {}, "non-decreasing"),
        (make_events(0, 0, 0, [-1]), {}, "non-negative"),
        (make_events(640, 0, 0, [1]), {"width": 640}, "width"),
        (make_events(0, 0, 2, [1]), {}, "polarity"),
        (make_events(0, 0, 0, [1]), {"time_high_period_us": 3}, "divide 4096"),
    ],
)
def test_encoder_rejects_what_evt3_cannot_carry(events: np.ndarray, kw: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        encode_evt3(events, **kw)


def test_encoding_nothing_gives_no_bytes() -> None:
    assert encode_evt3(empty_events()) == b""


def test_write_raw_then_read_raw(tmp_path: Path) -> None:
    events = random_stream(7, 3000, 5_000_000, 50, 0.5, width=640)
    events["y"] %= 480
    triggers = random_triggers(7, events, 3)
    path = tmp_path / "out.raw"
    size = write_raw(path, events, width=640, height=480, triggers=triggers, header_extra={"serial_number": "ab12"})
    assert size == path.stat().st_size
    raw = read_raw(path)
    assert (raw.header.width, raw.header.height, raw.header.fields["serial_number"]) == (640, 480, "ab12")
    np.testing.assert_array_equal(raw.events, events)
    np.testing.assert_array_equal(raw.triggers, triggers)


def test_backend_choice() -> None:
    with pytest.raises(ValueError, match="backend"):
        Evt3Decoder(backend="fortran")
    assert Evt3Decoder(backend="numpy").backend == "numpy"
    assert Evt3Decoder().backend == ("numba" if HAVE_NUMBA else "numpy")
    with pytest.raises(ValueError, match="sensor size"):
        Evt3Decoder(0, 720)


def test_warm_up_decodes_its_own_words() -> None:
    from darkread.edge.io.evt3 import _WARM_UP_WORDS, warm_up

    events, triggers = decode_evt3(_WARM_UP_WORDS)
    assert events[["x", "y", "p", "t"]].tolist() == [(10, 5, 0, 4096)] and len(triggers) == 0
    warm_up()  # compiles or loads the cached decoder; must not raise


# --- the sensor's ROI ----------------------------------------------------------------------------


def test_roi_delivers_the_events_inside_and_counts_the_words_skipped(backend: str) -> None:
    # row 10 (outside the ROI's rows 20..29): a single event and a vector, skipped unread;
    # row 20: x=3 (left of the columns 8..19) skipped, x=8 kept; a vector from 4 straddling the left
    # edge keeps its columns 8..15, the next (16..27) its 16..19
    data = pack(w(TH, 1), w(TL, 2), w(Y, 10), w(X, 9), w(BASE, 8), w(V12, 0xFFF),
                w(Y, 20), w(X, 3), w(X, 8), w(BASE, 4), w(V12, 0xFFF), w(V12, 0xFFF), w(V8, 0xFF))
    decoder = Evt3Decoder(64, 64, backend=backend)
    decoder.set_roi((8, 20, 12, 10))
    events, _ = decoder.decode(data)
    assert [e[:2] for e in columns(events)] == [(8, 20)] + [(x, 20) for x in range(8, 20)]
    assert decoder.stats.events == len(events)
    assert decoder.stats.words_outside_roi == 4  # row 10's two, x=3, and the VECT_8 at 28..35


def test_roi_decode_equals_a_crop_of_the_whole_decode_in_any_chunking(backend: str) -> None:
    events = random_stream(5, 20_000, 1 << 20, 40, 0.5)
    data = encode_evt3(events)
    roi = (300, 200, 264, 204)
    decoder = Evt3Decoder(backend=backend)
    decoder.set_roi(roi)
    parts = [decoder.decode(data[i : i + 777])[0] for i in range(0, len(data), 777)]
    x0, y0, w_, h = roi
    inside = (events["x"] >= x0) & (events["x"] < x0 + w_) & (events["y"] >= y0) & (events["y"] < y0 + h)
    assert np.array_equal(np.concatenate(parts), events[inside])
    assert decoder.stats.events == int(inside.sum()) and decoder.stats.words_outside_roi > 0
    decoder.set_roi((0, 0, 1280, 720))  # the whole sensor: no ROI
    assert decoder.roi is None
    with pytest.raises(ValueError):
        decoder.set_roi((0, 0, 0, 10))


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed")
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**16), x0=st.integers(0, 600), y0=st.integers(0, 470), w_=st.integers(1, 200), h=st.integers(1, 60))
def test_both_backends_skip_the_same_words(seed: int, x0: int, y0: int, w_: int, h: int) -> None:
    rng = np.random.default_rng(seed)
    kinds = rng.choice([TH, TL, Y, X, BASE, V12, V8, TRIG, OTHERS], size=60)
    payload = rng.integers(0, 4096, size=60)
    payload[kinds == TH] = np.sort(rng.integers(0, 4096, size=int(np.sum(kinds == TH))))
    data = pack(*((kinds << 12) | payload).tolist())
    decoders = [Evt3Decoder(640, 480, backend=b) for b in ("numpy", "numba")]
    outputs = []
    for decoder in decoders:
        decoder.set_roi((x0, y0, w_, h))
        outputs.append(decoder.decode(data))
    assert np.array_equal(outputs[0][0], outputs[1][0]) and np.array_equal(outputs[0][1], outputs[1][1])
    assert decoders[0].stats == decoders[1].stats


def test_a_readers_roi_is_in_effect_from_the_first_event_decoded_after_it(tmp_path: Path) -> None:
    """Events decoded before ``set_roi`` are still delivered (in flight, as a camera's are): the reader
    says from which event on the new ROI holds."""
    events = random_stream(7, 20_000, 1 << 20, 40, 0.5)
    path = tmp_path / "r.raw"
    write_raw(path, events)
    reader = RawReader(path, chunk_bytes=4096)
    chunks = iter(reader)
    first = next(chunks)
    assert reader.roi_since_us == int(first["t"][0])  # the whole sensor, from the start
    reader.set_roi((300, 200, 264, 204))
    assert reader.roi_since_us is None  # written, nothing decoded under it yet
    second = next(chunks)
    assert reader.roi_since_us == int(second["t"][0]) > int(first["t"][-1]) - 1
    assert ((second["x"] >= 300) & (second["x"] < 564) & (second["y"] >= 200) & (second["y"] < 404)).all()
