"""A calibration capture on disk and the pairing of its event bursts with RGB frames.

A capture is a directory with ``events.raw`` (the event camera watching a flashing board),
``board.json`` (the board, see ``markers.BoardSpec``), optionally ``rgb_frames.csv`` with the RGB
camera's frames (device-clock exposure middles) and a ``calibration.json`` with what is known so far.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np

from darkread.edge.calibrate.clock import RgbFrames
from darkread.edge.calibrate.event_image import (
    Burst,
    burst_events,
    detection_image,
    latency_image,
)
from darkread.edge.calibrate.markers import (
    BOARD_NAME,
    BoardSpec,
    Detection,
    detect_board,
    load_board,
)
from darkread.edge.errors import CalibrationError
from darkread.edge.io.raw import read_raw

logger = logging.getLogger(__name__)

RGB_FRAMES_NAME = "rgb_frames.csv"


@dataclass
class CaptureEvents:
    events: np.ndarray
    triggers: np.ndarray
    width: int
    height: int


def raw_path_of(path: str | Path) -> Path:
    path = Path(path)
    raw = path / "events.raw" if path.is_dir() else path
    if not raw.is_file():
        raise CalibrationError(f"{raw}: no event stream (expected a capture directory with events.raw, or a .raw file)")
    return raw


def read_capture_events(path: str | Path) -> CaptureEvents:
    """All events and triggers of a capture (captures are seconds long, so they are read whole)."""

    data = read_raw(raw_path_of(path))
    return CaptureEvents(data.events, data.triggers, int(data.header.width), int(data.header.height))


def board_of(path: str | Path, board: str | Path | None) -> BoardSpec:
    path = Path(path)
    return load_board(board if board is not None else (path if path.is_dir() else path.parent) / BOARD_NAME)


def shown_intervals(bursts: list[Burst]) -> list[tuple[float, float]]:
    """(appear, disappear) onsets on the event clock: an OFF burst followed by an ON burst."""
    out = []
    for a, b in pairwise(bursts):
        if a.polarity == 0 and b.polarity == 1:
            out.append((a.onset_us, b.onset_us))
    return out


def paired_views(
    events: np.ndarray,
    bursts: list[Burst],
    frames: RgbFrames,
    offset_us: float,
    spec: BoardSpec,
    width: int,
    height: int,
    *,
    margin_us: float = 3000.0,
) -> list[tuple[Detection, Detection]]:
    """(event detection, RGB detection) per shown interval: the appear burst's image and an RGB frame
    exposed entirely while the board was shown (found with the clock offset ``offset_us``)."""
    pairs = []
    by_onset = {b.onset_us: b for b in bursts}
    for on, off in shown_intervals(bursts):
        lo, hi = on - offset_us + margin_us, off - offset_us - margin_us
        inside = np.flatnonzero((frames.t_us - frames.exposure_us / 2 > lo) & (frames.t_us + frames.exposure_us / 2 < hi))
        if inside.size == 0:
            logger.info("no RGB frame fully inside the shown interval at %.0f us", on)
            continue
        rgb_det = None
        for k in sorted(inside.tolist(), key=lambda i: abs(i - inside.mean())):
            rgb_det = detect_board(frames.images[k], spec)
            if rgb_det is not None:
                break
        ev_det = detect_board(detection_image(burst_events(events, by_onset[on]), width, height), spec)
        if rgb_det is None or ev_det is None:
            logger.info("board not found in %s at %.0f us", "RGB" if rgb_det is None else "events", on)
            continue
        pairs.append((ev_det, rgb_det))
    return pairs


def page_view(
    events: np.ndarray,
    bursts: list[Burst],
    frames: RgbFrames,
    offset_us: float,
    spec: BoardSpec,
    width: int,
    height: int,
    *,
    settle_us: float = 100_000.0,
) -> tuple[Detection, Detection]:
    """Markers printed on a page, seen when a lamp is switched on (the first ON burst) and in the
    first RGB frame exposed ``settle_us`` or more after it (device clock via ``offset_us``)."""
    lamp = next((b for b in bursts if b.polarity == 1), None)
    if lamp is None:
        raise CalibrationError("no burst of ON events (a lamp switched on) in the stream")
    event_det = detect_board(latency_image(events, width, height, lamp.onset_us - 200.0), spec, min_corners=4)
    after = np.flatnonzero(frames.t_us - frames.exposure_us / 2 >= lamp.onset_us - offset_us + settle_us)
    candidates = after if after.size else np.arange(len(frames))
    rgb_det = None
    for k in candidates[:10]:
        rgb_det = detect_board(frames.images[k], spec, min_corners=4)
        if rgb_det is not None:
            break
    if event_det is None or rgb_det is None:
        raise CalibrationError(f"page markers not found in the {'events' if event_det is None else 'RGB frames'}")
    return event_det, rgb_det
