from __future__ import annotations

import numpy as np

from darkread.stitch import StitchConfig
from darkread.stitch.canvas import Canvas
from darkread.stitch.strip import STRIP_LAYERS, accumulate, row_taper


def _ones(h: int = 20, w: int = 30) -> np.ndarray:
    return np.ones((h, w), np.uint8)


def test_first_frames_average_evenly_then_alpha_takes_over() -> None:
    cfg = StitchConfig(alpha=0.25, improvement_tolerance=1.0)
    canvas = Canvas(STRIP_LAYERS)
    accumulate(canvas, _ones(), 0, 0, 0.8, cfg)
    accumulate(canvas, 0 * _ones(), 0, 0, 0.8, cfg)
    assert np.allclose(canvas.view("avg", 0, 0, 30, 20), 0.5)  # 1/n while 1/n > alpha
    for _ in range(3):
        accumulate(canvas, 0 * _ones(), 0, 0, 0.8, cfg)
    # n = 3 -> 1/3, n = 4 -> 0.25, n = 5 -> alpha 0.25
    expected = 0.5 * (2 / 3) * 0.75 * 0.75
    assert np.allclose(canvas.view("avg", 0, 0, 30, 20), expected)
    assert np.allclose(canvas.view("count", 0, 0, 30, 20), 5)


def test_improvement_mask_keeps_pixels_a_worse_match_would_spoil() -> None:
    cfg = StitchConfig(improvement_tolerance=0.1)
    canvas = Canvas(STRIP_LAYERS)
    accumulate(canvas, _ones(), 0, 0, 0.9, cfg)
    changed = accumulate(canvas, 0 * _ones(), 10, 0, 0.5, cfg)  # overlaps columns 10..29, worse score
    assert changed == 20 * 10  # only its columns nobody had seen (30..39) take it
    assert np.allclose(canvas.view("avg", 0, 0, 30, 20), 1.0)
    assert np.allclose(canvas.view("best", 0, 0, 30, 20), 0.9)
    accumulate(canvas, 0 * _ones(), 0, 0, 0.85, cfg)  # within tolerance: blended
    assert np.allclose(canvas.view("avg", 0, 0, 30, 20), 0.5)


def test_canvas_grows_to_negative_coordinates_and_keeps_content() -> None:
    cfg = StitchConfig()
    canvas = Canvas(STRIP_LAYERS)
    accumulate(canvas, _ones(), 0, 0, 0.9, cfg)
    accumulate(canvas, _ones(), -300, -200, 0.9, cfg)
    assert canvas.box[0] <= -300 and canvas.box[1] <= -200
    assert np.allclose(canvas.crop("avg", 0, 0, 30, 20), 1.0)
    assert np.allclose(canvas.crop("avg", 40, 40, 50, 50), 0.0)


def test_row_taper_weighs_the_fixated_row_most() -> None:
    taper = row_taper(100, 20.0)[:, 0]
    assert taper.shape == (100,)
    assert taper.argmax() in (49, 50) and taper[0] < 0.05


def test_a_fused_view_counts_as_the_frames_behind_it() -> None:
    """A view of three frames (probability 2/3) blends in as those three frames would have."""
    cfg = StitchConfig(improvement_tolerance=1.0)
    one_by_one, fused = Canvas(STRIP_LAYERS), Canvas(STRIP_LAYERS)
    for c in (one_by_one, fused):
        accumulate(c, 0 * _ones(), 0, 0, 0.8, cfg)  # a paper frame first
    for mask in (_ones(), _ones(), 0 * _ones()):
        accumulate(one_by_one, mask, 0, 0, 0.8, cfg)
    accumulate(fused, np.full((20, 30), 2 / 3, np.float32), 0, 0, 0.8, cfg, weight=3)
    for layer in ("avg", "count", "conf"):
        np.testing.assert_allclose(fused.view(layer, 0, 0, 30, 20), one_by_one.view(layer, 0, 0, 30, 20), rtol=1e-5)
