"""One view per fixation: frames registered to each other with the stitcher's registration, fused."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.core.frame_record import FrameRecord
from darkread.edge.view_fusion import N_LEVELS, ViewFuser, quantise, threshold
from darkread.proto.messages import View, decode, encode


def page_of_text(seed: int = 3) -> np.ndarray:
    """A wide strip of glyph-like blobs (ink = 1) that frames are cut from."""
    rng = np.random.default_rng(seed)
    page = np.zeros((140, 320), np.uint8)
    for row in (30, 60, 90):
        x = 5
        while x < 300:
            w = int(rng.integers(3, 8))
            page[row : row + int(rng.integers(6, 14)), x : x + w] = 1
            x += w + int(rng.integers(2, 6))
    return page


def frame(page: np.ndarray, x: int, y: int, i: int, origin: tuple[int, int]) -> FrameRecord:
    return FrameRecord(i, 1000 * i, page[y : y + 100, x : x + 200], origin, (origin[0] + 100.0, origin[1] + 50.0))


def dim_frame_of(page: np.ndarray, lost_share: float, speckle_share: float) -> tuple[FrameRecord, np.ndarray]:
    """The window 3 px right and 2 px down of ``frame(page, 20, 10, ...)``'s as dim light shows it:
    ``lost_share`` of its 4x4 cells of strokes lost, ``speckle_share`` of its pixels noise; with the
    probability of a network that doubted it."""
    rng = np.random.default_rng(0)
    lost = (rng.random((25, 50)) < lost_share).repeat(4, 0).repeat(4, 1)
    dim = np.where(rng.random((100, 200)) < speckle_share, 1, np.where(lost, 0, page[12:112, 23:223])).astype(np.uint8)
    return FrameRecord(1, 1000, dim, (500, 300), (600.0, 350.0)), np.where(dim > 0, 0.7, 0.35).astype(np.float32)


def test_frames_moved_on_the_sensor_are_registered_and_the_view_is_the_union_of_their_windows() -> None:
    page = page_of_text()
    fuser = ViewFuser()
    fuser.add(frame(page, 20, 10, 0, (500, 300)))
    # the head drifted: the text sits 3 px left and 2 px up in the window, which the sensor's
    # offset (the same, locked, origin) does not know; the registration finds it
    placed = fuser.add(frame(page, 23, 12, 1, (500, 300)))
    assert placed == pytest.approx((3.0, 2.0), abs=0.5)
    view = fuser.view(7)
    assert view.frames == 2 and view.frame_id == 7 and view.t0_us == 0 and view.t_us == 1000
    # the view covers both windows, placed where the newest frame's window is at its time (where
    # the stitcher predicts it): the first frame's window lies 3 px left and 2 px up of it
    assert view.origin == (497, 298) and view.levels.shape == (102, 203)
    np.testing.assert_array_equal(threshold(view.levels), page[10:112, 20:223])  # both agree: the page itself
    assert view.gaze_px == (600.0, 350.0)  # the mean of its frames' gaze


def test_frames_in_windows_above_and_below_make_one_taller_view() -> None:
    """The pipeline moves a view's frames up and down (the tracker's bias can put the line being
    read at the window's edge): the view holds what either saw, each part averaged over the
    frames that saw it."""
    page = page_of_text()
    fuser = ViewFuser()
    fuser.add(frame(page, 40, 0, 0, (400, 200)))
    placed = fuser.add(frame(page, 40, 30, 1, (400, 230)))  # the window 30 px lower, the same text
    assert placed == pytest.approx((0.0, 30.0), abs=0.5)
    view = fuser.view(0)
    assert view.origin == (400, 200) and view.levels.shape == (130, 200)
    np.testing.assert_array_equal(threshold(view.levels), page[0:130, 40:240])
    message = decode(encode(view.to_message()), max_bytes=1 << 20)
    assert isinstance(message, View) and message.shape == (130, 200) and message.origin == (400, 200)


def test_a_frame_that_does_not_register_is_left_out_for_the_next_view() -> None:
    fuser = ViewFuser()
    fuser.add(frame(page_of_text(seed=3), 0, 0, 0, (500, 300)))
    speckle = (np.random.default_rng(5).random((100, 200)) < 0.2).astype(np.uint8)  # nothing like the view
    assert fuser.add(FrameRecord(1, 1000, speckle, (500, 300), (600.0, 350.0))) is None
    assert len(fuser) == 1 and fuser.view(0).t_us == 0


def test_a_frame_the_network_doubted_joins_on_a_weaker_match() -> None:
    """Dim light: a frame that lost a quarter of its strokes and gained speckle matches its right
    place at about 0.78, under MIN_SCORE. Given with the probability of a network that doubted it
    (DOUBTED or more), it joins the view there; as a sure binary frame it starts the next view."""
    from darkread.edge.view_fusion import DOUBTED, DOUBTED_MIN_SCORE, MIN_SCORE, doubt

    page = page_of_text()
    dim_frame, doubted = dim_frame_of(page, lost_share=0.25, speckle_share=0.25)
    assert doubt(doubted) >= DOUBTED

    sure = ViewFuser()
    sure.add(frame(page, 20, 10, 0, (500, 300)))
    assert sure.add(dim_frame) is None and sure.last_score is None  # (no match kept)
    unsure = ViewFuser()
    unsure.add(frame(page, 20, 10, 0, (500, 300)))
    assert unsure.add(dim_frame, probability=doubted) == pytest.approx((3.0, 2.0), abs=0.5)
    assert unsure.last_score is not None and DOUBTED_MIN_SCORE <= unsure.last_score < MIN_SCORE and len(unsure) == 2


def test_a_dimmer_frame_joins_where_the_gyroscope_agrees_and_only_there() -> None:
    """A doubted frame that lost 40 % of its strokes and gained speckle matches its right place at
    about 0.64, under DOUBTED_MIN_SCORE: it starts a new view, unless the head's motion since the
    newest frame is known (``moved``: the scene moved 3 px left and 2 px up) and puts it within
    AGREE_PX of that match. A motion that disagrees, or a frame the network was sure of, still
    starts the next view."""
    from darkread.edge.view_fusion import AGREE_MIN_SCORE, DOUBTED, DOUBTED_MIN_SCORE, doubt

    page = page_of_text()
    dim_frame, doubted = dim_frame_of(page, lost_share=0.4, speckle_share=0.35)
    assert doubt(doubted) >= DOUBTED

    def fuser() -> ViewFuser:
        f = ViewFuser()
        f.add(frame(page, 20, 10, 0, (500, 300)))
        return f

    assert fuser().add(dim_frame, probability=doubted) is None
    known = fuser()
    assert known.add(dim_frame, probability=doubted, moved=(-3.0, -2.0)) == pytest.approx((3.0, 2.0), abs=0.5)
    assert known.last_score is not None and AGREE_MIN_SCORE <= known.last_score < DOUBTED_MIN_SCORE and len(known) == 2
    assert known.last_agreed
    assert fuser().add(dim_frame, probability=doubted, moved=(0.0, 0.0)) is None  # 3.6 px from its match
    assert fuser().add(dim_frame, moved=(-3.0, -2.0)) is None  # sure of it: a sure frame needs MIN_SCORE


def test_a_pixel_seen_as_ink_in_one_of_three_frames_is_unlikely_ink() -> None:
    page = page_of_text()
    noisy = page.copy()
    noisy[0:4, 150:154] = 1  # a speck in one frame only
    fuser = ViewFuser()
    for i, source in enumerate((page, page, noisy)):
        fuser.add(frame(source, 40, 0, i, (400, 200)), events_used=1600)
    view = fuser.view(0)
    assert view.levels[1, 111] == 2  # 1/3 -> level 2 of 0..7 (2/7, the nearest)
    assert view.mask[1, 111] == 0  # below one half: paper for a binary stitcher
    assert view.levels.max() == N_LEVELS - 1 and view.events_used == 4800


def test_the_view_goes_on_the_wire_as_grey_levels() -> None:
    fuser = ViewFuser()
    fuser.add(frame(page_of_text(), 0, 0, 0, (10, 20)))
    view = fuser.view(3)
    message = decode(encode(view.to_message()), max_bytes=1 << 20)
    assert isinstance(message, View) and message.frames == 1
    np.testing.assert_array_equal(message.ink(), view.levels)
    record = message.record()  # what the cloud stores and stitches: the levels and the frame count
    np.testing.assert_array_equal(record.mask, view.mask)  # one threshold on both ends
    np.testing.assert_array_equal(record.levels, view.levels)
    assert record.frames == view.frames and record.n_levels == view.n_levels


def test_quantise_and_threshold() -> None:
    p = np.array([[0.0, 0.2, 0.34, 0.5, 0.67, 1.0]])
    np.testing.assert_array_equal(quantise(p, 4), [[0, 1, 1, 2, 2, 3]])
    np.testing.assert_array_equal(threshold(quantise(p, 4), 4), [[0, 0, 0, 1, 1, 1]])
    np.testing.assert_array_equal(quantise(p), [[0, 1, 2, 4, 5, 7]])  # N_LEVELS = 8
    np.testing.assert_array_equal(threshold(quantise(p)), [[0, 0, 0, 1, 1, 1]])


def test_an_empty_fuser_has_no_view() -> None:
    with pytest.raises(ValueError):
        ViewFuser().view(0)


def test_a_view_averages_the_frames_probabilities_when_given_them() -> None:
    """Two frames the network was unsure of at a stroke (probability 0.4 and 0.45: paper in both
    masks) make a view with that stroke grey at ~0.43, where their masks' mean says 0."""
    page = page_of_text()
    faint = np.zeros((100, 200), np.float32)
    faint[40:50, 150:152] = 1.0  # a stroke neither mask holds
    fused, masks_only = ViewFuser(), ViewFuser()
    for i, doubt in enumerate((0.40, 0.45)):
        f = frame(page, 20, 0, i, (500, 300))
        probability = np.where(f.mask > 0, 0.9, 0.0).astype(np.float32) + doubt * faint
        fused.add(f, probability=probability)
        masks_only.add(f)
    grey = fused.view(0).ink_probability()
    assert grey[45, 151] == pytest.approx(3 / 7, abs=0.08)  # 0.425 -> level 3 of 0..7
    assert masks_only.view(0).ink_probability()[45, 151] == 0.0
    ink = page[0:100, 20:220] > 0
    assert grey[ink].min() == pytest.approx(6 / 7)  # 0.9 -> level 6: the network's confidence, not 1
    assert fused.view(0).mask[45, 151] == 0  # below one half: still paper for a binary stitcher
    with pytest.raises(ValueError, match="probability"):
        ViewFuser().add(frame(page, 0, 0, 0, (0, 0)), probability=np.zeros((50, 50), np.float32))


def test_a_frame_the_network_doubted_all_over_is_averaged_as_its_mask() -> None:
    """Dim light: probabilities between 0.2 and 0.8 everywhere (far more such pixels than ink) are
    noise, not faint strokes; the frame goes in as its mask."""
    from darkread.edge.view_fusion import MAX_DOUBT, doubt

    page = page_of_text()
    f = frame(page, 0, 0, 0, (0, 0))
    foggy = np.where(f.mask > 0, 0.7, 0.35).astype(np.float32)
    assert doubt(foggy) > MAX_DOUBT
    fuser = ViewFuser()
    fuser.add(f, probability=foggy)
    np.testing.assert_array_equal(fuser.view(0).ink_probability(), f.mask.astype(np.float64))
    assert doubt(np.zeros((100, 200), np.float32)) == 0.0


@pytest.mark.parametrize("xy", [(0.0, 0.0), (3.25, -1.5), (-6.75, 5.5), (9.5, 9.9), (-40.0, 0.0)])
def test_a_frame_is_resampled_onto_the_canvas_as_a_whole_canvas_warp_would(xy: tuple[float, float]) -> None:
    """Only the canvas rows and columns a frame touches are resampled: the same sums as warping
    onto the whole canvas, at the margin's edge and beyond it too."""
    import cv2

    rng = np.random.default_rng(1)
    fuser = ViewFuser(margin_px=8)
    fuser.add(FrameRecord(0, 0, np.zeros((30, 40), np.uint8), (0, 0), (0.0, 0.0)))  # sets up the 46 x 56 canvas
    before = fuser._sum.copy()
    mask = rng.random((30, 40)).astype(np.float32)
    fuser._accumulate(mask, xy)
    move = np.array([[1.0, 0.0, xy[0] + 8], [0.0, 1.0, xy[1] + 8]], np.float32)
    whole = cv2.warpAffine(mask, move, (56, 46), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    np.testing.assert_allclose(fuser._sum - before, whole, atol=1e-6)


def test_a_view_never_outgrows_what_the_protocol_accepts() -> None:
    """However far a long view's frames drift, it stays within MAX_VIEW_GROWTH windows per side
    around its newest frame (the cloud closes a session over a larger one)."""
    from darkread.proto.messages import WIDE_VIEW_VERSION, check_view_shape

    page = np.zeros((400, 400), np.uint8)
    page[:140, :320] = page_of_text()
    page[140:280, :320] = page_of_text(seed=4)
    fuser = ViewFuser(margin_px=200)
    for i, y in enumerate(range(0, 180, 20)):  # the text drifts 20 px a frame: 160 px over the view
        assert fuser.add(frame(page, 40, y, i, (400, 200 + y))) is not None
    view = fuser.view(0)
    # the frames reach 160 px above the newest one; the view keeps half a window of that
    assert view.levels.shape == (150, 200) and view.origin == (400, 200 + 160 - 50)
    check_view_shape(view.to_message(), (100, 200), WIDE_VIEW_VERSION)  # what the cloud accepts
