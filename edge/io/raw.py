"""Prophesee RAW files: read whole, stream in bounded memory, write.

``read_raw`` decodes a whole file; ``RawReader`` decodes it chunk by chunk (the decoder carries its
state across chunk boundaries, so the concatenated chunks equal the whole-file decode);
``write_raw`` writes an EVT 3.0 file with a header OpenEB and Metavision read. Times are absolute
sensor time (unshifted) unless ``time_shift=True`` asks for OpenEB's default shift.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE, Events
from darkread.edge.io.evt2 import Evt2Decoder
from darkread.edge.io.evt3 import DecodeStats, Evt3Decoder, Triggers
from darkread.edge.io.evt3_encode import encode_evt3_parts
from darkread.edge.io.raw_header import RawHeader, format_raw_header, parse_raw_header, read_raw_header

__all__ = ["RawData", "RawReader", "make_decoder", "read_raw", "write_raw"]


@dataclass
class RawData:
    events: Events
    triggers: Triggers
    header: RawHeader
    stats: DecodeStats


def make_decoder(
    header: RawHeader,
    *,
    path: str | None = None,
    time_shift: bool = False,
    strict: bool = False,
    y_range: tuple[int, int] | None = None,
) -> Evt3Decoder | Evt2Decoder:
    """The streaming decoder for ``header``'s format and sensor size."""
    cls = Evt3Decoder if header.format == "EVT3" else Evt2Decoder
    return cls(
        header.width,
        header.height,
        time_shift=time_shift,
        path=path,
        y_range=y_range,
        strict=strict,
        byte_offset=header.data_offset,
    )


def read_raw(path: str | os.PathLike[str], *, time_shift: bool = False, strict: bool = False) -> RawData:
    """Decode a whole RAW file (FileNotFoundError, RawFormatError, or CorruptRawError when strict)."""
    path = Path(path)
    data = path.read_bytes()
    header = parse_raw_header(data, str(path))
    decoder = make_decoder(header, path=str(path), time_shift=time_shift, strict=strict)
    events, triggers = decoder.decode(memoryview(data)[header.data_offset :])
    decoder.finish()
    return RawData(events, triggers, header, decoder.stats)


class RawReader:
    """Streaming reader: iterate to get decoded chunks; memory stays bounded by ``chunk_bytes``.

    Triggers seen so far are in ``.triggers``; ``.stats`` counts what was decoded and skipped.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_bytes: int = 1 << 20,
        time_shift: bool = False,
        strict: bool = False,
    ) -> None:
        if chunk_bytes < 1:
            raise ValueError(f"chunk_bytes must be positive, got {chunk_bytes}")
        self.path = Path(path)
        self.header = read_raw_header(self.path)
        self.chunk_bytes = chunk_bytes
        self._time_shift, self._strict = time_shift, strict
        self._decoder = self._new_decoder()
        self.stats: DecodeStats = self._decoder.stats
        self._triggers: list[Triggers] = []
        self._started = False
        self._roi: tuple[int, int, int, int] | None = None
        self.roi_since_us: int | None = None  # the first event decoded under the current ROI (None: none yet)

    def _new_decoder(self) -> Evt3Decoder | Evt2Decoder:
        return make_decoder(self.header, path=str(self.path), time_shift=self._time_shift, strict=self._strict)

    @property
    def triggers(self) -> Triggers:
        return np.concatenate(self._triggers, dtype=TRIGGER_DTYPE) if self._triggers else np.zeros(0, TRIGGER_DTYPE)

    def get_size(self) -> tuple[int, int]:
        """(height, width), as OpenEB's readers report it."""
        return self.header.height, self.header.width

    def set_roi(self, roi: tuple[int, int, int, int] | None) -> None:
        """Deliver only the events inside ``roi`` (x0, y0, width, height) from the next chunk on
        (None: all); the words skipped are counted in ``stats.words_outside_roi``."""
        self._decoder.set_roi(roi)
        self._roi = self._decoder.roi
        self.roi_since_us = None

    def __iter__(self) -> Iterator[Events]:
        """Decode from the start of the data; iterating again starts over with fresh counters."""
        if self._started:
            self._decoder = self._new_decoder()
            self._decoder.set_roi(self._roi)
            self.stats, self._triggers = self._decoder.stats, []
        self._started = True
        with self.path.open("rb") as f:
            f.seek(self.header.data_offset)
            while chunk := f.read(self.chunk_bytes):
                events, triggers = self._decoder.decode(chunk)
                if len(triggers):
                    self._triggers.append(triggers)
                if len(events):
                    if self.roi_since_us is None:
                        self.roi_since_us = int(events["t"][0])
                    yield events
        self._decoder.finish()


def write_raw(
    path: str | os.PathLike[str],
    events: Events,
    *,
    width: int = 1280,
    height: int = 720,
    triggers: Triggers | None = None,
    header_extra: dict[str, str] | None = None,
) -> int:
    """Write an EVT 3.0 RAW file; returns the number of bytes written. The events are encoded and
    written a part at a time (``encode_evt3_parts``): a long recording's encoding held whole would
    cost several times the events' own memory."""
    if events.dtype != EVENT_CD_DTYPE:
        raise ValueError(f"events must have EVENT_CD_DTYPE, got {events.dtype}")
    if len(events) and events["y"].max() >= height:
        raise ValueError(f"event y must be < height ({height})")
    parts = encode_evt3_parts(events, triggers, width=width)
    first = next(parts, b"")  # (the events are checked here, before the file is opened)
    with open(path, "wb") as f:
        written = f.write(format_raw_header(width, height, "EVT3", header_extra)) + f.write(first)
        for part in parts:
            written += f.write(part)
    return written
