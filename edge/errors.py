"""Errors raised on the glasses side, in one place.

    DarkreadError
     ├── RecordingError            a recording (directory or file) cannot be used
     │    ├── RawFormatError       RAW header unknown or inconsistent
     │    ├── CorruptRawError      bytes that cannot be decoded (names file and byte offset)
     │    ├── GazeCsvError         eye-gaze CSV missing columns or malformed (names file and line)
     │    └── CalibrationError     calibration.json missing keys or impossible values
     ├── DeviceError               the event camera cannot be opened or answers wrongly
     ├── ModelError                the ONNX model is missing or has the wrong shape
     └── RunError                  the edge ran but failed: the cloud refused the stream, the
                                   replay or reconstruction loop crashed, a replay made no frames

Built-in exceptions are used where their meaning fits (FileNotFoundError, ValueError for bad
arguments).
"""

from __future__ import annotations


class DarkreadError(Exception):
    """Base of every darkread error."""


class RecordingError(DarkreadError):
    """A recording cannot be read."""


class RawFormatError(RecordingError):
    """The RAW header names no format we decode, or contradicts itself."""


class CorruptRawError(RecordingError):
    """Undecodable RAW bytes; ``path`` and ``offset`` say where."""

    def __init__(self, message: str, path: str | None = None, offset: int | None = None) -> None:
        where = f"{path or '<bytes>'}" + (f" at byte {offset}" if offset is not None else "")
        super().__init__(f"{where}: {message}")
        self.path = path
        self.offset = offset


class GazeCsvError(RecordingError):
    """An eye-gaze CSV that cannot be read."""


class CalibrationError(RecordingError):
    """A calibration file that cannot be used."""


class DeviceError(DarkreadError):
    """The event camera cannot be opened or misbehaves."""


class ModelError(DarkreadError):
    """The reconstruction model cannot be loaded or run."""


class RunError(DarkreadError):
    """The edge daemon could not do its job; the message says why (frames stay in the spool)."""
