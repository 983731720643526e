"""Treuzell control frames, the EVK3/EVK4 board protocol (pure: bytes in, bytes out).

A frame is little-endian 32-bit words ``[property, payload_bytes, payload...]``. The host writes
it to the control OUT endpoint and reads the reply from control IN. The reply echoes the
property; ``property | FAILURE_FLAG`` means the command failed and the third word is an errno;
a bare ``FAILURE_FLAG`` means the board does not know the property. Writes set ``WRITE_FLAG``.
Learned from OpenEB ``hal_psee_plugins/src/boards/treuzell/tz_control_frame.cpp``,
``tz_libusb_board_command.cpp`` and ``include/boards/treuzell/treuzell_command_definition.h``.
"""

from __future__ import annotations

import errno as errno_module
import os
import struct
from dataclasses import dataclass

from darkread.edge.errors import DeviceError

FAILURE_FLAG = 0x80000000
WRITE_FLAG = 0x40000000
UNKNOWN_COMMAND = FAILURE_FLAG

PROP_FPGA_STATE = 0x71
PROP_SERIAL = 0x72
PROP_RELEASE_VERSION = 0x79
PROP_BUILD_DATE = 0x7A
PROP_DEVICES = 0x10000
PROP_DEVICE_NAME = 0x10001
PROP_DEVICE_COMPATIBLE = 0x10003
PROP_DEVICE_REG32 = 0x10102
PROP_DEVICE_STREAM = 0x10200

HEADER_BYTES = 8
MAX_REPLY_BYTES = 1024


class TreuzellError(DeviceError):
    """The board answered a control frame with something other than the expected reply."""


class CommandFailedError(TreuzellError):
    """The board reported a failure for a command; ``errno`` is what it sent back."""

    def __init__(self, prop: int, errno: int, detail: str = "") -> None:
        name = errno_module.errorcode.get(errno, "?")
        super().__init__(
            f"camera refused property 0x{prop:08X}{detail}: errno {errno} ({name}: {os.strerror(errno)})"
        )
        self.prop = prop
        self.errno = errno


@dataclass(frozen=True)
class Packet:
    """One Treuzell control packet: a property id and its payload (a request, or the board's reply)."""

    prop: int
    payload: bytes

    def word(self, index: int) -> int:
        """The ``index``-th 32-bit payload word; TreuzellError when the payload is too short."""
        end = 4 * (index + 1)
        if len(self.payload) < end:
            raise TreuzellError(
                f"reply to property 0x{self.prop:08X} has {len(self.payload)} payload bytes, need {end}"
            )
        return struct.unpack_from("<I", self.payload, 4 * index)[0]

    def u64(self, index: int = 0) -> int:
        end = 8 * (index + 1)
        if len(self.payload) < end:
            raise TreuzellError(
                f"reply to property 0x{self.prop:08X} has {len(self.payload)} payload bytes, need {end}"
            )
        return struct.unpack_from("<Q", self.payload, 8 * index)[0]


def encode_packet(prop: int, payload: bytes = b"") -> bytes:
    return struct.pack("<II", prop, len(payload)) + payload


def encode_words(prop: int, *words: int) -> bytes:
    return encode_packet(prop, struct.pack(f"<{len(words)}I", *words))


def decode_packet(data: bytes) -> Packet:
    """Split a frame; TreuzellError when the size word does not match the bytes received."""
    if len(data) < HEADER_BYTES:
        raise TreuzellError(f"control reply of {len(data)} bytes is shorter than a frame header")
    prop, size = struct.unpack_from("<II", data)
    if size != len(data) - HEADER_BYTES:
        raise TreuzellError(f"control frame says {size} payload bytes but carries {len(data) - HEADER_BYTES}")
    return Packet(prop, bytes(data[HEADER_BYTES:]))


def check_reply(request_prop: int, data: bytes) -> Packet:
    """The reply frame to ``request_prop``, or the error the board signalled."""
    reply = decode_packet(data)
    if reply.prop == UNKNOWN_COMMAND:
        raise TreuzellError(f"camera does not implement property 0x{request_prop:08X}")
    if reply.prop == request_prop | FAILURE_FLAG:
        err = reply.word(2) if len(reply.payload) >= 12 else (reply.word(0) if reply.payload else 0)
        raise CommandFailedError(request_prop, err)
    if reply.prop != request_prop:
        raise TreuzellError(f"camera answered property 0x{reply.prop:08X} to a request for 0x{request_prop:08X}")
    return reply


def encode_register_write(addr: int, value: int, device: int = 0) -> bytes:
    return encode_words(PROP_DEVICE_REG32 | WRITE_FLAG, device, addr, value)


def encode_register_read(addr: int, device: int = 0, count: int = 1) -> bytes:
    return encode_words(PROP_DEVICE_REG32, device, addr, count)


def check_register_reply(reply: Packet, addr: int, device: int = 0) -> None:
    """The board echoes device and address; a mismatch means replies got out of step."""
    if reply.word(0) != device or reply.word(1) != addr:
        raise TreuzellError(
            f"register reply for device {reply.word(0)} address 0x{reply.word(1):04X}, "
            f"expected device {device} address 0x{addr:04X}"
        )


def format_version(version: int) -> str:
    """Firmware release word 0x00MMmmpp as ``M.m.p``."""
    return f"{(version >> 16) & 0xFF}.{(version >> 8) & 0xFF}.{version & 0xFF}"
