"""What the store keeps, as plain values: no proto messages, no database rows, no file paths.

The websocket layer converts wire messages into these records; every ``SessionStore`` backend
takes and returns only them, so a backend can be swapped without touching ingest or the routes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from darkread.core.frame_record import FrameRecord

from ..errors import SessionOwnedError, SessionShapeError, StoreError, UnknownSessionError

Box = tuple[int, int, int, int]  # x0, y0, x1, y1

__all__ = [
    "GazeRecord", "PageBreak", "PageRecord", "SessionInfo", "SessionOwnedError", "SessionShapeError", "SessionSpec",
    "StoreError", "StoredFrame", "UnknownSessionError", "WriteResult",
]  # fmt: skip


@dataclass(frozen=True)
class SessionSpec:
    """What a stream says about itself when it opens (the ``hello``)."""

    session_id: str
    device_id: str
    mode: str  # "frames" (the cloud stitches) or "pages" (the glasses stitch)
    sensor: tuple[int, int]  # (width, height)
    fovea: tuple[int, int]  # (height, width)
    stream_id: str = ""  # the client's spool (its seq space); "" for a client that names none


def check_owner(spec: SessionSpec, stored: SessionSpec) -> None:
    """Raise unless ``spec`` may resume the stored session: same device, same stream (seq space),
    same mode and geometry (SessionOwnedError, SessionShapeError)."""
    if spec.device_id != stored.device_id:
        raise SessionOwnedError(f"session {spec.session_id!r} belongs to device {stored.device_id!r}")
    if spec.stream_id != stored.stream_id:
        raise SessionOwnedError(
            f"session {spec.session_id!r} belongs to another stream of {stored.device_id!r} (another spool, whose "
            "seqs would collide); use a new session id"
        )
    wanted, known = (spec.mode, tuple(spec.sensor), tuple(spec.fovea)), (stored.mode, stored.sensor, stored.fovea)
    if wanted != known:
        raise SessionShapeError(
            f"session {spec.session_id!r} is {known[0]} with sensor {known[1]} and fovea {known[2]}; hello says "
            f"{wanted[0]} with sensor {wanted[1]} and fovea {wanted[2]}"
        )


@dataclass(frozen=True)
class SessionInfo:
    session_id: str
    device_id: str
    mode: str
    sensor: tuple[int, int]  # (width, height)
    fovea: tuple[int, int]  # (height, width)
    created_s: float
    updated_s: float
    last_seq: int  # highest seq stored, -1 if none
    frames: int
    pages: int


@dataclass(frozen=True)
class StoredFrame(FrameRecord):
    """The frame record as a session stored it: the seq it arrived under, and what the glasses
    said besides (gaze angles, events used). The stitcher reads it as a ``FrameRecord``."""

    seq: int = 0
    gaze_rad: tuple[float, float] = (0.0, 0.0)
    events_used: int = 0


@dataclass(frozen=True)
class PageRecord:
    """A page stitched on the glasses (black text on white) and its line boxes."""

    seq: int
    page_id: int
    t_us: int
    mask: np.ndarray = field(repr=False)  # uint8 ink mask, ink = 1
    lines: tuple[Box, ...] = ()


@dataclass(frozen=True)
class GazeRecord:
    """A batch of gaze samples the glasses sent beside the frames."""

    seq: int
    t_us: tuple[int, ...]
    px: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class WriteResult:
    stored: bool  # False for a duplicate seq
    last_seq: int  # highest seq durably stored for the session (the cumulative ack)


@dataclass(frozen=True)
class PageBreak:
    """The glasses' explicit "new page": frames after ``seq`` belong to a new page."""

    seq: int
    t_us: int
