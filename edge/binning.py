"""Events binned into count images, compiled: one pass over the events instead of a dozen array passes.

The head-motion tracker (``scene_motion``) counts every event of the sensor into coarse cells, a
million events a few seconds; the deblur (``deblur``) counts a window's neighbourhood into one
image per time slice. In numpy each is a chain of whole-array passes (a strided field copy per
coordinate, a floor division, a clip, a multiply, an add, a bincount), and on the edge's one core
those passes cost more than the counting: compiled, each event is read once and counted in place.
The counts are exactly numpy's (integers; the slice ages summed in event order, as ``np.bincount``
sums its weights), which the tests check against the numpy formulation.
"""

from __future__ import annotations

import numpy as np

from darkread.edge.compiled import compiled
from darkread.edge.events import empty_events


def cell_tables(width: int, height: int, cell_px: int, pad: int = 0, row_stride: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(column of each x, flat offset of each y's row) of ``cell_px`` cells over ``width`` x
    ``height`` pixels, ``pad`` cells in; rows ``row_stride`` cells apart (default: as many as there
    are columns plus both pads). Looked up per event: an integer division per coordinate costs
    more than the rest of the counting."""
    columns = np.arange(width, dtype=np.int64) // cell_px + pad
    stride = int(columns[-1]) + 1 + pad if row_stride is None else row_stride
    rows = (np.arange(height, dtype=np.int64) // cell_px + pad) * stride
    return columns, rows


@compiled
def add_cell_counts(x, y, start, stop, column_of, row_of, out):  # pragma: no cover - compiled
    """Add events ``start:stop`` of (``x``, ``y``) to ``out`` (flat counts, any number type) at ``row_of[y] +
    column_of[x]`` (``cell_tables``); a coordinate past a table's end counts as its last entry."""
    last_x, last_y = column_of.shape[0] - 1, row_of.shape[0] - 1
    for i in range(start, stop):
        out[row_of[min(np.int64(y[i]), last_y)] + column_of[min(np.int64(x[i]), last_x)]] += 1


@compiled
def voters(x, y, t, x0, y0, width, height, t_first, t_last):  # pragma: no cover - compiled
    """(how many, earliest time) of the events inside the region [x0, x0 + width) x [y0, y0 + height)
    with ``t_first <= t <= t_last``; the time is ``t_last`` when there are none."""
    n = 0
    earliest = t_last
    for i in range(x.shape[0]):
        if 0 <= np.int64(x[i]) - x0 < width and 0 <= np.int64(y[i]) - y0 < height and t_first <= t[i] <= t_last:
            n += 1
            if t[i] < earliest:
                earliest = t[i]
    return n, earliest


@compiled
def slice_counts(x, y, t, x0, y0, column_of, row_of, t_first, t_last, t_ref, span, oldest, images, counts, age_sums):  # pragma: no cover - compiled
    """Count the events of [``t_first``, ``t_last``] inside the region at (``x0``, ``y0``) as wide
    and high as the tables (``cell_tables`` from its corner) into ``images`` [slices, plane] by
    their age (``(t_ref - t) / span``, 0 newest): slice ``int(age * (slices / oldest))``, clipped
    to the slices; ``counts`` and ``age_sums`` per slice."""
    width, height = column_of.shape[0], row_of.shape[0]
    slices = images.shape[0]
    scale = slices / oldest
    for i in range(x.shape[0]):
        dx = np.int64(x[i]) - x0
        dy = np.int64(y[i]) - y0
        if 0 <= dx < width and 0 <= dy < height and t_first <= t[i] <= t_last:
            age = (t_ref - np.float64(t[i])) / span
            k = min(max(np.int64(age * scale), 0), slices - 1)
            images[k, row_of[dy] + column_of[dx]] += 1.0
            counts[k] += 1
            age_sums[k] += age


@compiled
def voxel_sums(x, y, p, t, x0, y0, bins, width, height, sums, marked, touched):  # pragma: no cover - compiled
    """Add the E2VID voxel weights of the events (all inside the window at ``x0``, ``y0``) into
    ``sums`` (float64, ``bins * plane``, zero and unmarked in ``marked`` where untouched): polarity +-1, time scaled to [0,
    bins - 1] and each event shared between its two neighbouring bins (one bin: its pixel). The
    voxels first touched are written to ``touched`` (room for two per event); returns how many,
    or -1 (nothing added) when an event lies outside the window.
    Each voxel's sum runs over the lower shares in event order, then the upper ones, as
    ``np.bincount`` sums the two halves of ``voxel.voxel_grid``'s concatenated weights."""
    n = x.shape[0]
    count = 0
    for i in range(n):
        if not (0 <= np.int64(x[i]) - x0 < width and 0 <= np.int64(y[i]) - y0 < height):
            return -1
    plane = width * height
    scale = 0.0
    if n and bins > 1:
        span = np.float64(t[n - 1] - t[0])
        scale = (bins - 1) / (span if span != 0 else 1.0)
    for upper in range(2 if bins > 1 else 1):
        for i in range(n):
            pixel = (np.int64(y[i]) - y0) * width + (np.int64(x[i]) - x0)
            polarity = 1.0 if p[i] > 0 else -1.0
            if bins > 1:
                t_star = np.float64(t[i] - t[0]) * scale
                lower = min(np.int64(t_star), bins - 2)
                frac = t_star - lower
                voxel = (lower + upper) * plane + pixel
                weight = polarity * frac if upper else polarity * (1.0 - frac)
            else:
                voxel, weight = pixel, polarity
            if not marked[voxel]:
                marked[voxel] = 1
                touched[count] = voxel
                count += 1
            sums[voxel] += weight
    return count


def warm_up() -> None:
    """Compile (or load from numba's cache) every loop now, for the fields of event records as the
    edge passes them, so the first live window is not late (a daemon calls this before READY)."""

    events = empty_events(2)
    x, y, t = events["x"], events["y"], events["t"]
    columns, rows = cell_tables(2, 2, 1)
    add_cell_counts(x, y, 0, 2, columns, rows, np.zeros(4, np.float32))  # (scene motion counts in float32)
    voters(x, y, t, 0, 0, 2, 2, 0, 1)
    slice_counts(x, y, t, 0, 0, columns, rows, 0, 1, 1, 1.0, 1.0,
                 np.zeros((2, 4), np.float32), np.zeros(2, np.int64), np.zeros(2, np.float64))
    voxel_sums(x, y, events["p"], t, 0, 0, 2, 2, 2, np.zeros(8), np.zeros(8, np.uint8), np.zeros(4, np.int64))
