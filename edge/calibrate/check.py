"""A picture that shows at a glance whether a calibration is right: the gaze track over the events.

Events of the whole recording are accumulated (log-scaled grey, median-filtered against noise);
the gaze samples are projected with the calibration under test and drawn as a line coloured by
time (blue at the start, red at the end). With a right calibration a reader's gaze runs along the
text lines; a wrong pose shifts or tilts the track off the text, a wrong clock smears it across
lines when the head moves. ``on_text_fraction`` puts a number on it: the share of gaze samples
whose neighbourhood holds more events than the median of the area the track covers. An inset
plots the correlation of event activity with gaze speed against a shift of the clock offset: with
head motion, a right clock peaks at zero shift (too little head motion gives a flat, weak curve).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from darkread.edge.calibrate.clock import ActivityCounter, RefineResult, refine_offset
from darkread.edge.calibrate.event_image import count_image, denoise
from darkread.edge.errors import CalibrationError
from darkread.edge.gaze import GazeMapper
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.gaze_csv import GazeTrack


@dataclass
class CheckResult:
    n_gaze: int  # gaze samples drawn (valid, on the sensor)
    on_text_fraction: float
    picture: np.ndarray  # BGR uint8
    clock: RefineResult | None = None  # event activity vs gaze speed against a clock shift

    def to_dict(self) -> dict:
        out: dict = {"n_gaze": self.n_gaze, "on_text_fraction": self.on_text_fraction}
        if self.clock is not None:
            out["clock_peak_shift_us"] = self.clock.correction_us
            out["clock_peak_correlation"] = self.clock.peak_correlation
        return out


def gaze_track_pixels(calibration: Calibration, track: GazeTrack) -> tuple[np.ndarray, np.ndarray]:
    """(event-clock times, pixels) of every valid gaze sample projected with ``calibration``."""

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


def accumulate(chunks: Iterable[np.ndarray], width: int, height: int, activity: ActivityCounter | None = None) -> np.ndarray:
    """Events per pixel over a stream of event chunks (bounded memory); optionally events per time bin."""
    total = np.zeros((height, width), dtype=np.float32)
    for events in chunks:
        total += count_image(events, width, height)
        if activity is not None:
            activity.add(events["t"])
    return total


def clock_curve(activity: ActivityCounter, calibration: Calibration, track: GazeTrack) -> RefineResult | None:
    """Correlation of event activity with gaze speed against a shift of the clock offset, or None."""
    t_event, pixels = gaze_track_pixels(calibration, track)
    try:
        return refine_offset(activity, t_event - calibration.gaze_to_event_time_offset_us, pixels,
                             float(calibration.gaze_to_event_time_offset_us))
    except CalibrationError:
        return None


def draw_clock_inset(picture: np.ndarray, curve: RefineResult) -> None:
    """Bottom-right panel: correlation vs clock shift; a right clock peaks at 0 (white line)."""
    h, w = picture.shape[:2]
    pw, ph = 360, 130
    x0, y0 = w - pw - 10, h - ph - 10
    cv2.rectangle(picture, (x0, y0), (x0 + pw, y0 + ph), (40, 40, 40), -1)
    lags, corr = curve.lags_us, curve.correlation
    ok = np.isfinite(corr)
    if ok.sum() < 2:
        return
    lo, hi = float(np.nanmin(corr)), float(np.nanmax(corr))
    span = max(hi - lo, 1e-6)
    px = x0 + 10 + (lags[ok] - lags[0]) / (lags[-1] - lags[0]) * (pw - 20)
    py = y0 + ph - 30 - (corr[ok] - lo) / span * (ph - 50)
    cv2.polylines(picture, [np.stack([px, py], 1).round().astype(np.int32).reshape(-1, 1, 2)], False, (0, 200, 255), 1, cv2.LINE_AA)
    zero = round(x0 + 10 + (0 - lags[0]) / (lags[-1] - lags[0]) * (pw - 20))
    cv2.line(picture, (zero, y0 + 15), (zero, y0 + ph - 30), (255, 255, 255), 1)
    peak = round(x0 + 10 + (curve.correction_us - lags[0]) / (lags[-1] - lags[0]) * (pw - 20))
    cv2.line(picture, (peak, y0 + 15), (peak, y0 + ph - 30), (0, 255, 255), 1)
    judged = "" if curve.peak_correlation >= 0.3 else " (weak: too little head motion)"
    cv2.putText(picture, f"clock shift {lags[0] / 1e3:+.0f}..{lags[-1] / 1e3:+.0f} ms: peak {curve.correction_us / 1e3:+.1f} ms",
                (x0 + 8, y0 + ph - 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (220, 220, 220), 1, cv2.LINE_AA)
    cv2.putText(picture, f"event rate vs gaze speed r={curve.peak_correlation:.2f}{judged}", (x0 + 8, y0 + 12),
                cv2.FONT_HERSHEY_SIMPLEX, 0.4, (220, 220, 220), 1, cv2.LINE_AA)


def render_check(
    events: np.ndarray | Iterable[np.ndarray], calibration: Calibration, track: GazeTrack, *, title: str = ""
) -> CheckResult:
    """The check picture and its on-text score; ``events`` is one array or an iterable of chunks."""
    w, h = calibration.width, calibration.height
    chunks = [events] if isinstance(events, np.ndarray) else events
    activity = ActivityCounter()
    density = denoise(accumulate(chunks, w, h, activity))
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
    curve = clock_curve(activity, calibration, track)
    if curve is not None:
        draw_clock_inset(picture, curve)
    label = f"{title}  gaze on text: {score:.0%} of {n} samples".strip()
    cv2.putText(picture, label, (12, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 255, 0), 2, cv2.LINE_AA)
    return CheckResult(n, score, picture, curve)


def write_check_png(path: str | Path, result: CheckResult) -> None:
    if not cv2.imwrite(str(path), result.picture):
        raise ValueError(f"could not write {path} (use a .png name in an existing folder)")
