"""Errors raised on the glasses side: recordings, the event camera, the model.

They sit under ``DarkreadError``; the whole tree is drawn in ``darkread/core/errors.py``.
"""

from __future__ import annotations

from darkread.core.errors import DarkreadError


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


class ImuCsvError(RecordingError):
    """A head-motion (IMU) CSV that cannot be read."""


class CalibrationError(RecordingError):
    """A calibration file that cannot be used."""


class DeviceError(DarkreadError):
    """The event camera cannot be opened or misbehaves."""


class CloudRefusedError(DarkreadError, ConnectionError):
    """The cloud answered with a fatal error (``code``, ``message``); a ConnectionError too, so
    code that handles a lost connection sees it."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(f"cloud error {code}: {message}")
        self.code = code
        self.message = message


class ModelError(DarkreadError):
    """The reconstruction model cannot be loaded or run."""


class RunError(DarkreadError):
    """The edge daemon could not do its job; the message says why (frames stay in the spool)."""


class UndeliveredError(RunError):
    """The run ended with messages the cloud never acknowledged: the message says how many, why,
    and whether they wait in the spool for the next start or were lost with an in-memory spool."""

    exit_code = 3


class SpoolError(DarkreadError):
    """The spool cannot be opened or written (read-only or full disk, no permission, held by
    another edge); the message names the spool and the cause. Every failed write was rolled back."""

    exit_code = 4
