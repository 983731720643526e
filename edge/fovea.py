"""Foveation: keep only the events in a window (rows x cols) around the gaze.

Reading needs a few words around the fixation, not the whole sensor; dropping the rest cuts the
event rate (typically by three quarters on a page) before anything expensive runs. Cropped events
keep their sensor coordinates; the voxel grid makes them window-relative.

The window's size is the reconstruction model's input (``Reconstructor.voxel``); ``FoveaConfig()``
is the size the shipped model was trained for. :func:`in_window` is the one window test.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from darkread.edge.events import Events, select_events

WINDOW_HEIGHT = 100  # rows of the shipped model's window
WINDOW_WIDTH = 200  # columns
GAZE_TIME_STEP_US = 1000  # offline foveation looks the gaze up once per millisecond (it moves slowly)


@dataclass(frozen=True)
class FoveaConfig:
    height: int = WINDOW_HEIGHT
    width: int = WINDOW_WIDTH


def in_window(events: Events, x0: int, y0: int, width: int, height: int) -> np.ndarray:
    """Boolean mask of ``events`` inside [x0, x0 + width) x [y0, y0 + height).

    Subtracting the origin in uint16 wraps coordinates left of / above the window to large values,
    so one comparison per axis tests both bounds.
    """
    dx = events["x"] - np.uint16(x0)
    dy = events["y"] - np.uint16(y0)
    return (dx < width) & (dy < height)


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
    # ``window_origins`` of one centre in plain floats (the same arithmetic): the pipeline places a
    # window per view and per frame, and a dozen numpy calls on one-element arrays cost ~20x the arithmetic
    u, v = float(center_xy[0]), float(center_xy[1])
    if not (math.isfinite(u) and math.isfinite(v)):
        raise ValueError(f"gaze centre {center_xy} is not a finite pixel")
    x0 = min(max(math.floor(u + 0.5) - cfg.width // 2, 0), max(int(sensor_wh[0]) - cfg.width, 0))
    y0 = min(max(math.floor(v + 0.5) - cfg.height // 2, 0), max(int(sensor_wh[1]) - cfg.height, 0))
    return x0, y0


def crop(events: Events, x0: int, y0: int, cfg: FoveaConfig = FoveaConfig()) -> Events:
    """Events inside the window at (x0, y0), sensor coordinates kept (a copy)."""
    if x0 < 0 or y0 < 0:
        raise ValueError(f"window origin must be non-negative, got ({x0}, {y0})")
    return select_events(events, in_window(events, x0, y0, cfg.width, cfg.height))


def window_events(events: Events, origin: tuple[int, int], cfg: FoveaConfig, n_events: int) -> Events:
    """The newest ``n_events`` of ``events`` inside the window at ``origin``: what one voxel grid bins."""
    return crop(events, origin[0], origin[1], cfg)[-n_events:]


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
    return select_events(events, inside)


def origins_along_gaze(
    t_us: np.ndarray,
    gaze_px_at: Callable[[np.ndarray], np.ndarray],
    sensor_wh: tuple[int, int],
    cfg: FoveaConfig = FoveaConfig(),
) -> np.ndarray:
    """(N, 2) window origin per event time (NaN without a gaze), the gaze looked up once per millisecond.

    ``gaze_px_at(t_us [M]) -> [M, 2]`` is e.g. ``GazeMapper.pixels_at``: one call per millisecond
    of events, not per event.
    """
    t = np.asarray(t_us, dtype=np.int64)
    if t.shape[0] == 0:
        return np.zeros((0, 2))
    steps, index = np.unique(t // GAZE_TIME_STEP_US, return_inverse=True)
    centres = np.asarray(gaze_px_at(steps * GAZE_TIME_STEP_US + GAZE_TIME_STEP_US // 2), dtype=np.float64)
    return window_origins(centres, sensor_wh, cfg)[index.reshape(-1)]


def foveate_along_gaze(
    events: Events,
    gaze_px_at: Callable[[np.ndarray], np.ndarray],
    sensor_wh: tuple[int, int],
    cfg: FoveaConfig = FoveaConfig(),
) -> Events:
    """Offline foveation: the events inside the window around the gaze at their own time."""
    if events.shape[0] == 0:
        return events[:0]
    return crop_along_track(events, origins_along_gaze(events["t"], gaze_px_at, sensor_wh, cfg), cfg)
