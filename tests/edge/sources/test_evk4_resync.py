from __future__ import annotations

import numpy as np
from factories import random_events
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.io.evt3 import Evt3Decoder, encode_evt3
from darkread.edge.sources.evk4.resync import ChunkAligner

EVENTS = random_events(3000, t0=(1 << 24) - 300, rate_hz=3e6, seed=7)  # crosses the 2^24 µs wrap
STREAM = encode_evt3(EVENTS)


def decode(data: bytes) -> np.ndarray:
    return Evt3Decoder(width=1280, height=720).decode(data)[0]


def split(data: bytes, cuts: list[int]) -> list[tuple[int, bytes]]:
    bounds = [0, *sorted(set(cuts)), len(data)]
    return [(a, data[a:b]) for a, b in zip(bounds, bounds[1:]) if b > a]


@given(st.lists(st.integers(1, len(STREAM) - 1), max_size=20))
@settings(max_examples=50, deadline=None)
def test_contiguous_chunks_pass_through_as_whole_words(cuts: list[int]) -> None:
    aligner = ChunkAligner()
    out = b"".join(aligner.push(offset, data) for offset, data in split(STREAM, cuts))
    assert out == STREAM[: len(STREAM) // 2 * 2] and aligner.gaps == 0


@given(st.integers(0, len(STREAM) // 2), st.integers(1, 4000), st.sampled_from([97, 333, 4096]))
@settings(max_examples=30, deadline=None)
def test_after_a_gap_every_event_decoded_is_exact(lost_from: int, lost_bytes: int, piece: int) -> None:
    resume = min(lost_from + lost_bytes, len(STREAM))
    aligner = ChunkAligner()
    decoder = Evt3Decoder(width=1280, height=720)
    before = decoder.decode(aligner.push(0, STREAM[:lost_from]))[0]
    pieces = split(STREAM[resume:], list(range(piece, len(STREAM) - resume, piece)))
    after_parts = [decoder.decode(aligner.push(resume + o, d))[0] for o, d in pieces]
    assert aligner.gaps == (1 if pieces else 0)
    after = np.concatenate(after_parts) if after_parts else EVENTS[:0]
    np.testing.assert_array_equal(before, decode(STREAM[: lost_from // 2 * 2]))
    if len(after):
        expected = EVENTS[len(EVENTS) - len(after) :].copy()  # an exact suffix ...
        seen = np.frombuffer(STREAM[: lost_from // 2 * 2], "<u2")
        if not np.any(seen >> 12 == 8):  # ... counting the stream's 2^24 us time loops once a TIME_HIGH came before
            # the gap; a decoder whose first TIME_HIGH follows it starts as on a stream joined there, at loop 0
            expected["t"] -= (int(expected["t"][0]) >> 24) << 24
        np.testing.assert_array_equal(after, expected)


def test_resync_finds_the_restart_point_across_tiny_chunks() -> None:
    lost_from, resume = 1001, 5003
    aligner = ChunkAligner()
    decoder = Evt3Decoder(width=1280, height=720)
    decoder.decode(aligner.push(0, STREAM[:lost_from]))
    tiny = range(resume, resume + 300, 3)
    parts = [decoder.decode(aligner.push(o, STREAM[o : o + 3]))[0] for o in tiny]
    parts.append(decoder.decode(aligner.push(tiny[-1] + 3, STREAM[tiny[-1] + 3 :]))[0])
    after = np.concatenate(parts)
    assert aligner.gaps == 1 and 0 < aligner.skipped_bytes < 200
    assert len(after) > len(EVENTS) // 2
    np.testing.assert_array_equal(after, EVENTS[len(EVENTS) - len(after) :])
    assert after["t"].max() > 1 << 24  # the kept decoder still unrolls the wrap
