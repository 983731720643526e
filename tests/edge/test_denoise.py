"""A dim-light window's isolated events dropped: the noise goes, the strokes stay, bright windows
and hot pixels are handled as the module says."""

from __future__ import annotations

import numpy as np
import pytest
from factories import make_events, moving_strokes

from darkread.edge.denoise import DenoiseConfig, drop_isolated, isolated
from darkread.edge.fovea import FoveaConfig, window_events

ORIGIN = (540, 310)  # moving_strokes draws around this window
SHAPE = (100, 200)


def window_of(events):
    return window_events(events, ORIGIN, FoveaConfig(height=SHAPE[0], width=SHAPE[1]), 1600)


def strokes_and_noise(noise_share: float, seed: int = 0):
    """A still page's window with ``noise_share`` uniform noise, and which of its events are stroke events."""
    strokes = window_of(moving_strokes((0.0, 0.0), seed=seed))
    rng = np.random.default_rng(seed + 1)
    k = int(strokes.shape[0] * noise_share / (1 - noise_share))
    t = np.sort(rng.integers(int(strokes["t"][0]), int(strokes["t"][-1]) + 1, k))
    noise = make_events(rng.integers(ORIGIN[0], ORIGIN[0] + SHAPE[1], k), rng.integers(ORIGIN[1], ORIGIN[1] + SHAPE[0], k),
                        rng.integers(0, 2, k), t)
    both = np.concatenate([strokes, noise])
    is_stroke = np.r_[np.ones(strokes.shape[0], bool), np.zeros(k, bool)]
    order = np.argsort(both["t"], kind="stable")
    return both[order], is_stroke[order]


@pytest.mark.parametrize("noise_share", [0.2, 0.35])
def test_noise_is_dropped_and_strokes_are_kept(noise_share: float) -> None:
    window, is_stroke = strokes_and_noise(noise_share)
    alone = isolated(window, ORIGIN, SHAPE)
    assert alone[is_stroke].mean() < 0.05  # stroke events nearly always have a neighbour ...
    assert (~is_stroke[~alone]).mean() < 0.6 * noise_share  # ... and the noise's share of what is kept falls by half or more
    kept = drop_isolated(window, ORIGIN, SHAPE)
    assert kept.dtype == window.dtype and kept.shape[0] == int((~alone).sum())
    assert np.array_equal(kept, window[~alone])  # in time order, fields untouched


def test_a_clean_window_is_returned_as_it_is() -> None:
    window, _ = strokes_and_noise(0.0)
    assert isolated(window, ORIGIN, SHAPE).mean() < DenoiseConfig().min_isolated_share
    assert drop_isolated(window, ORIGIN, SHAPE) is window  # bright light: the fine ends of strokes stay


def test_a_pixel_firing_alone_is_isolated_however_often_it_fires() -> None:
    t = np.arange(10, dtype=np.int64) * 1000
    hot = make_events(np.full(10, ORIGIN[0] + 50), np.full(10, ORIGIN[1] + 50), np.ones(10, int), t)
    assert isolated(hot, ORIGIN, SHAPE).all()
    pair = make_events(np.array([ORIGIN[0] + 5, ORIGIN[0] + 6]), np.array([ORIGIN[1] + 5, ORIGIN[1] + 6]), np.ones(2, int), t[:2])
    assert not isolated(pair, ORIGIN, SHAPE).any()  # diagonal neighbours count


def test_disabled_and_empty_windows_pass_through() -> None:
    window, _ = strokes_and_noise(0.5)
    assert drop_isolated(window, ORIGIN, SHAPE, DenoiseConfig(enabled=False)) is window
    empty = window[:0]
    assert drop_isolated(empty, ORIGIN, SHAPE) is empty


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="min_neighbours"):
        DenoiseConfig(min_neighbours=0)
    with pytest.raises(ValueError, match="min_isolated_share"):
        DenoiseConfig(min_isolated_share=1.5)
