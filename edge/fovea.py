"""Foveation: keep only the events in a 100 x 200 (rows x cols) window around the gaze.

Reading needs a few words around the fixation, not the whole sensor; dropping the rest cuts the
event rate (typically by three quarters on a page) before anything expensive runs. Cropped events
keep their sensor coordinates; the voxel grid makes them window-relative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, Events

BYTES_PER_EVENT = EVENT_CD_DTYPE.itemsize


@dataclass(frozen=True)
class FoveaConfig:
    height: int = 100
    width: int = 200


def window_origins(centers_xy: np.ndarray, sensor_wh: tuple[int, int], cfg: FoveaConfig = FoveaConfig()) -> np.ndarray:
    """(N, 2) window origins (x0, y0) for (N, 2) gaze pixels, clamped inside the sensor; NaN stays NaN.

    The gaze pixel is rounded to the nearest pixel, which becomes pixel (width // 2, height // 2) of
    the window. A sensor smaller than the window gives origin 0 on that axis.
    """
    centers = np.asarray(centers_xy, dtype=np.float64).reshape(-1, 2)
    size = np.array([cfg.width, cfg.height], dtype=np.float64)
    upper = np.maximum(np.asarray(sensor_wh, dtype=np.float64) - size, 0.0)
    origin = np.floor(centers + 0.5) - size // 2
    return np.clip(origin, 0.0, upper)  # np.clip keeps NaN


def window_origin(
    center_xy: tuple[float, float], sensor_wh: tuple[int, int], cfg: FoveaConfig = FoveaConfig()
) -> tuple[int, int]:
    """(x0, y0) of the window centred on the gaze pixel, clamped inside the sensor."""
    origin = window_origins(np.array([center_xy], dtype=np.float64), sensor_wh, cfg)[0]
    if not np.all(np.isfinite(origin)):
        raise ValueError(f"gaze centre {center_xy} is not a finite pixel")
    return int(origin[0]), int(origin[1])


def crop(events: Events, x0: int, y0: int, cfg: FoveaConfig = FoveaConfig()) -> Events:
    """Events inside [x0, x0 + width) x [y0, y0 + height), sensor coordinates kept (a copy).

    Subtracting the origin in uint16 wraps coordinates left of / above the window to large values,
    so one comparison per axis tests both bounds.
    """
    if x0 < 0 or y0 < 0:
        raise ValueError(f"window origin must be non-negative, got ({x0}, {y0})")
    dx = events["x"] - np.uint16(x0)
    dy = events["y"] - np.uint16(y0)
    return events[(dx < cfg.width) & (dy < cfg.height)]


def crop_along_track(events: Events, origins_xy: np.ndarray, cfg: FoveaConfig = FoveaConfig()) -> Events:
    """Events inside their own window: ``origins_xy[i]`` is the origin for ``events[i]``.

    For offline foveation with a moving gaze; events whose origin is NaN (no gaze) are dropped.
    """
    origins = np.asarray(origins_xy, dtype=np.float64).reshape(-1, 2)
    if origins.shape[0] != events.shape[0]:
        raise ValueError(f"{origins.shape[0]} origins for {events.shape[0]} events")
    dx = events["x"] - origins[:, 0]
    dy = events["y"] - origins[:, 1]
    inside = (dx >= 0) & (dx < cfg.width) & (dy >= 0) & (dy < cfg.height)  # NaN compares False
    return events[inside]


@dataclass
class FoveaCounter:
    """Events (and their in-memory bytes, 16 B per EventCD) entering and leaving foveation.

    Bytes are those of the decoded event arrays, not of the EVT3 stream (~2-4 B per event).
    """

    events_in: int = 0
    events_out: int = 0

    def add(self, n_in: int, n_out: int) -> None:
        self.events_in += int(n_in)
        self.events_out += int(n_out)

    @property
    def bytes_in(self) -> int:
        return self.events_in * BYTES_PER_EVENT

    @property
    def bytes_out(self) -> int:
        return self.events_out * BYTES_PER_EVENT

    @property
    def kept_fraction(self) -> float:
        return self.events_out / self.events_in if self.events_in else 0.0
