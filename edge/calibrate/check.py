"""A picture that shows at a glance whether a calibration is right: the gaze track over the events.

Events of the whole recording are accumulated (log-scaled grey, median-filtered against noise);
the gaze samples are projected with the calibration under test and drawn as a line coloured by
time (blue at the start, red at the end). With a right calibration a reader's gaze runs along the
text lines; a wrong pose shifts or tilts the track off the text, a wrong clock smears it across
lines when the head moves. ``on_text_fraction`` puts a number on it: the share of gaze samples
whose neighbourhood holds more events than the median of the area the track covers.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from darkread.edge.calibrate.event_image import count_image, denoise
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.gaze_csv import GazeTrack


@dataclass
class CheckResult:
    n_gaze: int  # gaze samples drawn (valid, on the sensor)
    on_text_fraction: float
    picture: np.ndarray  # BGR uint8

    def to_dict(self) -> dict:
        return {"n_gaze": self.n_gaze, "on_text_fraction": self.on_text_fraction}


def gaze_track_pixels(calibration: Calibration, track: GazeTrack) -> tuple[np.ndarray, np.ndarray]:
    """(event-clock times, pixels) of every valid gaze sample projected with ``calibration``."""
    from darkread.edge.gaze import GazeMapper

    mapper = GazeMapper(calibration, track)
    t_event = track.t_us[track.valid].astype(np.int64) + mapper.clock_offset_us
    return t_event, mapper.pixels_at(t_event)


def on_text_fraction(density: np.ndarray, pixels: np.ndarray, *, radius_px: int = 12) -> float:
    """Share of gaze pixels whose neighbourhood holds more events than the typical place near the track."""
    ok = np.isfinite(pixels).all(axis=1)
    if not ok.any():
        return 0.0
    blurred = cv2.blur(density.astype(np.float32), (2 * radius_px + 1, 2 * radius_px + 1))
    h, w = density.shape
    uv = np.round(pixels[ok]).astype(int)
    uv[:, 0] = np.clip(uv[:, 0], 0, w - 1)
    uv[:, 1] = np.clip(uv[:, 1], 0, h - 1)
    at_gaze = blurred[uv[:, 1], uv[:, 0]]
    x0, y0 = np.maximum(uv.min(axis=0) - 100, 0)
    x1, y1 = uv.max(axis=0) + 100
    around = blurred[y0:y1, x0:x1]
    return float(np.mean(at_gaze > np.median(around)))


def accumulate(chunks: Iterable[np.ndarray], width: int, height: int) -> np.ndarray:
    """Events per pixel over a stream of event chunks (bounded memory)."""
    total = np.zeros((height, width), dtype=np.float32)
    for events in chunks:
        total += count_image(events, width, height)
    return total


def render_check(
    events: np.ndarray | Iterable[np.ndarray], calibration: Calibration, track: GazeTrack, *, title: str = ""
) -> CheckResult:
    """The check picture and its on-text score; ``events`` is one array or an iterable of chunks."""
    w, h = calibration.width, calibration.height
    chunks = [events] if isinstance(events, np.ndarray) else events
    density = denoise(accumulate(chunks, w, h))
    scale = np.log1p(density)
    top = np.percentile(scale[scale > 0], 99.5) if np.any(scale > 0) else 1.0
    grey = np.clip(scale / top * 255, 0, 255).astype(np.uint8)
    picture = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    _, pixels = gaze_track_pixels(calibration, track)
    ok = np.isfinite(pixels).all(axis=1)
    pts = pixels[ok]
    n = pts.shape[0]
    for i in range(1, n):  # a few hundred segments
        a = tuple(np.round(pts[i - 1]).astype(int))
        b = tuple(np.round(pts[i]).astype(int))
        frac = i / max(n - 1, 1)
        colour = (int(255 * (1 - frac)), 80, int(255 * frac))
        cv2.line(picture, a, b, colour, 1, cv2.LINE_AA)
    for p in pts[:: max(1, n // 60)]:
        cv2.circle(picture, tuple(np.round(p).astype(int)), 3, (0, 255, 255), 1, cv2.LINE_AA)
    score = on_text_fraction(density, pixels)
    label = f"{title}  gaze on text: {score:.0%} of {n} samples".strip()
    cv2.putText(picture, label, (12, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 255, 0), 2, cv2.LINE_AA)
    return CheckResult(n, score, picture)


def write_check_png(path: str | Path, result: CheckResult) -> None:
    if not cv2.imwrite(str(path), result.picture):
        raise ValueError(f"could not write {path} (use a .png name in an existing folder)")
