from __future__ import annotations

import cv2
import numpy as np
import pytest

from darkread.stitch import StitchConfig
from darkread.stitch.canvas import Canvas
from darkread.stitch.dewarp import (
    apply_line_warp,
    dewarp_strip,
    estimate_line_warp,
)
from darkread.stitch.strip import STRIP_LAYERS


def _warped(image: np.ndarray, offset_xy: tuple[float, float], slope: float) -> np.ndarray:
    """image shown displaced: out(x + dx, y + dy(x)) = image(x, y), dy(x) = offset_y + slope * x."""
    h, w = image.shape
    xs = np.arange(w, dtype=np.float32)
    map_x = np.broadcast_to(xs - offset_xy[0], (h, w)).astype(np.float32)
    map_y = (np.arange(h, dtype=np.float32)[:, None] - (offset_xy[1] + slope * xs)[None, :]).astype(np.float32)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR)


@pytest.mark.parametrize(("offset", "slope"), [((1.5, -2.0), 0.0), ((0.0, 1.0), 0.006), ((-2.0, 0.0), -0.008)])
def test_klt_measures_the_offset_and_tilt_of_a_line_strip(rendered_page, offset, slope) -> None:
    reference = rendered_page.coverage[100:240, 120:620].copy()
    strip = _warped(reference, offset, slope)
    valid = np.ones(reference.shape, bool)
    warp = estimate_line_warp(reference, valid, strip, valid, x0=0, cfg=StitchConfig(dewarp_degree=1))
    assert warp is not None and warp.points >= 12
    xs = np.array([50.0, 250.0, 450.0])
    dx, dy = warp.at(xs)
    assert np.allclose(dx, offset[0], atol=0.3)
    assert np.allclose(dy, offset[1] + slope * xs, atol=0.3)


def test_applying_the_warp_brings_the_strip_back(rendered_page) -> None:
    reference = rendered_page.coverage[100:240, 120:620].copy()
    canvas = Canvas(STRIP_LAYERS)
    canvas.ensure(0, 0, 500, 140)
    canvas.view("avg", 0, 0, 500, 140)[...] = _warped(reference, (1.0, 2.0), 0.004)
    canvas.view("count", 0, 0, 500, 140)[...] = 1
    ref_full = canvas.crop("avg", *canvas.box) * 0
    ref_full[-canvas.y0 : -canvas.y0 + 140, -canvas.x0 : -canvas.x0 + 500] = reference
    valid = canvas.layers["count"] > 0
    warp = estimate_line_warp(ref_full, valid, canvas.layers["avg"], valid, canvas.x0, StitchConfig(dewarp_degree=1))
    assert warp is not None and apply_line_warp(canvas, warp)
    restored = canvas.view("avg", 20, 20, 480, 120)
    before = np.abs(_warped(reference, (1.0, 2.0), 0.004)[20:120, 20:480] - reference[20:120, 20:480]).mean()
    after = np.abs(restored - reference[20:120, 20:480]).mean()
    assert after < 0.3 * before


def test_no_warp_from_blank_or_implausible_input(rendered_page) -> None:
    reference = rendered_page.coverage[100:240, 120:620].copy()
    valid = np.ones(reference.shape, bool)
    assert estimate_line_warp(np.zeros_like(reference), valid, reference, valid, 0) is None
    far = _warped(reference, (0.0, 12.0), 0.0)  # beyond dewarp_max_shift_px
    assert estimate_line_warp(reference, valid, far, valid, 0, StitchConfig(dewarp_max_shift_px=8.0)) is None


def _strip_canvas(image: np.ndarray) -> Canvas:
    canvas = Canvas(STRIP_LAYERS)
    h, w = image.shape
    canvas.ensure(0, 0, w, h)
    canvas.view("avg", 0, 0, w, h)[...] = image
    canvas.view("count", 0, 0, w, h)[...] = 1
    return canvas


def _page_reference(canvas: Canvas, image: np.ndarray) -> np.ndarray:
    reference = np.zeros(canvas.shape, np.float32)
    h, w = image.shape
    reference[-canvas.y0 : -canvas.y0 + h, -canvas.x0 : -canvas.x0 + w] = image
    return reference


def test_dewarp_strip_undoes_a_line_offset(rendered_page) -> None:
    truth = rendered_page.coverage[100:240, 120:620].copy()
    canvas = _strip_canvas(_warped(truth, (1.0, -2.0), 0.0))
    reference = _page_reference(canvas, truth)
    warp = dewarp_strip(canvas, reference, reference > -1, StitchConfig())
    assert warp is not None
    assert np.abs(canvas.view("avg", 10, 10, 490, 130) - truth[10:130, 10:490]).mean() < 0.02


def test_dewarp_strip_leaves_an_aligned_strip_alone(rendered_page) -> None:
    truth = rendered_page.coverage[100:240, 120:620].copy()
    canvas = _strip_canvas(truth)
    before = canvas.layers["avg"].copy()
    assert dewarp_strip(canvas, _page_reference(canvas, truth), np.ones(canvas.shape, bool), StitchConfig()) is None
    assert np.array_equal(canvas.layers["avg"], before)
