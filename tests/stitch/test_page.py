from __future__ import annotations

import cv2
import numpy as np
import pytest

from darkread.stitch import StitchConfig, StitchedPage
from darkread.stitch.page import (
    assign_lines,
    binarize,
    estimate_skew,
    ink_level,
    main_column_span,
    rotation_to_fit,
    text_bands,
)


def test_text_bands_find_every_line_including_a_short_last_one(rendered_page) -> None:
    bands = text_bands(rendered_page.mask)
    assert len(bands) == len(rendered_page.text_lines)
    for (top, bottom, centre), (_x0, y0, _x1, y1), (_, _, yc) in zip(
        bands, rendered_page.line_boxes, rendered_page.line_centres
    ):
        assert abs(centre - yc) < 3
        assert top <= y0 + 1 and bottom >= y1 - 1


def test_lines_are_assigned_despite_a_common_gaze_bias() -> None:
    centres = [100.0, 128.0, 156.0, 184.0]
    gaze = [c + 11.0 + d for c, d in zip(centres, [2.0, -3.0, 1.0, 0.0])]  # biased by 11 px, ~ pitch / 2
    assert assign_lines(gaze, centres) == [0, 1, 2, 3]
    assert assign_lines(gaze, []) == [-1] * 4


def test_a_line_split_in_two_segments_keeps_one_band_and_order_restarts_going_up() -> None:
    centres = [100.0, 128.0, 156.0, 184.0]
    assert assign_lines([101.0, 127.0, 131.0, 157.0], centres) == [0, 1, 1, 2]
    assert assign_lines([100.0, 128.0, 156.0, 101.0, 129.0], centres) == [0, 1, 2, 0, 1]


def test_binarize_thresholds_and_removes_single_pixel_specks() -> None:
    avg = np.zeros((20, 20), np.float32)
    avg[5:8, 5:8] = 0.9
    avg[15, 15] = 0.9  # speck
    avg[2, 2:5] = 0.3  # below threshold
    ink = binarize(avg, StitchConfig(ink_threshold=0.45, min_component_px=2))
    assert ink.sum() == 9 and ink[15, 15] == 0


def _strokes(peak: float) -> np.ndarray:
    """A page of 40 horizontal strokes whose averaged ink probability reaches ``peak``, on paper
    with a little faint noise."""
    rng = np.random.default_rng(0)
    avg = rng.uniform(0.0, 0.04, (80, 200)).astype(np.float32)
    for row in range(5, 75, 7):
        avg[row : row + 2, 10:190] = peak * rng.uniform(0.9, 1.0, (2, 180))
    return avg


def test_ink_level_is_the_saturation_on_a_page_whose_frames_agree() -> None:
    cfg = StitchConfig()
    assert ink_level(_strokes(0.95), cfg) == cfg.grey_saturation
    assert ink_level(np.zeros((10, 10), np.float32), cfg) == cfg.grey_saturation  # nothing seen


def test_a_faint_page_is_stretched_to_ink_and_thresholded_at_its_own_level() -> None:
    cfg = StitchConfig()
    faint = _strokes(0.35)  # dim light: every frame finds a different part of the strokes
    level = ink_level(faint, cfg)
    assert 0.3 < level <= 0.35
    assert binarize(faint, cfg).sum() == 0  # the configured threshold (0.4) loses the whole page
    ink = binarize(faint, cfg, level=level)
    assert ink[5:7, 10:190].all() and ink.sum() == 10 * 2 * 180
    assert StitchedPage(ink, [], [], ink_probability=faint, grey_saturation=level).to_grey()[5, 100] < 30


def test_a_page_of_faint_noise_is_not_stretched_into_ink() -> None:
    cfg = StitchConfig()
    noise = np.random.default_rng(1).uniform(0.0, 0.09, (80, 200)).astype(np.float32)
    level = ink_level(noise, cfg)
    assert level == cfg.min_ink_level
    assert binarize(noise, cfg, level=level).sum() == 0


def test_views_below_min_views_do_not_set_the_level() -> None:
    cfg = StitchConfig()
    avg = _strokes(0.3)
    avg[0:3, :] = 0.9  # a window border seen once
    views = np.full(avg.shape, 3, np.int32)
    views[0:3, :] = 1
    assert ink_level(avg, cfg, views) < 0.35
    assert ink_level(avg, cfg) == cfg.grey_saturation


def test_ink_level_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="min_ink_level"):
        StitchConfig(min_ink_level=0.9)
    with pytest.raises(ValueError, match="ink_percentile"):
        StitchConfig(ink_percentile=120.0)


def test_main_column_span_skips_stray_ink() -> None:
    cols = np.zeros(300, bool)
    cols[[5]] = True
    cols[60:250:3] = True
    assert main_column_span(cols, 30) == (60, 250)
    assert main_column_span(np.zeros(10, bool), 30) is None


def test_png_is_black_ink_on_white() -> None:
    image = np.zeros((30, 40), np.uint8)
    image[10:20, 5:15] = 1
    page = StitchedPage(image, [(5, 10, 15, 20)], [image[10:20, 5:15]], 3, 1)
    decoded = cv2.imdecode(np.frombuffer(page.to_png_bytes(), np.uint8), cv2.IMREAD_UNCHANGED)
    assert decoded.shape == (30, 40)
    assert (decoded[image == 1] == 0).all() and (decoded[image == 0] == 255).all()
    assert cv2.imdecode(np.frombuffer(StitchedPage(np.zeros((0, 0), np.uint8), [], []).to_png_bytes(), np.uint8), 0).shape == (
        1,
        1,
    )


@pytest.mark.parametrize("angle", [-6.0, 0.0, 3.5])
def test_skew_of_a_turned_page_is_found(rendered_page, angle: float) -> None:
    turn, size = rotation_to_fit(rendered_page.mask.shape, -angle)
    turned = (cv2.warpAffine(rendered_page.coverage, turn, size, flags=cv2.INTER_LINEAR) >= 0.5).astype(np.uint8)
    assert abs(estimate_skew(turned, 15.0) - angle) <= 0.3
    assert estimate_skew(turned, 0.0) == 0.0


def test_grey_page_keeps_the_averaged_ink_probability() -> None:
    from darkread.stitch.stitched_page import StitchedPage, ink_probability_to_paper

    probability = np.array([[0.0, 0.4, 0.8, 1.0]], np.float32)
    assert ink_probability_to_paper(probability, 0.8).tolist() == [[255, 128, 0, 0]]
    binary = (probability > 0.4).astype(np.uint8)
    assert StitchedPage(binary, [], []).to_grey().tolist() == [[255, 255, 0, 0]]  # no probability: the binary page
    assert StitchedPage(binary, [], [], ink_probability=probability).to_grey()[0, 1] == 128
