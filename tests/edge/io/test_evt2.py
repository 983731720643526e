"""EVT 2.0 decoder: word layout, 34-bit time, chunking, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.errors import CorruptRawError
from darkread.edge.io.evt2 import Evt2Decoder, decode_evt2


def cd(on: int, ts6: int, x: int, y: int) -> int:
    return (on << 28) | (ts6 << 22) | (x << 11) | y


def high(value: int) -> int:
    return (0x8 << 28) | value


def trigger(ts6: int, channel: int, edge: int) -> int:
    return (0xA << 28) | (ts6 << 22) | (channel << 8) | edge


def pack(*words: int) -> bytes:
    return np.array(words, dtype="<u4").tobytes()


def test_cd_events_combine_time_high_and_low_bits() -> None:
    events, triggers = decode_evt2(pack(high(100), cd(1, 5, 639, 479), cd(0, 63, 0, 0), high(101), cd(1, 0, 7, 8)))
    assert [tuple(int(v) for v in e) for e in events] == [
        (639, 479, 1, 100 * 64 + 5),
        (0, 0, 0, 100 * 64 + 63),
        (7, 8, 1, 101 * 64),
    ]
    assert len(triggers) == 0


def test_time_uses_all_34_bits() -> None:
    top = (1 << 28) - 1
    events, _ = decode_evt2(pack(high(top), cd(0, 63, 1, 1)))
    assert int(events["t"][0]) == (1 << 34) - 1


def test_triggers_others_and_words_before_time_high() -> None:
    decoder = Evt2Decoder(640, 480)
    data = pack(
        cd(1, 0, 1, 1), high(2), trigger(3, 6, 1), (0xE << 28) | 5, (0xF << 28), cd(0, 1, 2, 2), trigger(4, 31, 0)
    )
    events, triggers = decoder.decode(data)
    assert [tuple(int(v) for v in e) for e in events] == [(2, 2, 0, 129)]
    assert [(int(t["p"]), int(t["id"]), int(t["t"])) for t in triggers] == [(1, 6, 131), (0, 31, 132)]
    assert decoder.stats.skipped_before_time_high == 1
    assert decoder.stats.skipped_other == 2
    assert (decoder.stats.events, decoder.stats.triggers, decoder.stats.words) == (1, 2, 7)


def test_step_back_in_time_drops_events_until_recovered() -> None:
    decoder = Evt2Decoder()
    events, _ = decoder.decode(pack(high(10), cd(1, 0, 1, 1), high(9), cd(1, 0, 2, 2), high(10), cd(1, 1, 3, 3)))
    assert list(events["x"]) == [1, 3]
    assert decoder.stats.non_monotonic_time_high == 1
    assert decoder.stats.dropped_non_monotonic == 1


def test_outside_sensor_dropped_and_y_range_and_time_shift() -> None:
    decoder = Evt2Decoder(640, 480, y_range=(10, 20), time_shift=True)
    events, _ = decoder.decode(pack(high(50), cd(1, 1, 640, 15), cd(1, 2, 5, 15), cd(1, 3, 5, 25), cd(1, 4, 5, 480)))
    assert [(int(e["x"]), int(e["y"]), int(e["t"])) for e in events] == [(5, 15, 2)]
    assert decoder.stats.events_out_of_range == 2


def test_partial_word_at_end_is_counted_or_raises_when_strict() -> None:
    data = pack(high(1), cd(1, 0, 1, 1)) + b"\x01\x02\x03"
    decoder = Evt2Decoder(path="cut.raw", byte_offset=10)
    assert len(decoder.decode(data)[0]) == 1
    decoder.finish()
    assert decoder.stats.trailing_bytes == 3
    strict = Evt2Decoder(path="cut.raw", byte_offset=10, strict=True)
    strict.decode(data)
    with pytest.raises(CorruptRawError, match=r"cut\.raw at byte 18"):
        strict.finish()


def test_garbage_never_escapes_the_sensor() -> None:
    rng = np.random.default_rng(5)
    decoder = Evt2Decoder(640, 480)
    events, triggers = decoder.decode(rng.integers(0, 256, 40_001, dtype=np.uint8).tobytes())
    decoder.finish()
    assert np.all(events["x"] < 640) and np.all(events["y"] < 480) and np.all(events["t"] >= 0)
    assert np.all(triggers["t"] >= 0)


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**16), cuts=st.lists(st.integers(0, 400), max_size=10))
def test_chunked_decode_equals_whole_decode(seed: int, cuts: list[int]) -> None:
    rng = np.random.default_rng(seed)
    kinds = rng.choice([0x0, 0x1, 0x8, 0xA, 0xE, 0xF], size=100, p=[0.3, 0.3, 0.2, 0.1, 0.05, 0.05])
    payload = rng.integers(0, 1 << 28, size=100)
    payload[kinds == 0x8] = np.sort(rng.integers(0, 1 << 20, int(np.sum(kinds == 0x8))))
    n_cd = int(np.sum(kinds <= 1))  # mostly inside a 640x480 sensor, some outside
    payload[kinds <= 1] = (
        (rng.integers(0, 64, n_cd) << 22) | (rng.integers(0, 700, n_cd) << 11) | rng.integers(0, 500, n_cd)
    )
    data = pack(*((kinds.astype(np.int64) << 28) | payload).tolist())
    whole, whole_triggers = decode_evt2(data)
    decoder = Evt2Decoder()
    bounds = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    parts = [decoder.decode(data[a:b]) for a, b in zip(bounds, bounds[1:])]
    np.testing.assert_array_equal(np.concatenate([whole[:0]] + [p[0] for p in parts]), whole)
    np.testing.assert_array_equal(np.concatenate([whole_triggers[:0]] + [p[1] for p in parts]), whole_triggers)
    assert decoder.stats.events == len(whole)
