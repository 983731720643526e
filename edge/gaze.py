"""Gaze (Aria device clock, CPF angles) -> event-camera pixel (event clock).

The gaze point is ``depth`` metres along the gaze direction in CPF, moved into the event camera
with ``T_event_cpf`` and projected with the camera's radtan model. Depth matters: the camera sits a
few centimetres from the eyes, so a wrong depth shifts the pixel by parallax. Rows without a depth
use a reading-distance prior (0.45 m), not Aria's 1 m default, which is too far for a page.

Gaze samples are interpolated linearly (angles and depth) to each event time. Any event time
without a usable gaze gives NaN: before the first / after the last valid sample, between two valid
samples more than ``max_gap_us`` apart (blink rows are invalid, so a blink opens such a gap), or a
gaze point that projects off the sensor or behind the camera.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from darkread.edge.io.calibration import Calibration
from darkread.edge.io.gaze_csv import GazeTrack

READING_DEPTH_PRIOR_M = 0.45


@dataclass(frozen=True)
class GazeSample:
    """Where the wearer looks at one event time: the event-camera pixel and the CPF angles."""

    pixel: tuple[float, float]  # (u, v) event-camera pixel, on the sensor
    angles: tuple[float, float]  # (yaw, pitch) radians, projection convention


class GazeLookup(Protocol):
    """Where the wearer looks at an event time (a recorded track or a live feed); the pipeline's only question."""

    def at(self, t_event_us: int) -> GazeSample | None:
        """The gaze at ``t_event_us`` (event clock), or None without a usable gaze on the sensor."""
        ...

    def rows(self, t0_event_us: int, t1_event_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracker's own rows with event time in (t0, t1]: (t_event_us, yaw, pitch) in radians,
        NaN for invalid rows; the on-change mode classifies them into fixations, saccades, blinks."""
        ...


def gaze_point_cpf(yaw_rad: np.ndarray, pitch_rad: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """(N, 3) CPF points ``depth`` along normalise(tan yaw, tan pitch, 1); negative depth -> origin."""
    yaw, pitch, depth = np.broadcast_arrays(
        np.asarray(yaw_rad, dtype=np.float64), np.asarray(pitch_rad, dtype=np.float64), np.asarray(depth_m, dtype=np.float64)
    )
    direction = np.stack([np.tan(yaw), np.tan(pitch), np.ones(yaw.shape)], axis=-1)
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    return direction * np.where(depth < 0, 0.0, depth)[..., None]


def project_gaze(calibration: Calibration, yaw: np.ndarray, pitch: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(N, 2) event pixels of gaze points; NaN rows off the sensor (or without a gaze)."""
    uv = calibration.project(calibration.cpf_to_event(gaze_point_cpf(yaw, pitch, depth)))
    uv[~calibration.on_sensor(uv)] = np.nan
    return uv


def gaze_sample(calibration: Calibration, yaw: float, pitch: float, depth: float) -> GazeSample | None:
    """One gaze (angles and depth) as a :class:`GazeSample`; None when it misses the sensor.

    ``project_gaze`` for one gaze in plain floats (same arithmetic, same pixel): the pipeline asks
    at every inference, and thirty numpy calls on one-element arrays cost ~50x the arithmetic."""
    tx, ty = math.tan(yaw), math.tan(pitch)
    norm = math.sqrt(tx * tx + ty * ty + 1.0)
    d = 0.0 if depth < 0 else float(depth)
    point = calibration.cpf_to_event(np.array([[tx / norm * d, ty / norm * d, 1.0 / norm * d]]))[0].tolist()
    uv = calibration.project_point(*point)
    if uv is None or not calibration.point_on_sensor(*uv):
        return None
    return GazeSample(pixel=(float(uv[0]), float(uv[1])), angles=(float(yaw), float(pitch)))


def rows_between(
    t_us: np.ndarray, yaw: np.ndarray, pitch: np.ndarray, t0: int, t1: int, times: list[int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows with ``t0 < t <= t1`` of time-sorted arrays (views, no copies).

    ``times`` (``t_us`` as a list) finds them by ``bisect``: the on-change mode asks every 5 ms of
    events, mostly for no row at all, and two ``np.searchsorted`` calls cost ten times as much."""
    if times is not None:
        i0, i1 = bisect.bisect_right(times, t0), bisect.bisect_right(times, t1)
    else:
        i0, i1 = int(np.searchsorted(t_us, t0, side="right")), int(np.searchsorted(t_us, t1, side="right"))
    return t_us[i0:i1], yaw[i0:i1], pitch[i0:i1]


class GazeMapper:
    """Where the wearer looks, in event pixels, at any event timestamp (vectorised)."""

    def __init__(
        self,
        calibration: Calibration,
        track: GazeTrack,
        *,
        depth_prior_m: float = READING_DEPTH_PRIOR_M,
        max_gap_us: int = 50_000,
        clock_offset_us: int | None = None,
    ) -> None:
        if depth_prior_m <= 0:
            raise ValueError(f"depth_prior_m must be positive, got {depth_prior_m}")
        self.calibration = calibration
        self.track = track
        self.depth_prior_m = float(depth_prior_m)
        self.max_gap_us = int(max_gap_us)
        self.clock_offset_us = int(
            calibration.gaze_to_event_time_offset_us if clock_offset_us is None else clock_offset_us
        )
        keep = track.valid
        self._t = track.t_us[keep].astype(np.int64)
        self._t_list: list[int] = self._t.tolist()
        self._yaw = track.yaw_rad[keep]
        self._pitch = track.pitch_rad[keep]
        depth = track.depth_m[keep]
        self._depth = np.where(np.isfinite(depth) & (depth > 0), depth, self.depth_prior_m)
        # every row on the event clock, invalid ones (blinks) as NaN: what the gaze-event classifier reads
        self._rows_t = track.t_us.astype(np.int64) + self.clock_offset_us
        self._rows_t_list: list[int] = self._rows_t.tolist()
        self._rows_yaw = np.where(track.valid, track.yaw_rad, np.nan)
        self._rows_pitch = np.where(track.valid, track.pitch_rad, np.nan)
        period = float(np.median(np.diff(self._rows_t))) if self._rows_t.shape[0] > 1 else 0.0
        self.rate_hz = 1e6 / period if period > 0 else 60.0

    def rows(self, t0_event_us: int, t1_event_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracker's rows with event time in (t0, t1]: (t_event_us, yaw, pitch), NaN when invalid."""
        return rows_between(self._rows_t, self._rows_yaw, self._rows_pitch, t0_event_us, t1_event_us, self._rows_t_list)

    def angles_and_depth_at(self, t_event_us: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Interpolated (yaw, pitch, depth) per event time; NaN where no usable gaze."""
        t_device = np.asarray(t_event_us, dtype=np.int64).reshape(-1) - self.clock_offset_us
        n_samples = self._t.shape[0]
        if n_samples == 0:
            nan = np.full(t_device.shape[0], np.nan)
            return nan, nan.copy(), nan.copy()
        after = np.searchsorted(self._t, t_device, side="right")
        left = np.clip(after - 1, 0, n_samples - 1)
        right = np.clip(after, 0, n_samples - 1)
        t_left, t_right = self._t[left], self._t[right]
        gap = t_right - t_left
        usable = (t_device >= self._t[0]) & (t_device <= self._t[-1]) & (gap <= self.max_gap_us)
        weight = np.where(gap > 0, (t_device - t_left) / np.maximum(gap, 1), 0.0)

        def lerp(values: np.ndarray) -> np.ndarray:
            out = values[left] + weight * (values[right] - values[left])
            return np.where(usable, out, np.nan)

        return lerp(self._yaw), lerp(self._pitch), lerp(self._depth)

    def pixels_at(self, t_event_us: np.ndarray) -> np.ndarray:
        """(N, 2) float64 event pixels (x, y); NaN rows where no valid gaze or off the sensor."""
        return project_gaze(self.calibration, *self.angles_and_depth_at(t_event_us))

    def at(self, t_event_us: int) -> GazeSample | None:
        """The gaze at one event time: ``angles_and_depth_at`` and ``project_gaze`` of one time, in
        plain floats (the same arithmetic)."""
        t = int(t_event_us) - self.clock_offset_us
        times = self._t_list
        if not times or not times[0] <= t <= times[-1]:
            return None
        right = bisect.bisect_right(times, t)  # times[right - 1] <= t < times[right]
        left, right = right - 1, min(right, len(times) - 1)
        gap = times[right] - times[left]
        if gap > self.max_gap_us:
            return None
        w = (t - times[left]) / max(gap, 1) if gap > 0 else 0.0
        yaw, pitch, depth = (float(v[left] + w * (v[right] - v[left])) for v in (self._yaw, self._pitch, self._depth))
        if math.isnan(yaw):
            return None
        return gaze_sample(self.calibration, yaw, pitch, depth)

    def event_time_range(self) -> tuple[int, int] | None:
        """First and last valid gaze sample on the event clock."""
        if self._t.shape[0] == 0:
            return None
        return int(self._t[0] + self.clock_offset_us), int(self._t[-1] + self.clock_offset_us)
