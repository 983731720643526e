"""Protocol versions 2 and 3: compressed masks, the fused view, the G4 page; golden fixtures
(valid, truncated, hostile) in ``fixtures/`` and property tests of the codecs."""

from __future__ import annotations

from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from darkread.core.mask_bits import pack_bits, packed_length
from darkread.proto.codecs import (
    LEVEL_ENCODINGS,
    MASK_ENCODINGS,
    compress_bits,
    compress_levels,
    decompress_bits,
    decompress_levels,
    g4_tiff,
)
from darkread.proto.errors import BadMaskError, CloseCode, InvalidFieldError, ProtocolError
from darkread.proto.messages import Frame, Hello, Page, View, content_version, decode, encode, pack_mask

FIXTURES = Path(__file__).parent / "fixtures"
LIMIT = 1 << 20
SMALL_BITS = bytes([0x03, 0x88, 0x00])  # the 4 x 5 mask of test_messages.py
LEVELS = bytes([0, 0, 0, 0, 0, 0, 3, 3, 2, 0, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0])
GAZE = {"origin": (540, 310), "gaze_px": (640.5, 360.25), "gaze_rad": (0.125, -0.0625)}

VALID = {
    "v2_hello": Hello(device_id="glasses-01", session_id="s-0001", mode="frames", sensor=(1280, 720),
                      fovea=(100, 200), token="k", resume_from_seq=7, v=2),
    "v2_frame_zlib": Frame(seq=8, frame_id=42, t_us=1234567, events_used=1600, shape=(4, 5), bits=SMALL_BITS,
                           enc="zlib", **GAZE),
    "v2_page_png": Page(seq=9, page_id=1, t_us=2000000, shape=(4, 5), bits=SMALL_BITS, lines=((1, 1, 4, 3),), enc="png"),
    "v2_view_png": View(seq=11, view_id=3, t0_us=1000000, t_us=1200000, frames=3, events_used=4800, shape=(4, 5),
                        n_levels=4, levels=LEVELS, enc="png", **GAZE),
    "v2_view_zlib": View(seq=12, view_id=4, t0_us=1000000, t_us=1200000, frames=3, events_used=4800, shape=(4, 5),
                         n_levels=4, levels=LEVELS, enc="zlib", **GAZE),
    "v3_page_g4": Page(seq=10, page_id=2, t_us=2000000, shape=(4, 5), bits=SMALL_BITS, lines=((1, 1, 4, 3),), enc="g4"),
    # version 4: a view may be larger than the fovea (the union of its frames' windows; the
    # session checks its shape against hello.fovea, the message decodes as in version 2)
    "v4_hello": Hello(device_id="glasses-01", session_id="s-0002", mode="frames", sensor=(1280, 720),
                      fovea=(4, 5), token="k", v=4),
    "v4_view_wide_zlib": View(seq=13, view_id=5, t0_us=1000000, t_us=1200000, frames=2, events_used=3200, shape=(6, 5),
                              n_levels=4, levels=LEVELS + bytes([0, 2, 3, 2, 0, 0, 0, 1, 0, 0]), enc="zlib", **GAZE),
}
# zlib output is fixed for a given input and level; PNG bytes may differ between libpng builds,
# so those fixtures are checked by decoding (and re-encoding round trips), not byte for byte
# T.6 fixes every code of a G4 stream (libtiff ends it with EOFB), so the G4 page is byte exact too
BYTE_EXACT = {"v2_hello", "v2_frame_zlib", "v2_view_zlib", "v3_page_g4", "v4_hello", "v4_view_wide_zlib"}
HOSTILE = {
    "hostile_frame_zlib_bomb": BadMaskError,  # 16 MiB of zeros declared as a 4 x 5 mask
    "hostile_frame_zlib_trailing": BadMaskError,
    "hostile_page_png_huge_header": BadMaskError,  # IHDR claims 60000 x 60000
    "hostile_view_level_range": BadMaskError,
    "hostile_view_unknown_enc": InvalidFieldError,
    "hostile_view_png_colour": BadMaskError,
    "hostile_page_g4_cut": BadMaskError,  # the stream's last two bytes (its end-of-block code) cut off
    "hostile_page_g4_huge_shape": BadMaskError,  # a 44-byte stream declared as 65535 x 65535: refused before decoding
    "hostile_page_g4_not_g4": BadMaskError,  # zero bytes (no valid code) before a real stream
    "hostile_frame_g4": InvalidFieldError,  # G4 is for pages only
}


def fixture(name: str) -> bytes:
    return (FIXTURES / f"{name}.msgpack").read_bytes()


def test_fixtures_are_all_tested() -> None:
    assert {p.stem for p in FIXTURES.glob("*.msgpack")} == set(VALID) | set(HOSTILE)


@pytest.mark.parametrize("name", sorted(VALID))
def test_valid_fixtures_decode_to_the_examples(name: str) -> None:
    assert decode(fixture(name), max_bytes=LIMIT) == VALID[name]
    assert decode(encode(VALID[name]), max_bytes=LIMIT) == VALID[name]
    if name in BYTE_EXACT:
        assert encode(VALID[name]) == fixture(name)


@pytest.mark.parametrize("name", sorted(VALID))
def test_every_truncation_of_a_valid_fixture_is_a_protocol_error(name: str) -> None:
    data = fixture(name)
    for end in range(len(data)):
        with pytest.raises(ProtocolError):
            decode(data[:end], max_bytes=LIMIT)


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_fixtures_are_refused(name: str) -> None:
    with pytest.raises(HOSTILE[name]):
        decode(fixture(name), max_bytes=LIMIT)


def test_the_view_decodes_to_its_levels_and_a_thresholded_frame() -> None:
    view = decode(fixture("v2_view_png"), max_bytes=LIMIT)
    assert isinstance(view, View)
    np.testing.assert_array_equal(view.ink(), np.frombuffer(LEVELS, np.uint8).reshape(4, 5))
    frame = view.as_frame()  # ink where the level is at least half: 2 and 3 of 0..3
    assert frame.seq == view.seq and frame.enc == "bits"
    np.testing.assert_array_equal(frame.mask(), (np.frombuffer(LEVELS, np.uint8).reshape(4, 5) >= 2).astype(np.uint8))


def test_compressed_frames_carry_the_same_mask_as_v1() -> None:
    frame = decode(fixture("v2_frame_zlib"), max_bytes=LIMIT)
    assert frame.bits == SMALL_BITS and msgpack.unpackb(fixture("v2_frame_zlib"))["bits"] != SMALL_BITS


def test_a_v1_frame_has_no_enc_on_the_wire() -> None:
    frame = Frame(seq=1, frame_id=1, t_us=0, events_used=0, shape=(4, 5), bits=SMALL_BITS, **GAZE)
    assert "enc" not in msgpack.unpackb(encode(frame))


def test_a_text_like_mask_compresses_well() -> None:
    mask = np.zeros((100, 200), np.uint8)
    mask[30:40, 10:190:6] = 1  # strokes of a line of text
    mask[30:32, 10:190] = 1
    shape, bits = pack_mask(mask)
    assert len(compress_bits(shape, bits, "zlib")) < len(bits) / 5
    assert len(compress_bits(shape, bits, "png")) < len(bits) / 3


def test_a_g4_page_is_version_3_content_and_the_smallest_of_a_text_like_page() -> None:
    import cv2

    mask = np.zeros((200, 400), np.uint8)
    for i, line in enumerate(("the quick brown fox jumps", "over the lazy dog, then", "reads a page in the dark")):
        cv2.putText(mask, line, (20, 60 + 30 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.7, 1, 1)  # text, not a pattern
    shape, bits = pack_mask(mask)
    sizes = {enc: len(compress_bits(shape, bits, enc)) for enc in MASK_ENCODINGS}
    assert sizes["g4"] == min(sizes.values()), sizes
    page = Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits, enc="g4")
    assert content_version(page) == 3 and content_version(Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits)) == 1
    assert content_version(Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits, enc="png")) == 2


def test_every_cut_of_a_g4_stream_is_refused() -> None:
    mask = np.zeros((40, 120), np.uint8)
    mask[10:30, 5:115:4] = 1
    shape, bits = pack_mask(mask)
    stream = compress_bits(shape, bits, "g4")
    for end in range(len(stream)):
        with pytest.raises(BadMaskError):
            decompress_bits(shape, stream[:end], "g4")


def test_the_g4_decoder_takes_the_size_from_the_message_not_the_stream() -> None:
    stream = compress_bits((4, 5), SMALL_BITS, "g4")
    tiff = g4_tiff((4, 5), stream)
    assert tiff.startswith(b"II*\0") and stream in tiff
    wider = decompress_bits((4, 9), stream, "g4")  # the same stream under another shape: that shape, whatever it says
    assert len(wider) == packed_length((4, 9)) and wider != SMALL_BITS


# --- property tests of the codecs -----------------------------------------------------------------

masks = hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=48), elements=st.integers(0, 1))


@settings(deadline=None)
@given(masks, st.sampled_from(MASK_ENCODINGS))
def test_masks_round_trip_through_every_encoding(mask: np.ndarray, enc: str) -> None:
    shape, bits = pack_mask(mask)
    assert decompress_bits(shape, compress_bits(shape, bits, enc), enc) == bits


@settings(deadline=None)
@given(
    hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=48), elements=st.integers(0, 15)),
    st.sampled_from(LEVEL_ENCODINGS),
)
def test_levels_round_trip_through_every_encoding(levels: np.ndarray, enc: str) -> None:
    shape = levels.shape
    data = levels.tobytes()
    assert decompress_levels(shape, compress_levels(shape, data, enc), enc) == data


@settings(deadline=None)
@given(masks, st.sampled_from(("zlib", "png", "g4")), st.sampled_from((None, 1, 2, 3)),
       st.none() | st.floats(min_value=1e-3, max_value=1e6))
def test_views_and_frames_round_trip_as_messages(mask: np.ndarray, enc: str, shed_level: int | None, light_lux: float | None) -> None:
    shape, bits = pack_mask(mask)
    frame = Frame(seq=1, frame_id=2, t_us=3, events_used=4, shape=shape, bits=bits, enc="zlib", light_lux=light_lux, **GAZE)
    page = Page(seq=1, page_id=2, t_us=3, shape=shape, bits=bits, enc=enc)
    view = View(seq=1, view_id=2, t0_us=0, t_us=3, frames=1, events_used=4, shape=shape, n_levels=2,
                levels=mask.tobytes(), enc="png" if enc == "png" else "zlib", shed_level=shed_level, light_lux=light_lux,
                **GAZE)
    for message in (frame, page, view):
        assert decode(encode(message), max_bytes=LIMIT) == message
    np.testing.assert_array_equal(decode(encode(view), max_bytes=LIMIT).as_frame().mask(), mask)


@settings(max_examples=200, deadline=None)  # PNG decoding on a shared machine
@given(st.sampled_from(sorted(VALID)), st.integers(0, 400), st.integers(0, 255))
def test_corrupted_fixtures_raise_only_protocol_errors(name: str, position: int, value: int) -> None:
    data = bytearray(fixture(name))
    data[position % len(data)] = value
    try:
        decode(bytes(data), max_bytes=LIMIT)
    except ProtocolError:
        pass


@settings(deadline=None)
@given(st.binary(max_size=200), st.sampled_from(MASK_ENCODINGS[1:]))
def test_random_compressed_bits_raise_only_bad_mask(data: bytes, enc: str) -> None:
    try:
        bits = decompress_bits((8, 8), data, enc)
    except BadMaskError as exc:
        assert exc.close_code == CloseCode.BAD_MASK
        return
    assert len(bits) == len(pack_bits(np.zeros((8, 8))))


def test_view_of_carries_a_fused_record_and_refuses_a_binary_one() -> None:
    from darkread.core.frame_record import FrameRecord

    levels = np.frombuffer(LEVELS, np.uint8).reshape(4, 5)
    record = FrameRecord(3, 1200000, (levels >= 2).astype(np.uint8), GAZE["origin"], GAZE["gaze_px"],
                         levels=levels, n_levels=4, frames=3)
    view = View.of(record, seq=11, t0_us=1000000, gaze_rad=GAZE["gaze_rad"], events_used=4800)
    assert view == VALID["v2_view_png"]
    with pytest.raises(BadMaskError, match="binary frame, not a view"):
        View.of(FrameRecord(3, 0, np.zeros((4, 5), np.uint8), (0, 0), (0.0, 0.0)))
