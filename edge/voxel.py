"""Event voxel grid, E2VID definition (rpg_e2vid ``events_to_voxel_grid``).

Polarity becomes +-1; time is scaled to [0, bins - 1] over the window (first event -> bin 0, last
-> bin bins - 1) and each event is shared linearly between its two neighbouring bins. Normalisation
uses non-zero voxels only, so empty pixels stay exactly 0. Accumulation uses ``np.bincount`` with
weights, several times faster than ``np.add.at``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darkread.edge.events import Events


@dataclass(frozen=True)
class VoxelConfig:
    bins: int = 4
    n_events: int = 1600
    height: int = 100
    width: int = 200
    normalize: bool = True

    def __post_init__(self) -> None:
        if self.bins < 1 or self.n_events < 1 or self.height < 1 or self.width < 1:
            raise ValueError(f"VoxelConfig fields must be positive: {self}")


def voxel_grid(events: Events, x0: int = 0, y0: int = 0, cfg: VoxelConfig = VoxelConfig()) -> np.ndarray:
    """float32 [bins, height, width] of the last ``cfg.n_events`` events inside the window at (x0, y0).

    Coordinates become window-relative; events outside the window are ignored before the last
    ``n_events`` are taken. No events -> all zeros.
    """
    bins, height, width = cfg.bins, cfg.height, cfg.width
    plane = height * width
    x = events["x"].astype(np.intp) - x0
    y = events["y"].astype(np.intp) - y0
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    if not inside.all():
        events, x, y = events[inside], x[inside], y[inside]
    events, x, y = events[-cfg.n_events :], x[-cfg.n_events :], y[-cfg.n_events :]
    if events.shape[0] == 0:
        return np.zeros((bins, height, width), dtype=np.float32)

    polarity = np.where(events["p"] > 0, 1.0, -1.0)
    pixel = y * width + x
    if bins == 1:
        touched, weights = pixel, polarity
        grid = np.bincount(touched, weights=weights, minlength=plane)
    else:
        t = events["t"]
        span = float(t[-1] - t[0]) or 1.0
        t_star = (t - t[0]) * ((bins - 1) / span)
        # The last event sits exactly on bins - 1: put it on the upper end of bin bins - 2's pair.
        lower = np.minimum(t_star.astype(np.intp), bins - 2)
        frac = t_star - lower
        index = lower * plane + pixel
        touched = np.concatenate([index, index + plane])
        weights = np.concatenate([polarity * (1.0 - frac), polarity * frac])
        grid = np.bincount(touched, weights=weights, minlength=bins * plane)
    if cfg.normalize:
        _normalize_nonzero(grid, touched, float(weights.sum()))
    return grid.astype(np.float32).reshape(bins, height, width)


def _normalize_nonzero(grid: np.ndarray, touched: np.ndarray, total: float) -> None:
    """(v - mean) / std over the non-zero voxels, in place; zeros stay zero.

    Statistics come from whole-array reductions and the update touches only the voxels the events
    hit (``touched``, duplicates allowed; ``total`` = sum of all weights = sum of the grid): gathering
    the non-zero voxels of an 80 000-voxel grid costs several times the accumulation itself.
    """
    count = np.count_nonzero(grid != 0)  # faster than count_nonzero on floats
    if count == 0:
        return
    mean = total / count
    std = np.sqrt(max(float(np.dot(grid, grid)) / count - mean * mean, 0.0))
    values = grid[touched]
    grid[touched] = np.where(values != 0, (values - mean) / (std if std > 0 else 1.0), 0.0)
