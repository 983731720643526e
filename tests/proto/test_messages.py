"""Wire protocol: round trips, golden bytes, property tests and hostile inputs."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from darkread.proto.errors import (
    BadMaskError,
    CloseCode,
    InvalidFieldError,
    MalformedMessageError,
    MessageTooLargeError,
    ProtocolError,
    UnknownMessageTypeError,
    VersionMismatchError,
)
from darkread.proto.messages import (
    MESSAGE_TYPES,
    PROTOCOL_VERSION,
    Ack,
    Error,
    Frame,
    Gaze,
    Heartbeat,
    Hello,
    NewPage,
    Page,
    View,
    Welcome,
    decode,
    encode,
    pack_mask,
    unpack_mask,
)

LIMIT = 1 << 20
# A 4 x 5 mask with a 3-pixel stroke in row 1 and one pixel in row 2: bits 00000 01110 00100 00000.
SMALL_MASK = np.array([[0, 0, 0, 0, 0], [0, 1, 1, 1, 0], [0, 0, 1, 0, 0], [0, 0, 0, 0, 0]], np.uint8)
SMALL_BITS = bytes([0x03, 0x88, 0x00])

EXAMPLES = {
    "hello": Hello(
        device_id="glasses-01",
        session_id="s-0001",
        mode="frames",
        sensor=(1280, 720),
        fovea=(100, 200),
        token="k",
        resume_from_seq=7,
        v=1,
    ),
    "welcome": Welcome(session_id="s-0001", last_acked_seq=-1, max_message_bytes=4194304, v=1),
    "frame": Frame(
        seq=8,
        frame_id=42,
        t_us=1234567,
        origin=(540, 310),
        gaze_px=(640.5, 360.25),
        gaze_rad=(0.125, -0.0625),
        events_used=1600,
        shape=(4, 5),
        bits=SMALL_BITS,
    ),
    "page": Page(seq=9, page_id=1, t_us=2000000, shape=(4, 5), bits=SMALL_BITS, lines=((1, 1, 4, 3),)),
    "new_page": NewPage(seq=11, t_us=3000000),
    "gaze": Gaze(seq=10, t_us=(1, 2), px=((1.5, 2.5), (3.0, 4.0))),
    "heartbeat": Heartbeat(t_us=5, stats={"fps": 30.0}),
    "ack": Ack(seq=10),
    "error": Error(code=4400, message="bad", fatal=True),
}

# Golden bytes: what version 1 puts on the wire. A change here is a protocol change.
GOLDEN = {
    "hello": "89a474797065a568656c6c6fa96465766963655f6964aa676c61737365732d3031aa73657373696f6e5f6964a6732d"
    "30303031a46d6f6465a66672616d6573a673656e736f7292cd0500cd02d0a5666f7665619264ccc8a5746f6b656ea1"
    "6baf726573756d655f66726f6d5f73657107a17601",
    "welcome": "85a474797065a777656c636f6d65aa73657373696f6e5f6964a6732d30303031ae6c6173745f61636b65645f73"
    "6571ffb16d61785f6d6573736167655f6279746573ce00400000a17601",
    "frame": "8aa474797065a56672616d65a373657108a86672616d655f69642aa4745f7573ce0012d687a66f726967696e92cd02"
    "1ccd0136a767617a655f707892cb4084040000000000cb4076840000000000a867617a655f72616492cb3fc0000000"
    "000000cbbfb0000000000000ab6576656e74735f75736564cd0640a57368617065920405a462697473c403038800",
    "page": "87a474797065a470616765a373657109a7706167655f696401a4745f7573ce001e8480a57368617065920405a46269"
    "7473c403038800a56c696e6573919401010403",
    "gaze": "84a474797065a467617a65a37365710aa4745f7573920102a270789292cb3ff8000000000000cb400400000000000092"
    "cb4008000000000000cb4010000000000000",
    "new_page": "83a474797065a86e65775f70616765a37365710ba4745f7573ce002dc6c0",
    "heartbeat": "83a474797065a9686561727462656174a4745f757305a5737461747381a3667073cb403e000000000000",
    "ack": "82a474797065a361636ba37365710a",
    "error": "84a474797065a56572726f72a4636f6465cd1130a76d657373616765a3626164a5666174616cc3",
}


def test_examples_cover_every_message_type() -> None:
    assert set(EXAMPLES) == set(GOLDEN) == set(MESSAGE_TYPES) - {"view"}  # view: version 2, tests/proto/test_codecs.py


def test_welcome_features_are_optional_both_ways() -> None:
    """A server that lists no features sends version-1 bytes unchanged; one that does is understood."""
    listed = Welcome(session_id="s-0001", last_acked_seq=-1, max_message_bytes=4194304, features=("new_page",))
    assert decode(encode(listed), max_bytes=LIMIT).features == ("new_page",)
    assert decode(bytes.fromhex(GOLDEN["welcome"]), max_bytes=LIMIT).features is None


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_round_trip(kind: str) -> None:
    message = EXAMPLES[kind]
    assert decode(encode(message), max_bytes=LIMIT) == message


@pytest.mark.parametrize("kind", sorted(GOLDEN))
def test_golden_bytes(kind: str) -> None:
    golden = bytes.fromhex(GOLDEN[kind])
    assert encode(EXAMPLES[kind]) == golden
    assert decode(golden, max_bytes=LIMIT) == EXAMPLES[kind]


@pytest.mark.parametrize("kind", sorted(GOLDEN))
def test_every_truncation_of_golden_bytes_is_a_protocol_error(kind: str) -> None:
    golden = bytes.fromhex(GOLDEN[kind])
    for end in range(len(golden)):
        with pytest.raises(ProtocolError):
            decode(golden[:end], max_bytes=LIMIT)


def test_small_mask_packs_row_major_ink_one() -> None:
    shape, bits = pack_mask(SMALL_MASK)
    assert (shape, bits) == ((4, 5), SMALL_BITS)
    np.testing.assert_array_equal(unpack_mask(shape, bits), SMALL_MASK)
    assert unpack_mask(shape, bits).dtype == np.uint8


def test_frame_mask_decodes_to_the_sent_mask() -> None:
    frame = decode(encode(EXAMPLES["frame"]), max_bytes=LIMIT)
    assert isinstance(frame, Frame)
    np.testing.assert_array_equal(frame.mask(), SMALL_MASK)


def test_optional_hello_fields_are_omitted_and_default() -> None:
    hello = Hello(device_id="d", session_id="s", mode="pages", sensor=(1280, 720), fovea=(100, 200))
    payload = msgpack.unpackb(encode(hello))
    assert "token" not in payload and "resume_from_seq" not in payload
    assert decode(encode(hello), max_bytes=LIMIT) == hello


def test_unknown_extra_keys_are_ignored() -> None:
    payload = msgpack.unpackb(encode(EXAMPLES["ack"]))
    payload["future_field"] = [1, 2, 3]
    assert decode(msgpack.packb(payload), max_bytes=LIMIT) == EXAMPLES["ack"]


# --- property tests ---------------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
int64 = st.integers(-(2**63), 2**63 - 1)
seqs = st.integers(0, 2**63 - 1)
masks = hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=40), elements=st.integers(0, 1))


@given(masks)
def test_random_masks_round_trip(mask: np.ndarray) -> None:
    shape, bits = pack_mask(mask)
    np.testing.assert_array_equal(unpack_mask(shape, bits), mask)


@given(
    seq=seqs,
    frame_id=seqs,
    t_us=int64,
    origin=st.tuples(int64, int64),
    gaze_px=st.tuples(finite, finite),
    gaze_rad=st.tuples(finite, finite),
    events_used=st.integers(0, 2**32 - 1),
    mask=masks,
)
def test_random_frames_round_trip(seq, frame_id, t_us, origin, gaze_px, gaze_rad, events_used, mask) -> None:
    shape, bits = pack_mask(mask)
    frame = Frame(seq, frame_id, t_us, origin, gaze_px, gaze_rad, events_used, shape, bits)
    decoded = decode(encode(frame), max_bytes=LIMIT)
    assert decoded == frame
    np.testing.assert_array_equal(decoded.mask(), mask)


@given(
    t_us=int64,
    stats=st.dictionaries(st.text(max_size=64), finite, max_size=64),
    device_id=st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}", fullmatch=True),
    lines=st.lists(st.tuples(int64, int64, int64, int64), max_size=20),
    mask=masks,
)
def test_random_other_messages_round_trip(t_us, stats, device_id, lines, mask) -> None:
    shape, bits = pack_mask(mask)
    for message in (
        Heartbeat(t_us=t_us, stats=stats),
        Hello(device_id=device_id, session_id=device_id, mode="frames", sensor=(1280, 720), fovea=(100, 200)),
        Page(seq=1, page_id=2, t_us=t_us, shape=shape, bits=bits, lines=tuple(lines)),
    ):
        assert decode(encode(message), max_bytes=LIMIT) == message


@settings(max_examples=300)
@given(st.binary(max_size=300))
def test_random_bytes_raise_only_protocol_errors(data: bytes) -> None:
    try:
        decode(data, max_bytes=LIMIT)
    except ProtocolError:
        pass


@given(st.sampled_from(sorted(GOLDEN)), st.integers(0, 400), st.integers(0, 255))
def test_corrupted_golden_bytes_raise_only_protocol_errors(kind: str, position: int, value: int) -> None:
    data = bytearray.fromhex(GOLDEN[kind])
    data[position % len(data)] = value
    try:
        message = decode(bytes(data), max_bytes=LIMIT)
    except ProtocolError:
        return
    assert type(message).TYPE in MESSAGE_TYPES  # still a valid message (e.g. a changed number)


# --- hostile and invalid inputs -------------------------------------------------------------------


def _with(kind: str, **changes: object) -> bytes:
    payload = msgpack.unpackb(bytes.fromhex(GOLDEN[kind]))
    for key, value in changes.items():
        if value is ...:
            del payload[key]
        else:
            payload[key] = value
    return msgpack.packb(payload, use_bin_type=True)


def test_oversized_message_is_refused_before_parsing() -> None:
    with pytest.raises(MessageTooLargeError) as caught:
        decode(b"\x00" * 101, max_bytes=100)
    assert caught.value.close_code == CloseCode.MESSAGE_TOO_BIG


@pytest.mark.parametrize(
    "data",
    [
        b"\xdb\xff\xff\xff\xff",  # str32 declaring 4 GiB
        b"\xc6\x7f\xff\xff\xff\x00",  # bin32 declaring 2 GiB
        b"\xdd\xff\xff\xff\xff",  # array32 declaring 4 G entries
        b"\xdf\xff\xff\xff\xff",  # map32 declaring 4 G entries
        b"\x91" * 100_000 + b"\xc0",  # nesting depth bomb
        b"\x81\x91\x01\x02",  # unhashable map key
        b"\x81\x01\x02",  # integer map key
        b"\xc1",  # reserved byte
        b"\x83\xa4type\xa3ack\xa3seq\x03",  # map declares 3 pairs, holds 2
        b"\x81\xa4type\xa3ack\x00",  # trailing byte
        b"\xa1\xff",  # invalid UTF-8
        b"",
    ],
)
def test_hostile_bytes_are_malformed(data: bytes) -> None:
    with pytest.raises(ProtocolError):
        decode(data, max_bytes=1 << 22)


@pytest.mark.parametrize("value", [[1, 2], 5, "hello", None, b"\x01"])
def test_message_must_be_a_map(value: object) -> None:
    with pytest.raises(MalformedMessageError):
        decode(msgpack.packb(value), max_bytes=LIMIT)


@pytest.mark.parametrize("kind", ["nope", 3, None, b"ack"])
def test_unknown_type(kind: object) -> None:
    with pytest.raises(UnknownMessageTypeError):
        decode(msgpack.packb({"type": kind, "seq": 1}), max_bytes=LIMIT)


@pytest.mark.parametrize("version", [0, 5, "1", True])
def test_wrong_protocol_version(version: object) -> None:
    with pytest.raises(VersionMismatchError) as caught:
        decode(_with("hello", v=version), max_bytes=LIMIT)
    assert caught.value.close_code == CloseCode.VERSION_MISMATCH


@pytest.mark.parametrize(
    ("kind", "changes"),
    [
        ("hello", {"v": ...}),
        ("hello", {"session_id": ...}),
        ("hello", {"session_id": "../etc/passwd"}),
        ("hello", {"session_id": ""}),
        ("hello", {"mode": "video"}),
        ("hello", {"sensor": [1280]}),
        ("hello", {"fovea": [0, 200]}),
        ("hello", {"resume_from_seq": -1}),
        ("frame", {"seq": -1}),
        ("frame", {"seq": 1.5}),
        ("frame", {"seq": True}),
        ("frame", {"seq": 2**63}),
        ("frame", {"origin": "0,0"}),
        ("frame", {"gaze_px": [float("nan"), 1.0]}),
        ("frame", {"gaze_rad": [1.0, float("inf")]}),
        ("frame", {"bits": "not bytes"}),
        ("frame", {"t_us": ...}),
        ("frame", {"events_used": msgpack.ExtType(5, b"x")}),
        ("page", {"lines": [[1, 2, 3]]}),
        ("gaze", {"px": [[1.0, 2.0]]}),  # length differs from t_us
        ("heartbeat", {"stats": {"a": "b"}}),
        ("heartbeat", {"stats": {str(i): i for i in range(100)}}),
        ("error", {"fatal": 1}),
        ("ack", {"seq": None}),
    ],
)
def test_invalid_fields(kind: str, changes: dict[str, object]) -> None:
    with pytest.raises(InvalidFieldError):
        decode(_with(kind, **changes), max_bytes=LIMIT)


@pytest.mark.parametrize(
    "changes",
    [
        {"shape": [4, 7]},  # 28 pixels need 4 bytes, 3 sent
        {"shape": [5, 5]},
        {"bits": SMALL_BITS + b"\x00"},
        {"bits": SMALL_BITS[:-1]},
        {"bits": bytes([0x03, 0x88, 0x01])},  # a padding bit set
        {"shape": [70000, 1]},
        {"shape": [8192, 8192], "bits": b"\x00" * (8192 * 8192 // 8)},
    ],
)
def test_bad_frame_masks(changes: dict[str, object]) -> None:
    with pytest.raises(BadMaskError) as caught:
        decode(_with("frame", **changes), max_bytes=1 << 24)
    assert caught.value.close_code == CloseCode.BAD_MASK


def test_invalid_messages_cannot_be_built() -> None:
    with pytest.raises(BadMaskError):
        Frame(1, 1, 0, (0, 0), (0.0, 0.0), (0.0, 0.0), 0, (100, 200), b"\x00")
    with pytest.raises(InvalidFieldError):
        Ack(seq=-5)
    with pytest.raises(BadMaskError):
        pack_mask(np.zeros((3,), np.uint8))


def test_protocol_version_is_four_and_one_is_still_accepted() -> None:
    assert PROTOCOL_VERSION == 4
    assert decode(bytes.fromhex(GOLDEN["hello"]), max_bytes=LIMIT).v == 1


@pytest.mark.parametrize("kind", ["frame", "page", "gaze", "new_page"])
@given(seq=st.integers(min_value=0, max_value=2**63 - 1))
@settings(max_examples=25, deadline=None)
def test_numbered_is_replace_of_the_seq_alone(kind: str, seq: int) -> None:
    """What the uplink sends: the message under its spool seq, the same bytes as a rebuilt one."""
    import dataclasses

    message = EXAMPLES[kind]
    before = message.seq
    numbered = message.numbered(seq)
    assert numbered == dataclasses.replace(message, seq=seq) and encode(numbered) == encode(dataclasses.replace(message, seq=seq))
    assert message.seq == before and numbered is not message  # the original is untouched


@pytest.mark.parametrize("seq", [-1, 2**63, "3", 1.5, True])
def test_numbered_refuses_a_wild_seq(seq: object) -> None:
    with pytest.raises(InvalidFieldError):
        EXAMPLES["frame"].numbered(seq)  # type: ignore[arg-type]  # a wrong type, on purpose


def test_the_scene_motion_is_an_optional_field_of_frames_and_views() -> None:
    """Glasses that measure the head's motion send it; older ones omit it (no version bump)."""
    frame = EXAMPLES["frame"]
    assert "scene_px" not in msgpack.unpackb(encode(frame)) and decode(encode(frame), max_bytes=LIMIT).scene_px is None
    moved = Frame(**{**frame.__dict__, "scene_px": (-12.5, 3.25)})
    decoded = decode(encode(moved), max_bytes=LIMIT)
    assert decoded.scene_px == (-12.5, 3.25) and decoded.record().scene_px == (-12.5, 3.25)
    levels = np.array([[0, 3, 7, 0, 1]] * 4, np.uint8)
    view = View(seq=1, view_id=2, t0_us=0, t_us=3, origin=(1, 2), gaze_px=(0.5, 0.5), gaze_rad=(0.0, 0.0), frames=2,
                events_used=4, shape=(4, 5), n_levels=8, levels=levels.tobytes(), scene_px=(4.0, -1.0))  # fmt: skip
    back = decode(encode(view), max_bytes=LIMIT)
    assert back.scene_px == (4.0, -1.0) and back.record().scene_px == (4.0, -1.0) and back.as_frame().scene_px == (4.0, -1.0)
    for bad in ([float("nan"), 0.0], [1.0], "up"):
        payload = msgpack.unpackb(encode(moved))
        payload["scene_px"] = bad
        with pytest.raises(InvalidFieldError, match="scene_px"):
            decode(msgpack.packb(payload), max_bytes=LIMIT)


def test_the_light_the_glasses_measured_is_an_optional_field_of_frames_and_views() -> None:
    """Glasses that measured the light say it in each frame and view; ones that did not omit it (no
    bytes, no version bump); the record carries it to the cloud, and a light that is no light is refused."""
    levels = np.array([[0, 3, 7, 0, 1]] * 4, np.uint8)
    unknown = View(seq=1, view_id=2, t0_us=0, t_us=3, origin=(1, 2), gaze_px=(0.5, 0.5), gaze_rad=(0.0, 0.0), frames=1,
                   events_used=4, shape=(4, 5), n_levels=8, levels=levels.tobytes())  # fmt: skip
    assert "light_lux" not in msgpack.unpackb(encode(unknown)) and decode(encode(unknown), max_bytes=LIMIT).record().light_lux is None
    dim = View(**{**unknown.__dict__, "light_lux": 6.5})
    back = decode(encode(dim), max_bytes=LIMIT)
    assert back.light_lux == 6.5 and back.record().light_lux == 6.5 and View.of(back.record()).light_lux == 6.5
    assert back.as_frame().light_lux == 6.5 and decode(encode(back.as_frame()), max_bytes=LIMIT).record().light_lux == 6.5
    for bad in (0, -3.0, "6", True, [6.0], float("nan"), float("inf")):
        payload = msgpack.unpackb(encode(dim))
        payload["light_lux"] = bad
        with pytest.raises(InvalidFieldError, match="light_lux"):
            decode(msgpack.packb(payload), max_bytes=LIMIT)


def test_a_starved_edge_says_how_much_it_shed_in_an_optional_field_of_views() -> None:
    """A view made while the live edge was shedding (edge.load) carries the level; one made by an edge
    that kept up omits it (no bytes, no version bump), and a peer that does not know it ignores it."""
    levels = np.array([[0, 3, 7, 0, 1]] * 4, np.uint8)
    kept_up = View(seq=1, view_id=2, t0_us=0, t_us=3, origin=(1, 2), gaze_px=(0.5, 0.5), gaze_rad=(0.0, 0.0), frames=1,
                   events_used=4, shape=(4, 5), n_levels=8, levels=levels.tobytes())  # fmt: skip
    assert "shed_level" not in msgpack.unpackb(encode(kept_up)) and decode(encode(kept_up), max_bytes=LIMIT).record().shed_level == 0
    starved = View(**{**kept_up.__dict__, "shed_level": 3})
    back = decode(encode(starved), max_bytes=LIMIT)
    assert back.shed_level == 3 and back.record().shed_level == 3
    assert View.of(back.record()).shed_level == 3 and View.of(kept_up.record()).shed_level is None
    for bad in (0, 4, True, 1.5, "3"):
        payload = msgpack.unpackb(encode(starved))
        payload["shed_level"] = bad
        with pytest.raises(InvalidFieldError, match="shed_level"):
            decode(msgpack.packb(payload), max_bytes=LIMIT)
