"""Foveation and voxel grid cost per 100x200 window, next to straightforward references.

* Fovea crop: ``crop`` (uint16 wrap-around, two comparisons) on a 10 ms whole-sensor slice at
  1 Mev/s (10 000 events), against a naive four-comparison boolean mask on int32 coordinates.
* Voxel grid: ``voxel_grid`` (``np.bincount`` with weights) on 1600 windowed events, against the
  same definition accumulated with ``np.add.at``; once returning a new grid per window (dropped
  right away, the worst case for the allocator) and once filling a reused ``out`` buffer. On hosts
  where page faults are expensive (sandboxes, some VMs) the difference is large: each fresh 320 KB
  grid is a new mapping.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from darkread.edge.config import PipelineConfig
from darkread.edge.events import EVENT_CD_DTYPE
from darkread.edge.fovea import FoveaConfig, crop
from darkread.edge.voxel import VoxelConfig, voxel_grid
from darkread.lab.bench import BenchContext, Figure
from darkread.models.train.latency import best_median_s

SLICE_EVENTS = 10_000
X0, Y0 = 540, 310


def best_median_us(call: Callable[[], object], runs: int, repeats: int = 3) -> float:
    return best_median_s(call, runs, repeats) * 1e6


def _events(n: int, width: int, height: int, x0: int = 0, y0: int = 0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=EVENT_CD_DTYPE)
    ev["x"] = x0 + rng.integers(0, width, n)
    ev["y"] = y0 + rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    ev["t"] = np.sort(rng.integers(0, n * 2, n))
    return ev


def naive_crop(events: np.ndarray, x0: int, y0: int, cfg: FoveaConfig = FoveaConfig()) -> np.ndarray:
    x, y = events["x"].astype(np.int32), events["y"].astype(np.int32)
    return events[(x >= x0) & (x < x0 + cfg.width) & (y >= y0) & (y < y0 + cfg.height)]


def add_at_voxel_grid(events: np.ndarray, x0: int, y0: int, cfg: VoxelConfig = VoxelConfig()) -> np.ndarray:
    """The E2VID definition accumulated with np.add.at (the reference)."""
    x = events["x"].astype(np.intp) - x0
    y = events["y"].astype(np.intp) - y0
    t = events["t"].astype(np.float64)
    ts = (cfg.bins - 1) * (t - t[0]) / ((t[-1] - t[0]) or 1.0)
    ti = ts.astype(np.intp)
    dt = ts - ti
    pol = np.where(events["p"] > 0, 1.0, -1.0)
    grid = np.zeros((cfg.bins, cfg.height, cfg.width))
    ok = ti < cfg.bins
    np.add.at(grid, (ti[ok], y[ok], x[ok]), pol[ok] * (1 - dt[ok]))
    ok = ti + 1 < cfg.bins
    np.add.at(grid, (ti[ok] + 1, y[ok], x[ok]), pol[ok] * dt[ok])
    nz = grid != 0
    grid[nz] = (grid[nz] - grid[nz].mean()) / grid[nz].std()
    return grid.astype(np.float32)


def run(ctx: BenchContext) -> list[Figure]:
    runs = ctx.runs(300, 50, 3)
    sensor_slice = _events(SLICE_EVENTS, 1280, 720, seed=1)
    window = _events(PipelineConfig().n_events, 200, 100, X0, Y0, seed=2)

    crop_us = best_median_us(lambda: crop(sensor_slice, X0, Y0), runs)
    naive_crop_us = best_median_us(lambda: naive_crop(sensor_slice, X0, Y0), runs)
    voxel_us = best_median_us(lambda: voxel_grid(window, X0, Y0), runs)
    out = np.zeros((4, 100, 200), dtype=np.float32)
    voxel_out_us = best_median_us(lambda: voxel_grid(window, X0, Y0, out=out), runs)
    add_at_us = best_median_us(lambda: add_at_voxel_grid(window, X0, Y0), runs)
    if not np.allclose(voxel_grid(window, X0, Y0), add_at_voxel_grid(window, X0, Y0), atol=1e-5):
        ctx.notes.append("fovea bench: voxel_grid differs from the np.add.at reference")

    return [
        Figure(
            "fovea_crop_us_per_window",
            crop_us,
            f"fovea crop, {SLICE_EVENTS} sensor events -> 100x200 (us)",
            reference=f"naive 4-compare mask: {naive_crop_us:.1f} us",
            goal="<= naive",
        ),
        Figure("fovea_crop_naive_us_per_window", naive_crop_us, "fovea crop, naive mask reference (us)"),
        Figure(
            "voxel_us_per_window",
            voxel_us,
            "voxel grid, 1600 events -> 4x100x200 (us)",
            reference=f"np.add.at: {add_at_us:.1f} us",
            goal="< np.add.at",
        ),
        Figure(
            "voxel_reused_out_us_per_window",
            voxel_out_us,
            "voxel grid into a reused buffer (us)",
            reference=f"np.add.at: {add_at_us:.1f} us",
            goal="~40 us (np.bincount)",
        ),
        Figure("voxel_add_at_us_per_window", add_at_us, "voxel grid, np.add.at reference (us)"),
        Figure("voxel_speedup_vs_add_at_x", add_at_us / voxel_us, "voxel grid speed-up over np.add.at (x)"),
    ]
