"""Voxel grid: equals a straightforward np.add.at implementation of the E2VID definition."""

from __future__ import annotations

import numpy as np
import pytest
from factories import random_events

from darkread.edge.events import make_events
from darkread.edge.fovea import window_events
from darkread.edge.voxel import VoxelConfig, voxel_grid


def reference_voxel_grid(events, x0, y0, cfg, n_events=1600):
    """E2VID events_to_voxel_grid of the window's newest ``n_events``, written plainly with np.add.at."""
    x = events["x"].astype(int) - x0
    y = events["y"].astype(int) - y0
    keep = (x >= 0) & (x < cfg.width) & (y >= 0) & (y < cfg.height)
    events, x, y = events[keep][-n_events:], x[keep][-n_events:], y[keep][-n_events:]
    grid = np.zeros((cfg.bins, cfg.height, cfg.width))
    if len(events) == 0:
        return grid.astype(np.float32)
    t = events["t"].astype(np.float64)
    span = (t[-1] - t[0]) or 1.0
    ts = (cfg.bins - 1) * (t - t[0]) / span
    ti = np.floor(ts).astype(int)
    dt = ts - ti
    pol = np.where(events["p"] == 0, -1.0, 1.0)
    ok = ti < cfg.bins
    np.add.at(grid, (ti[ok], y[ok], x[ok]), pol[ok] * (1 - dt[ok]))
    ok = ti + 1 < cfg.bins
    np.add.at(grid, (ti[ok] + 1, y[ok], x[ok]), pol[ok] * dt[ok])
    if cfg.normalize:
        nz = grid != 0
        if nz.any():
            std = grid[nz].std()
            grid[nz] = (grid[nz] - grid[nz].mean()) / (std if std > 0 else 1.0)
    return grid.astype(np.float32)


@pytest.mark.parametrize("bins", [1, 2, 4, 5])
@pytest.mark.parametrize("normalize", [False, True])
def test_matches_reference_on_random_events(bins: int, normalize: bool) -> None:
    cfg = VoxelConfig(bins=bins, normalize=normalize)
    events = random_events(3000, width=200, height=100, seed=bins)
    events["x"] += 540
    events["y"] += 310
    ours = voxel_grid(window_events(events, (540, 310), cfg.fovea, 1600), 540, 310, cfg)
    assert ours.dtype == np.float32 and ours.shape == (bins, 100, 200)
    assert np.allclose(ours, reference_voxel_grid(events, 540, 310, cfg), atol=1e-5)


def test_events_outside_the_window_are_ignored_and_last_n_taken() -> None:
    """The window's events are chosen before binning (``window_events``); the grid trusts them."""
    events = random_events(5000, seed=9)  # whole sensor
    cfg = VoxelConfig(normalize=False)
    ours = voxel_grid(window_events(events, (540, 310), cfg.fovea, 100), 540, 310, cfg)
    assert np.allclose(ours, reference_voxel_grid(events, 540, 310, cfg, n_events=100), atol=1e-6)
    inside = events[(events["x"] >= 540) & (events["x"] < 740) & (events["y"] >= 310) & (events["y"] < 410)]
    polarity = np.where(inside["p"][-100:] > 0, 1.0, -1.0)
    assert ours.sum() == pytest.approx(polarity.sum(), abs=1e-4)  # each event adds its polarity once


def test_first_event_in_bin_0_last_in_last_bin() -> None:
    events = make_events([0, 5, 9], [0, 1, 2], [1, 0, 1], [100, 150, 200])
    grid = voxel_grid(events, cfg=VoxelConfig(bins=4, normalize=False))
    assert grid[0, 0, 0] == 1.0 and grid[1:, 0, 0].sum() == 0
    assert grid[3, 2, 9] == 1.0 and grid[:3, 2, 9].sum() == 0
    # the middle OFF event at t* = 1.5 is shared between bins 1 and 2
    assert grid[1, 1, 5] == pytest.approx(-0.5) and grid[2, 1, 5] == pytest.approx(-0.5)


def test_normalisation_over_non_zero_voxels_only() -> None:
    events = random_events(1600, width=200, height=100, seed=4)
    grid = voxel_grid(events)
    nonzero = grid[grid != 0]
    assert nonzero.mean() == pytest.approx(0.0, abs=1e-5) and nonzero.std() == pytest.approx(1.0, abs=1e-4)
    assert (grid == 0).mean() > 0.8  # sparse: 1600 events over 4 x 20 000 voxels


def test_empty_and_single_event() -> None:
    assert not voxel_grid(random_events(0)).any()
    single = voxel_grid(make_events([3], [4], [0], [7]), cfg=VoxelConfig(normalize=False))
    assert single[0, 4, 3] == -1.0 and np.abs(single).sum() == 1.0


def test_reused_output_buffer() -> None:
    cfg = VoxelConfig()
    out = np.full((4, 100, 200), 7.0, dtype=np.float32)
    first = voxel_grid(random_events(1600, width=200, height=100, seed=1), out=out)
    assert first is not None and np.shares_memory(first, out)
    expected = voxel_grid(random_events(1600, width=200, height=100, seed=2))
    assert np.array_equal(voxel_grid(random_events(1600, width=200, height=100, seed=2), out=out), expected)
    assert not voxel_grid(random_events(0), out=out).any()  # cleared, not stale
    with pytest.raises(ValueError):
        voxel_grid(random_events(10), cfg=cfg, out=np.zeros((4, 100, 200)))
