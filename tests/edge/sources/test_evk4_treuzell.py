from __future__ import annotations

import errno
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from darkread.edge.errors import DeviceError
from darkread.edge.sources.evk4 import treuzell as tz


def words(data: bytes) -> list[int]:
    return list(struct.unpack(f"<{len(data) // 4}I", data))


def test_register_write_frame_is_the_documented_five_words() -> None:
    assert words(tz.encode_register_write(0x1010, 0x11A10066)) == [0x40010102, 12, 0, 0x1010, 0x11A10066]


def test_register_read_frame_asks_for_one_value() -> None:
    assert words(tz.encode_register_read(0x14)) == [0x00010102, 12, 0, 0x14, 1]


@given(st.integers(0, 0xFFFFFFFF), st.binary(max_size=64))
def test_frames_round_trip(prop: int, payload: bytes) -> None:
    frame = tz.decode_packet(tz.encode_packet(prop, payload))
    assert (frame.prop, frame.payload) == (prop, payload)


def test_reply_with_value_at_word_four() -> None:
    reply = tz.check_reply(0x10102, tz.encode_words(0x10102, 0, 0x14, 0xA0401806))
    tz.check_register_reply(reply, 0x14)
    assert reply.word(2) == 0xA0401806


def test_failure_flag_raises_with_errno() -> None:
    answer = tz.encode_words(0x40010102 | tz.FAILURE_FLAG, 0, 0x1010, errno.EIO)
    with pytest.raises(tz.CommandFailedError) as info:
        tz.check_reply(0x40010102, answer)
    assert info.value.errno == errno.EIO
    assert isinstance(info.value, DeviceError)
    assert "EIO" in str(info.value)


@pytest.mark.parametrize(
    ("answer", "message"),
    [
        (tz.encode_packet(tz.UNKNOWN_COMMAND), "does not implement"),
        (tz.encode_words(0x79, 1), "answered property"),
        (b"\x01\x00", "shorter than a frame header"),
        (struct.pack("<III", 0x72, 8, 5), "says 8 payload bytes but carries 4"),
    ],
)
def test_malformed_replies_raise(answer: bytes, message: str) -> None:
    with pytest.raises(tz.TreuzellError, match=message):
        tz.check_reply(0x72, answer)


def test_register_reply_for_another_address_is_rejected() -> None:
    reply = tz.decode_packet(tz.encode_words(0x10102, 0, 0x18, 5))
    with pytest.raises(tz.TreuzellError, match="expected device 0 address 0x0014"):
        tz.check_register_reply(reply, 0x14)


def test_short_payload_word_access_raises() -> None:
    with pytest.raises(tz.TreuzellError, match="need 12"):
        tz.decode_packet(tz.encode_words(0x10102, 0, 0x14)).word(2)


def test_version_format() -> None:
    assert tz.format_version(0x030800) == "3.8.0"
