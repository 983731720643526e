"""The darkread wire protocol: versioned msgpack messages between the glasses and the cloud.

Every message is one msgpack map with a ``type`` string; each type is a frozen dataclass here.
``encode`` and ``decode`` are pure (bytes in, bytes out) so both ends and the tests share them.
``decode`` checks everything a hostile peer could get wrong and raises only ``ProtocolError``
subclasses (see ``errors.py``). Unknown extra keys are ignored so a peer may add optional
fields without a version bump; anything that changes meaning bumps ``PROTOCOL_VERSION``.
Version 2 adds compressed masks (``enc``, see ``codecs.py``) and the fused ``view``; version 3 the
CCITT G4 page (``enc="g4"``); version 4 lets a view be larger than the fovea (the union of its frames'
windows, ``WIDE_VIEW_VERSION``); a server still accepts version 1-3 clients (``SUPPORTED_VERSIONS``).
The field list with units and limits is in ``README.md`` next to this file.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import Any, ClassVar, Literal, TypeAlias

import msgpack
import numpy as np

from darkread.core.frame_record import MAX_SHED_LEVEL, MAX_VIEW_GROWTH, FrameRecord, threshold_levels
from darkread.core.mask_bits import pack_bits, packed_length, unpack_bits

from .codecs import LEVEL_ENCODINGS, MASK_ENCODINGS, compress_bits, compress_levels, decompress_bits, decompress_levels
from .errors import (
    BadMaskError,
    InvalidFieldError,
    MalformedMessageError,
    MessageTooLargeError,
    ProtocolError,
    UnknownMessageTypeError,
    VersionMismatchError,
)

PROTOCOL_VERSION = 4
SUPPORTED_VERSIONS = (1, 2, 3, 4)  # what a server accepts in hello.v (and answers in welcome.v)
WIDE_VIEW_VERSION = 4  # from this version a view may be larger than hello.fovea (up to MAX_VIEW_GROWTH per side)
MAX_LEVELS = 16  # grey levels of a view
DEFAULT_MAX_MESSAGE_BYTES = 4 * 1024 * 1024
MAX_MASK_PIXELS = 16 * 1024 * 1024  # 16 Mpx: a stitched page of 4096 x 4096 fits
FRAME_ENCODINGS = MASK_ENCODINGS[:2]  # a frame's mask: bits or zlib
PAGE_ENCODINGS = MASK_ENCODINGS  # a page's: also a 1-bit PNG (v2) or CCITT G4 (v3)
MAX_SIDE = 65_535
MAX_LIST = 100_000  # lines per page, gaze samples per batch
MAX_STATS = 64
MAX_TEXT = 4096
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1
ID_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")

Mode = Literal["frames", "pages"]


# --- field checks: wire value -> Python value, raising InvalidFieldError ------------------------


def _int(value: Any, name: str, lo: int = INT64_MIN, hi: int = INT64_MAX) -> int:
    if type(value) is not int:  # bool is an int subclass; refuse it
        raise InvalidFieldError(f"{name}: expected an integer, got {type(value).__name__}")
    if not lo <= value <= hi:
        raise InvalidFieldError(f"{name}: {value} outside [{lo}, {hi}]")
    return value


def _seq(value: Any, name: str) -> int:
    return _int(value, name, 0, INT64_MAX)


def _count(value: Any, name: str) -> int:
    return _int(value, name, 0, 2**32 - 1)


def _float(value: Any, name: str) -> float:
    if type(value) not in (int, float):
        raise InvalidFieldError(f"{name}: expected a number, got {type(value).__name__}")
    if type(value) is int and not INT64_MIN <= value <= INT64_MAX:
        raise InvalidFieldError(f"{name}: {value} out of range")
    result = float(value)
    if not math.isfinite(result):
        raise InvalidFieldError(f"{name}: must be finite, got {result}")
    return result


def _lux(value: Any, name: str) -> float:
    result = _float(value, name)
    if result <= 0:
        raise InvalidFieldError(f"{name}: a light level must be positive lux, got {result}")
    return result


def _bool(value: Any, name: str) -> bool:
    if type(value) is not bool:
        raise InvalidFieldError(f"{name}: expected a boolean, got {type(value).__name__}")
    return value


def _text(value: Any, name: str, limit: int = MAX_TEXT) -> str:
    if type(value) is not str:
        raise InvalidFieldError(f"{name}: expected a string, got {type(value).__name__}")
    if len(value) > limit:
        raise InvalidFieldError(f"{name}: longer than {limit} characters")
    return value


def _identifier(value: Any, name: str) -> str:
    text = _text(value, name, 128)
    if not ID_PATTERN.fullmatch(text):
        raise InvalidFieldError(f"{name}: {text!r} must match {ID_PATTERN.pattern}")
    return text


def _mode(value: Any, name: str) -> str:
    if value not in ("frames", "pages") or type(value) is not str:
        raise InvalidFieldError(f"{name}: expected 'frames' or 'pages', got {value!r}")
    return value


def _choice(options: tuple[str, ...]) -> Callable[[Any, str], str]:
    def convert(value: Any, name: str) -> str:
        if type(value) is not str or value not in options:
            raise InvalidFieldError(f"{name}: expected one of {', '.join(options)}, got {str(value)[:32]!r}")
        return value

    return convert


def _bytes(value: Any, name: str) -> bytes:
    if type(value) is not bytes:
        raise InvalidFieldError(f"{name}: expected bytes (msgpack bin), got {type(value).__name__}")
    return value


def _list(value: Any, name: str, limit: int = MAX_LIST) -> list[Any]:
    if type(value) not in (list, tuple):
        raise InvalidFieldError(f"{name}: expected an array, got {type(value).__name__}")
    if len(value) > limit:
        raise InvalidFieldError(f"{name}: more than {limit} entries")
    return list(value)


def _tuple_of(check: Callable[[Any, str], Any], length: int) -> Callable[[Any, str], tuple[Any, ...]]:
    def convert(value: Any, name: str) -> tuple[Any, ...]:
        items = _list(value, name, length)
        if len(items) != length:
            raise InvalidFieldError(f"{name}: expected {length} entries, got {len(items)}")
        return tuple(check(item, f"{name}[{i}]") for i, item in enumerate(items))

    return convert


def _list_of(check: Callable[[Any, str], Any]) -> Callable[[Any, str], tuple[Any, ...]]:
    def convert(value: Any, name: str) -> tuple[Any, ...]:
        return tuple(check(item, f"{name}[{i}]") for i, item in enumerate(_list(value, name)))

    return convert


def _side(value: Any, name: str) -> int:
    return _int(value, name, 1, MAX_SIDE)


def _stats(value: Any, name: str) -> dict[str, float]:
    if type(value) is not dict:
        raise InvalidFieldError(f"{name}: expected a map, got {type(value).__name__}")
    if len(value) > MAX_STATS:
        raise InvalidFieldError(f"{name}: more than {MAX_STATS} entries")
    result: dict[str, float] = {}
    for key, item in value.items():
        key_text = _text(key, f"{name} key", 64)
        result[key_text] = _float(item, f"{name}[{key_text!r}]")
    return result


_pair_int = _tuple_of(_int, 2)
_pair_float = _tuple_of(_float, 2)
_shape = _tuple_of(_side, 2)


def _mask_shape(value: Any, name: str) -> tuple[int, int]:
    try:
        return _shape(value, name)
    except InvalidFieldError as exc:
        raise BadMaskError(str(exc)) from None

_box = _tuple_of(_int, 4)


def _optional(check: Callable[[Any, str], Any]) -> Callable[[Any, str], Any]:
    def convert(value: Any, name: str) -> Any:
        return None if value is None else check(value, name)

    return convert


def _spec(check: Callable[[Any, str], Any], default: Any = MISSING, **kwargs: Any) -> Any:
    """A dataclass field that carries its wire check in ``metadata``."""
    return field(default=default, metadata={"check": check}, **kwargs)


# --- masks --------------------------------------------------------------------------------------


def pack_mask(mask: np.ndarray) -> tuple[tuple[int, int], bytes]:
    """A 2-D ink mask (nonzero = ink) -> ``(shape, bits)``, row-major, MSB first, ink = 1."""
    array = np.asarray(mask)
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise BadMaskError(f"mask must be a non-empty 2-D array, got shape {array.shape}")
    shape = (int(array.shape[0]), int(array.shape[1]))
    check_mask(shape, b"\0" * packed_length(shape))
    return shape, pack_bits(array)


def check_mask_shape(shape: tuple[int, int]) -> None:
    """Raise ``BadMaskError`` unless ``shape`` is within the protocol's limits (checked before decoding)."""
    height, width = shape
    if height < 1 or width < 1 or height > MAX_SIDE or width > MAX_SIDE:
        raise BadMaskError(f"mask shape {shape} must be positive and at most {MAX_SIDE} per side")
    if height * width > MAX_MASK_PIXELS:
        raise BadMaskError(f"mask shape {shape} exceeds {MAX_MASK_PIXELS} pixels")


def check_mask(shape: tuple[int, int], bits: bytes) -> None:
    """Raise ``BadMaskError`` unless ``bits`` is exactly the packed form of a ``shape`` mask."""
    check_mask_shape(shape)
    height, width = shape
    expected = packed_length(shape)
    if len(bits) != expected:
        raise BadMaskError(f"mask of shape {shape} needs {expected} bytes of bits, got {len(bits)}")
    spare = expected * 8 - height * width
    if spare and bits[-1] & ((1 << spare) - 1):
        raise BadMaskError("padding bits after the last pixel must be zero")


def unpack_mask(shape: tuple[int, int], bits: bytes) -> np.ndarray:
    """``(shape, bits)`` -> uint8 mask of ``shape`` with ink = 1, background = 0."""
    check_mask(shape, bits)
    return unpack_bits(shape, bits)


# --- messages -----------------------------------------------------------------------------------


class _Checked:
    """Validation at construction: an invalid message can neither be built nor decoded."""

    TYPE: ClassVar[str]
    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]  # every message is a dataclass

    def _to_wire(self, payload: dict[str, Any]) -> None:
        """Turn the in-memory form of a field into its wire form (compression), in place."""

    @classmethod
    def _from_wire(cls, values: dict[str, Any]) -> None:
        """The inverse of ``_to_wire`` on decoded values, in place; raises ``ProtocolError``."""

    def __post_init__(self) -> None:
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        for name, value in _check_fields(type(self), values).items():
            object.__setattr__(self, name, value)

    def numbered(self, seq: int) -> Any:
        """A copy under ``seq``: only the seq is checked, the rest was at construction (the uplink
        numbers every message, and checking a mask again costs more than sending it)."""
        copy = object.__new__(type(self))
        copy.__dict__.update(self.__dict__)
        object.__setattr__(copy, "seq", _seq(seq, f"{self.TYPE}.seq"))
        return copy


@dataclass(frozen=True)
class Hello(_Checked):
    """client -> server, the first message of every connection."""

    TYPE: ClassVar[str] = "hello"
    device_id: str = _spec(_identifier)
    session_id: str = _spec(_identifier)
    mode: Mode = _spec(_mode)
    sensor: tuple[int, int] = _spec(_shape)  # (width, height) in pixels -- not the order of fovea (proto/README.md)
    fovea: tuple[int, int] = _spec(_shape)  # (height, width) in pixels, a numpy shape: frame.shape equals it
    token: str | None = _spec(_optional(lambda v, n: _text(v, n, 512)), None)
    resume_from_seq: int | None = _spec(_optional(_seq), None)
    # which spool (seq space) speaks: a session belongs to the stream that opened it
    stream_id: str | None = _spec(_optional(_identifier), None)
    v: int = _spec(_int, PROTOCOL_VERSION)


@dataclass(frozen=True)
class Welcome(_Checked):
    """server -> client, answer to hello: resend every message with seq > last_acked_seq."""

    TYPE: ClassVar[str] = "welcome"
    session_id: str = _spec(_identifier)
    last_acked_seq: int = _spec(lambda v, n: _int(v, n, -1, INT64_MAX))
    max_message_bytes: int = _spec(lambda v, n: _int(v, n, 1, 2**31))
    v: int = _spec(_int, PROTOCOL_VERSION)
    # optional message types this server accepts beyond the version's core set (e.g. "new_page");
    # a client sends those only when listed, so old servers and old clients keep working
    features: tuple[str, ...] | None = _spec(_optional(_list_of(lambda v, n: _text(v, n, 64))), None)


@dataclass(frozen=True)
class Frame(_Checked):
    """client -> server, one reconstructed foveal window."""

    TYPE: ClassVar[str] = "frame"
    seq: int = _spec(_seq)
    frame_id: int = _spec(_seq)
    t_us: int = _spec(_int)  # event clock of the window's last event, microseconds
    origin: tuple[int, int] = _spec(_pair_int)  # window top-left (x0, y0), sensor pixels
    gaze_px: tuple[float, float] = _spec(_pair_float)  # (u, v), sensor pixels
    gaze_rad: tuple[float, float] = _spec(_pair_float)  # (yaw, pitch), radians
    events_used: int = _spec(_count)
    shape: tuple[int, int] = _spec(_mask_shape)  # (rows, cols)
    bits: bytes = _spec(_bytes, repr=False)  # the ink mask, darkread.core.mask_bits.pack_bits (decoded form)
    enc: str = _spec(_choice(FRAME_ENCODINGS), "bits")  # v2: how ``bits`` go on the wire
    scene_px: tuple[float, float] | None = _spec(_optional(_pair_float), None)  # the scene's motion so far, sensor px
    light_lux: float | None = _spec(_optional(_lux), None)  # the light the glasses measured at the page; absent: not known

    @classmethod
    def of(
        cls, record: FrameRecord, *, seq: int = 0, gaze_rad: tuple[float, float] = (0.0, 0.0), events_used: int = 0,
        enc: str = "zlib",
    ) -> Frame:
        """The wire message carrying ``record`` (``seq`` is assigned by the uplink)."""
        shape, bits = pack_mask(record.mask)
        return cls(
            seq=seq, frame_id=record.frame_id, t_us=record.t_us, origin=record.origin, gaze_px=record.gaze_px,
            gaze_rad=gaze_rad, events_used=events_used, shape=shape, bits=bits, enc=enc, scene_px=record.scene_px,
            light_lux=record.light_lux,
        )

    def _to_wire(self, payload: dict[str, Any]) -> None:
        _bits_to_wire(self, payload)

    @classmethod
    def _from_wire(cls, values: dict[str, Any]) -> None:
        _bits_from_wire(cls, values)

    def mask(self) -> np.ndarray:
        return unpack_mask(self.shape, self.bits)

    def record(self) -> FrameRecord:
        """The frame record this message carries."""
        return FrameRecord(self.frame_id, self.t_us, self.mask(), self.origin, self.gaze_px, scene_px=self.scene_px,
                           light_lux=self.light_lux)


@dataclass(frozen=True)
class Page(_Checked):
    """client -> server, a page stitched on the glasses (mode "pages")."""

    TYPE: ClassVar[str] = "page"
    seq: int = _spec(_seq)
    page_id: int = _spec(_seq)
    t_us: int = _spec(_int)
    shape: tuple[int, int] = _spec(_mask_shape)
    bits: bytes = _spec(_bytes, repr=False)
    lines: tuple[tuple[int, int, int, int], ...] = _spec(_list_of(_box), ())  # (x0, y0, x1, y1)
    enc: str = _spec(_choice(PAGE_ENCODINGS), "bits")  # v2: "png" a 1-bit PNG; v3: "g4" a CCITT G4 stream

    def mask(self) -> np.ndarray:
        return unpack_mask(self.shape, self.bits)

    def _to_wire(self, payload: dict[str, Any]) -> None:
        _bits_to_wire(self, payload)

    @classmethod
    def _from_wire(cls, values: dict[str, Any]) -> None:
        _bits_from_wire(cls, values)


@dataclass(frozen=True)
class View(_Checked):
    """client -> server (v2, mode "frames"): the frames of one fixation registered and fused into
    one view of ink probability in ``n_levels`` grey levels (level / (n_levels - 1))."""

    TYPE: ClassVar[str] = "view"
    seq: int = _spec(_seq)
    view_id: int = _spec(_seq)
    t0_us: int = _spec(_int)  # event clock: the first fused frame
    t_us: int = _spec(_int)  # event clock: the last fused frame (no event in the view is newer)
    origin: tuple[int, int] = _spec(_pair_int)  # the view's top-left (x0, y0), sensor pixels
    gaze_px: tuple[float, float] = _spec(_pair_float)
    gaze_rad: tuple[float, float] = _spec(_pair_float)
    frames: int = _spec(lambda v, n: _int(v, n, 1, 2**32 - 1))  # frames fused
    events_used: int = _spec(_count)
    shape: tuple[int, int] = _spec(_mask_shape)
    n_levels: int = _spec(lambda v, n: _int(v, n, 2, MAX_LEVELS))
    levels: bytes = _spec(_bytes, repr=False)  # one level index per pixel, row-major (decoded form)
    enc: str = _spec(_choice(LEVEL_ENCODINGS), "png")
    scene_px: tuple[float, float] | None = _spec(_optional(_pair_float), None)  # the scene's motion so far, sensor px
    # a live edge that could not keep up: how much it was giving up (1-3, ``edge.load``); absent: nothing
    shed_level: int | None = _spec(_optional(lambda v, n: _int(v, n, 1, MAX_SHED_LEVEL)), None)
    # the light the glasses measured at the page while the view was made (lux); absent: not known
    light_lux: float | None = _spec(_optional(_lux), None)

    @classmethod
    def of(
        cls, record: FrameRecord, *, seq: int = 0, t0_us: int | None = None, gaze_rad: tuple[float, float] = (0.0, 0.0),
        events_used: int = 0, enc: str = "png",
    ) -> View:
        """The wire message carrying the fused ``record`` (it has ``levels``); ``t0_us``, its first
        frame's time, defaults to ``record.t_us`` (``seq`` is assigned by the uplink)."""
        if record.levels is None:
            raise BadMaskError(f"record {record.frame_id} has no grey levels: it is a binary frame, not a view")
        levels = np.ascontiguousarray(record.levels, dtype=np.uint8)
        return cls(
            seq=seq, view_id=record.frame_id, t0_us=record.t_us if t0_us is None else t0_us, t_us=record.t_us,
            origin=record.origin, gaze_px=record.gaze_px, gaze_rad=gaze_rad, frames=record.frames, events_used=events_used,
            shape=(int(levels.shape[0]), int(levels.shape[1])), n_levels=record.n_levels, levels=levels.tobytes(), enc=enc,
            scene_px=record.scene_px, shed_level=record.shed_level or None, light_lux=record.light_lux,
        )

    def ink(self) -> np.ndarray:
        """uint8 [rows, cols] level indices, 0 (paper) .. n_levels - 1 (surely ink)."""
        return np.frombuffer(self.levels, np.uint8).reshape(self.shape)

    def record(self) -> FrameRecord:
        """The view as a frame record: its grey levels and frame count (the stitcher averages it in
        as that many frames), with ``mask`` the ink where the probability is at least one half."""
        levels = self.ink()
        return FrameRecord(self.view_id, self.t_us, threshold_levels(levels, self.n_levels), self.origin, self.gaze_px,
                           levels=levels, n_levels=self.n_levels, frames=self.frames, scene_px=self.scene_px,
                           shed_level=self.shed_level or 0, light_lux=self.light_lux)  # fmt: skip

    def as_frame(self) -> Frame:
        """The thresholded view as a binary ``frame`` of the same seq (for a reader of binary frames)."""
        shape, bits = pack_mask(self.record().mask)
        return Frame(
            seq=self.seq, frame_id=self.view_id, t_us=self.t_us, origin=self.origin, gaze_px=self.gaze_px,
            gaze_rad=self.gaze_rad, events_used=self.events_used, shape=shape, bits=bits, scene_px=self.scene_px,
            light_lux=self.light_lux,
        )

    def _to_wire(self, payload: dict[str, Any]) -> None:
        payload["levels"] = compress_levels(self.shape, self.levels, self.enc)

    @classmethod
    def _from_wire(cls, values: dict[str, Any]) -> None:
        shape = _mask_shape(values.get("shape"), "view.shape")
        enc = _choice(LEVEL_ENCODINGS)(values.get("enc", "png"), "view.enc")
        values["levels"] = decompress_levels(shape, _bytes(values.get("levels"), "view.levels"), enc)


def check_view_shape(message: Frame | View, fovea: tuple[int, int], version: int) -> None:
    """A frame is one foveal window; a view of a version 4 session the union of its frames' windows,
    from the fovea up to ``MAX_VIEW_GROWTH`` times its side (before version 4: the fovea)."""
    h, w = message.shape
    fh, fw = fovea
    if isinstance(message, View) and version >= WIDE_VIEW_VERSION:
        if not (fh <= h <= MAX_VIEW_GROWTH * fh and fw <= w <= MAX_VIEW_GROWTH * fw):
            raise BadMaskError(f"view shape {message.shape} is outside hello.fovea {fovea} .. {MAX_VIEW_GROWTH}x its sides")
    elif message.shape != fovea:
        raise BadMaskError(f"{message.TYPE} shape {message.shape} differs from hello.fovea {fovea}"
                           + (f" (a larger view needs protocol version {WIDE_VIEW_VERSION})" if isinstance(message, View) else ""))


def content_version(message: Message) -> int:
    """The lowest protocol version that has everything ``message`` uses (a session may not send newer)."""
    enc = getattr(message, "enc", "bits")
    if enc == "g4":
        return 3
    return 2 if isinstance(message, View) or enc != "bits" else 1


def _bits_to_wire(message: Frame | Page, payload: dict[str, Any]) -> None:
    payload["bits"] = compress_bits(message.shape, message.bits, message.enc)


def _bits_from_wire(cls: type[Frame] | type[Page], values: dict[str, Any]) -> None:
    enc = values.get("enc", "bits")
    if enc == "bits":
        return  # v1 layout: checked by the message itself
    enc = _choice(PAGE_ENCODINGS if cls is Page else FRAME_ENCODINGS)(enc, f"{cls.TYPE}.enc")  # before decoding
    shape = _mask_shape(values.get("shape"), f"{cls.TYPE}.shape")
    check_mask_shape(shape)  # the protocol's limits before a byte is decompressed
    values["bits"] = decompress_bits(shape, _bytes(values.get("bits"), f"{cls.TYPE}.bits"), enc)


@dataclass(frozen=True)
class NewPage(_Checked):
    """client -> server (mode "frames", if ``welcome.features`` lists "new_page"): the wearer
    moved to other text; frames after this seq start a new page."""

    TYPE: ClassVar[str] = "new_page"
    seq: int = _spec(_seq)
    t_us: int = _spec(_int)


@dataclass(frozen=True)
class Gaze(_Checked):
    """client -> server, an optional batch of gaze samples (same length lists)."""

    TYPE: ClassVar[str] = "gaze"
    seq: int = _spec(_seq)
    t_us: tuple[int, ...] = _spec(_list_of(_int))
    px: tuple[tuple[float, float], ...] = _spec(_list_of(_pair_float))


@dataclass(frozen=True)
class Heartbeat(_Checked):
    """client -> server, liveness plus a few numbers for the server's logs."""

    TYPE: ClassVar[str] = "heartbeat"
    t_us: int = _spec(_int)
    stats: dict[str, float] = _spec(_stats, default_factory=dict)


@dataclass(frozen=True)
class Ack(_Checked):
    """server -> client, cumulative: every seq <= ``seq`` is durably stored."""

    TYPE: ClassVar[str] = "ack"
    seq: int = _spec(_seq)


@dataclass(frozen=True)
class Error(_Checked):
    """server -> client, sent before the server closes (``fatal``) or to report a dropped message."""

    TYPE: ClassVar[str] = "error"
    code: int = _spec(lambda v, n: _int(v, n, 0, 65_535))
    message: str = _spec(_text)
    fatal: bool = _spec(_bool)


Message: TypeAlias = Hello | Welcome | Frame | Page | View | NewPage | Gaze | Heartbeat | Ack | Error
MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls for cls in (Hello, Welcome, Frame, Page, View, NewPage, Gaze, Heartbeat, Ack, Error)
}


def _check_fields(cls: type[_Checked], values: Mapping[str, Any]) -> dict[str, Any]:
    checked: dict[str, Any] = {}
    for spec in fields(cls):
        name = f"{cls.TYPE}.{spec.name}"
        if spec.name not in values:
            raise InvalidFieldError(f"{name}: missing")
        checked[spec.name] = spec.metadata["check"](values[spec.name], name)
    if "shape" in checked and "bits" in checked:
        check_mask(checked["shape"], checked["bits"])
    if cls is View:
        if len(checked["levels"]) != checked["shape"][0] * checked["shape"][1]:
            raise BadMaskError(f"view.levels: {len(checked['levels'])} bytes for a {checked['shape']} view")
        if np.frombuffer(checked["levels"], np.uint8).max(initial=0) >= checked["n_levels"]:
            raise BadMaskError(f"view.levels: a level of {checked['n_levels']} or more")
    if cls is Gaze and len(checked["t_us"]) != len(checked["px"]):
        raise InvalidFieldError("gaze.t_us and gaze.px must have the same length")
    return checked


def encode(message: Message) -> bytes:
    """A message -> msgpack bytes (a map; ``type`` first, then fields in declaration order)."""
    payload: dict[str, Any] = {"type": message.TYPE}
    for spec in fields(message):
        value = getattr(message, spec.name)
        if value is not None:  # optional fields are omitted rather than sent as nil
            payload[spec.name] = value
    if payload.get("enc") == "bits":
        del payload["enc"]  # the v1 layout: the bytes of a v1 message exactly
    message._to_wire(payload)
    return msgpack.packb(payload, use_bin_type=True)


def decode(data: bytes | str, *, max_bytes: int) -> Message:
    """msgpack bytes -> a message; raises only ``ProtocolError`` subclasses on bad input (a text
    websocket message among them)."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MalformedMessageError(f"expected a binary message, got {type(data).__name__}")
    if len(data) > max_bytes:
        raise MessageTooLargeError(f"message of {len(data)} bytes exceeds the limit of {max_bytes}")
    try:
        payload = msgpack.unpackb(data, raw=False, strict_map_key=True, timestamp=0)
    except (ValueError, TypeError, OverflowError, msgpack.UnpackException) as exc:
        detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise MalformedMessageError(f"not valid msgpack ({detail})"[:300]) from None
    if type(payload) is not dict:
        raise MalformedMessageError(f"a message must be a msgpack map, got {type(payload).__name__}")
    kind = payload.get("type")
    cls = MESSAGE_TYPES.get(kind) if type(kind) is str else None
    if cls is None:
        shown = kind if type(kind) is str else type(kind).__name__
        raise UnknownMessageTypeError(f"unknown message type {str(shown)[:64]!r}")
    if cls in (Hello, Welcome) and "v" not in payload:
        raise InvalidFieldError(f"{cls.TYPE}.v: missing (the protocol version, {PROTOCOL_VERSION})")
    if cls in (Hello, Welcome) and (type(payload["v"]) is not int or payload["v"] not in SUPPORTED_VERSIONS):
        version = payload["v"]
        raise VersionMismatchError(
            f"protocol version {str(version)[:16]} is not supported; this end speaks "
            f"{', '.join(map(str, SUPPORTED_VERSIONS))}"
        )
    values = {spec.name: payload[spec.name] for spec in fields(cls) if spec.name in payload}
    cls._from_wire(values)
    for spec in fields(cls):  # absent optional fields take their defaults
        if spec.name not in values and spec.default is not MISSING:
            values[spec.name] = spec.default
        elif spec.name not in values and spec.default_factory is not MISSING:
            values[spec.name] = spec.default_factory()
    try:
        return cls(**values)
    except ProtocolError:
        raise
    except TypeError as exc:  # a required field is missing
        raise InvalidFieldError(f"{cls.TYPE}: {exc}") from None


__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "MAX_MASK_PIXELS",
    "MESSAGE_TYPES",
    "PROTOCOL_VERSION",
    "SUPPORTED_VERSIONS",
    "MAX_VIEW_GROWTH",
    "WIDE_VIEW_VERSION",
    "Ack",
    "Error",
    "Frame",
    "Gaze",
    "Heartbeat",
    "Hello",
    "Message",
    "Mode",
    "NewPage",
    "Page",
    "View",
    "Welcome",
    "check_mask",
    "check_mask_shape",
    "check_view_shape",
    "content_version",
    "decode",
    "encode",
    "pack_mask",
    "unpack_mask",
]
