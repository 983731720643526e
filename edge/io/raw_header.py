"""Prophesee RAW header: ASCII ``% key value`` lines in front of the binary event stream.

The header ends at ``% end`` or, in files written before Metavision SDK 4 (which have no ``end``
line), at the first line that does not start with ``"% "``. The encoding and sensor size come from
``format`` (``EVT3;height=720;width=1280``), else from the legacy ``evt`` and ``geometry`` keys,
else from ``system_ID`` (the camera model), as OpenEB does for old files.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from darkread.edge.errors import RawFormatError

SUPPORTED_FORMATS = ("EVT3", "EVT2")
# Legacy ``evt`` values and the format names they stand for.
_LEGACY_EVT = {"3.0": "EVT3", "2.0": "EVT2", "2.1": "EVT21"}
# Cameras known by ``system_ID`` in files without ``format``/``geometry``: (format, width, height).
_SYSTEM_IDS = {
    "21": ("EVT2", 640, 480),  # Gen3 VGA
    "48": ("EVT3", 1280, 720),  # EVK3 Gen4.1 HD
    "49": ("EVT3", 1280, 720),  # EVK3 / EVK4 IMX636
    "50": ("EVT3", 1280, 720),  # EVK2 IMX636
}
# A header longer than this is not a header (guards against scanning a huge binary file).
MAX_HEADER_BYTES = 1 << 20


@dataclass(frozen=True)
class RawHeader:
    format: str  # "EVT3" or "EVT2"
    width: int
    height: int
    fields: dict[str, str] = field(default_factory=dict)  # every "% key value" line
    data_offset: int = 0  # byte offset of the first data byte


def _split_header(data: bytes) -> tuple[dict[str, str], int, bool]:
    """The ``% key value`` lines, the offset of the first byte after them, and whether the
    header is known to be complete (False when ``data`` ends inside or right after it)."""
    fields: dict[str, str] = {}
    pos = 0
    while data.startswith(b"% ", pos):
        end = data.find(b"\n", pos)
        if end < 0:  # the bytes end inside a header line
            end = len(data)
        line = data[pos + 2 : end].decode("latin-1").rstrip("\r")
        pos = min(end + 1, len(data))
        key, _, value = line.partition(" ")
        if key == "end":
            return fields, pos, True
        fields[key] = value.strip()
    return fields, pos, pos < len(data) and not b"% ".startswith(data[pos : pos + 2])


def _parse_format(value: str) -> tuple[str, dict[str, str]]:
    name, *options = value.split(";")
    opts = dict(opt.partition("=")[::2] for opt in options if "=" in opt)
    return name.strip().upper(), opts


def _int_field(text: str, what: str, where: str) -> int:
    try:
        number = int(text)
    except ValueError:
        raise RawFormatError(f"{where}: {what} {text!r} is not an integer") from None
    if not 0 < number <= 2048:
        raise RawFormatError(f"{where}: {what} {number} is outside 1..2048")
    return number


def _resolve(fields: dict[str, str], where: str) -> tuple[str, int, int]:
    """Format and geometry from the header keys, newest convention first."""
    fmt, width, height = None, None, None
    if "format" in fields:
        fmt, opts = _parse_format(fields["format"])
        width, height = opts.get("width"), opts.get("height")
    elif "evt" in fields:
        fmt = _LEGACY_EVT.get(fields["evt"].strip(), f"evt {fields['evt']}")
    if (width is None or height is None) and "geometry" in fields:
        width, _, height = fields["geometry"].lower().partition("x")
    known = _SYSTEM_IDS.get(fields.get("system_ID", "").strip())
    if fmt is None and known is not None:
        fmt = known[0]
    if (width is None or height is None) and known is not None:
        width, height = str(known[1]), str(known[2])
    if fmt is None:
        raise RawFormatError(
            f"{where}: the RAW header names no event format (no 'format', 'evt' or known 'system_ID' line)"
        )
    if fmt not in SUPPORTED_FORMATS:
        raise RawFormatError(f"{where}: event format {fmt!r} is not supported (supported: EVT3, EVT2)")
    if width is None or height is None:
        raise RawFormatError(
            f"{where}: the RAW header gives no sensor size (no 'format' size, 'geometry' or known 'system_ID')"
        )
    return fmt, _int_field(width, "width", where), _int_field(height, "height", where)


def parse_raw_header(data: bytes, path: str | None = None) -> RawHeader:
    """Parse the header at the start of ``data`` (the whole file or at least its header)."""
    fields, data_offset, _ = _split_header(bytes(data[:MAX_HEADER_BYTES]))
    fmt, width, height = _resolve(fields, path or "<bytes>")
    return RawHeader(format=fmt, width=width, height=height, fields=fields, data_offset=data_offset)


def read_raw_header(path: str | os.PathLike[str]) -> RawHeader:
    """Read only the header of a RAW file (FileNotFoundError when it does not exist)."""
    path = Path(path)
    with path.open("rb") as f:
        head = f.read(4096)
        while not _split_header(head)[2] and len(head) < MAX_HEADER_BYTES:
            more = f.read(65536)
            if not more:
                break
            head += more
    return parse_raw_header(head, str(path))


def format_raw_header(width: int, height: int, fmt: str = "EVT3", extra: dict[str, str] | None = None) -> bytes:
    """A header OpenEB reads: ``format``, legacy ``evt``, ``geometry``, extra lines, ``% end``."""
    fmt = fmt.upper()
    if fmt not in SUPPORTED_FORMATS:
        raise ValueError(f"cannot write format {fmt!r} (supported: EVT3, EVT2)")
    if not (0 < width <= 2048 and 0 < height <= 2048):
        raise ValueError(f"sensor size {width}x{height} is outside 1..2048")
    lines = {"evt": "3.0" if fmt == "EVT3" else "2.0", "format": f"{fmt};height={height};width={width}"}
    lines["geometry"] = f"{width}x{height}"
    for key, value in (extra or {}).items():
        if not key or " " in key or "\n" in key + value or key == "end":
            raise ValueError(f"header line {key!r} {value!r}: keys need no spaces, values no newlines")
        lines.setdefault(key, value)
    text = "".join(f"% {key} {value}\n" for key, value in lines.items()) + "% end\n"
    return text.encode("latin-1")
