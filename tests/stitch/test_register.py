from __future__ import annotations

import numpy as np
import pytest

from darkread.stitch import register_frame


def _crop(mask: np.ndarray, x: int, y: int, h: int = 100, w: int = 200) -> np.ndarray:
    return mask[y : y + h, x : x + w].copy()


@pytest.mark.parametrize("shift", [(0, 0), (5, -3), (-11, 7), (13, 12)])
def test_recovers_the_offset_of_a_noisy_crop(rendered_page, shift: tuple[int, int]) -> None:
    rng = np.random.default_rng(0)
    r = 14
    px, py = 200, 130  # predicted top-left; the frame truly sits at predicted + shift
    reference = _crop(rendered_page.mask, px - r, py - r, 100 + 2 * r, 200 + 2 * r).astype(np.float32)
    frame = _crop(rendered_page.mask, px + shift[0], py + shift[1])
    frame = (frame.astype(bool) & (rng.random(frame.shape) > 0.15)) | (rng.random(frame.shape) < 0.01)
    reg = register_frame(reference, np.ones_like(reference, bool), frame.astype(np.uint8), r)
    assert reg is not None
    assert reg.shift_xy == shift
    assert reg.score > 0.5


def test_only_the_part_overlapping_known_content_is_matched(rendered_page) -> None:
    r = 10
    reference = _crop(rendered_page.mask, 190, 120, 120, 220).astype(np.float32)
    known = np.zeros_like(reference, bool)
    known[:, :110] = True  # only the left half has been seen
    reference[~known] = 0
    frame = _crop(rendered_page.mask, 203, 128)  # true shift (+3, -2) from the predicted (200, 130)
    reg = register_frame(reference, known, frame, r)
    assert reg is not None and reg.shift_xy == (3, -2)
    assert 0.4 < reg.overlap < 0.6
    # where the peak puts the frame: its footprint on the known half (97 of its 200 columns)
    assert reg.overlap_at_peak == pytest.approx(known[8:108, 13:213].mean(), abs=1e-6)
    assert reg.overlap_at_peak == pytest.approx(97 / 200, abs=1e-6)


def test_no_registration_without_overlap_or_ink(rendered_page) -> None:
    r = 5
    reference = np.zeros((110, 210), np.float32)
    frame = _crop(rendered_page.mask, 200, 130)
    assert register_frame(reference, np.zeros_like(reference, bool), frame, r) is None
    assert register_frame(reference, np.ones_like(reference, bool), np.zeros_like(frame), r) is None


def test_reference_of_the_wrong_size_is_refused(rendered_page) -> None:
    with pytest.raises(ValueError, match="grown by"):
        register_frame(np.zeros((100, 200), np.float32), np.ones((100, 200), bool), np.zeros((100, 200), np.uint8), 4)


@pytest.mark.parametrize("roll", [-1.2, 0.7])
def test_recovers_a_small_rotation_of_the_frame(rendered_page, roll: float) -> None:
    import cv2

    from darkread.stitch.register import frame_transform

    r = 8
    px, py = 200, 130
    reference = rendered_page.coverage[py - r : py + 100 + r, px - r : px + 200 + r].astype(np.float32)
    window = rendered_page.coverage[py : py + 100, px : px + 200]
    # the camera saw the page turned by -roll: turning the frame by +roll undoes it
    seen = cv2.warpAffine(window, frame_transform((100, 200), -roll), (200, 100), flags=cv2.INTER_LINEAR)
    frame = (seen >= 0.5).astype(np.uint8)
    reg = register_frame(
        reference, np.ones_like(reference, bool), frame, r, angles_deg=(roll - 0.6, roll - 0.1, roll + 0.4)
    )
    assert reg is not None
    assert abs(reg.angle_deg - roll) < 0.25
    assert reg.shift_xy == (0, 0)


def test_a_match_beyond_the_search_is_flagged_on_the_rim(rendered_page) -> None:
    r = 10
    px, py = 200, 130
    reference = _crop(rendered_page.mask, px - r, py - r, 100 + 2 * r, 200 + 2 * r).astype(np.float32)
    inside = register_frame(reference, np.ones_like(reference, bool), _crop(rendered_page.mask, px + 2, py + 3), r)
    beyond = register_frame(reference, np.ones_like(reference, bool), _crop(rendered_page.mask, px, py + 18), r)
    assert inside is not None and not inside.on_rim and inside.shift_xy == (2, 3)
    assert beyond is not None and beyond.on_rim


def test_the_vertical_margin_tells_the_true_line_from_its_neighbours(rendered_page) -> None:
    r = 40  # reaches the lines above and below (pitch 28 px)
    px, py = 200, 130
    reference = _crop(rendered_page.mask, px - r, py - r, 100 + 2 * r, 200 + 2 * r).astype(np.float32)
    reg = register_frame(reference, np.ones_like(reference, bool), _crop(rendered_page.mask, px + 3, py - 5), r)
    assert reg is not None and reg.shift_xy == (3, -5)
    assert reg.vertical_margin > 0.3  # other words on the neighbouring lines
    # a page of identical lines: one pitch up or down matches as well
    line = rendered_page.mask[py + 10 : py + 10 + rendered_page.pitch_px]
    striped = np.tile(line, (12, 1))[:, :600]
    reference = striped[50 - r : 50 + 100 + r, 100 - r : 100 + 200 + r].astype(np.float32)
    reg = register_frame(reference, np.ones_like(reference, bool), striped[50:150, 100:300].copy(), r)
    assert reg is not None and reg.vertical_margin < 0.05


@pytest.mark.parametrize("shift", [(0, 0), (-70, 95), (110, -60)])
def test_locate_frame_finds_a_crop_far_from_the_prediction(rendered_page, shift: tuple[int, int]) -> None:
    from darkread.stitch.register import locate_frame

    rng = np.random.default_rng(1)
    radius = 120
    px, py = 200, 130
    size = (100 + 2 * radius, 200 + 2 * radius)
    reference = _crop(rendered_page.mask, px - radius, py - radius, *size).astype(np.float32)
    frame = _crop(rendered_page.mask, px + shift[0], py + shift[1])
    frame = (frame.astype(bool) & (rng.random(frame.shape) > 0.15)) | (rng.random(frame.shape) < 0.01)
    found = locate_frame(reference, np.ones_like(reference, bool), frame.astype(np.uint8), radius)
    assert found is not None
    assert found.shift_xy == shift
    assert found.score > 0.5


def test_locate_frame_needs_known_content_with_ink(rendered_page) -> None:
    from darkread.stitch.register import locate_frame

    radius = 60
    frame = _crop(rendered_page.mask, 200, 130)
    blank = np.zeros((100 + 2 * radius, 200 + 2 * radius), np.float32)
    assert locate_frame(blank, np.ones_like(blank, bool), frame, radius) is None  # paper only
    size = (100 + 2 * radius, 200 + 2 * radius)
    reference = _crop(rendered_page.mask, 200 - radius, 130 - radius, *size).astype(np.float32)
    assert locate_frame(reference, np.zeros_like(reference, bool), frame, radius) is None  # nothing seen
    with pytest.raises(ValueError):
        locate_frame(reference[1:], np.ones_like(reference[1:], bool), frame, radius)



def test_a_faint_trace_of_the_page_is_no_place_for_a_frame(rendered_page) -> None:
    """Normalised correlation ignores contrast: a stretch of page where one frame left a faint trace
    of ink (here at 1 %) correlates perfectly with a frame of the same words, nearer the prediction
    than their true place. Registration takes only places whose ink varies about as much as the
    frame's (as ``locate_frame`` does): a walking page once grew a second copy of its first lines so."""
    r = 20
    frame = _crop(rendered_page.mask, 200, 130).astype(np.float32)
    trace = np.zeros((100 + 2 * r, 200 + 2 * r), np.float32)
    trace[r + 2 : r + 102, r + 3 : r + 203] = 0.01 * frame  # 2 rows and 3 columns from the prediction
    page = trace.copy()
    page[r - 4 : r + 96, r - 16 : r + 184] = np.maximum(page[r - 4 : r + 96, r - 16 : r + 184], frame)  # the words
    reg = register_frame(page, np.ones_like(page, bool), frame, r)
    assert reg is not None and reg.shift_xy == (-16, -4) and reg.score > 0.9
    alone = register_frame(trace, np.ones_like(trace, bool), frame, r)  # the trace alone: no match, not a perfect one
    assert alone is not None and alone.score < 0
