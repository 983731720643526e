"""Annotation from pose: the pure pieces (homography fit and interpolation, targets under a known pose)."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.models.synth.camera import random_calibration
from darkread.models.synth.recording import RecordingSpec, page_to_camera, session_spec
from darkread.models.synth.scene import Region
from darkread.models.synth.session import make_session
from darkread.models.train.annotate import (
    PoseTrack,
    alignment_residual,
    apply_h,
    fit_homography,
    marker_area_for_pose,
    page_coordinates,
    page_ink_for_pose,
    project_page,
    reference_points,
    render_ignore,
    render_target,
    window_rays,
)

SPEC = RecordingSpec(lux=100, motion="normal", kind="pangram", seconds=1.0, seed=4, xheight_px=9.0, n_lines=2,
                     line_chars=24, regime="shifted", markers=True)


@pytest.fixture(scope="module")
def session():
    return make_session(session_spec(SPEC), SPEC.seed)


def normalised(H_cam: np.ndarray) -> np.ndarray:
    return H_cam / H_cam[2, 2]


def test_target_rendered_under_the_true_pose_is_the_simulators_ink_mask(session):
    page, calib = session.marker_page, session.calib
    assert page is not None and session.spec.regime == "shifted" and session.page.font.startswith("DejaVu Sans Mono")
    ink = page.ink_at(session.texels_per_mm)
    centre = np.asarray(page.text_box_mm).reshape(2, 2).mean(axis=0)
    for t in (0.1, 0.7):
        H = page_to_camera(session, np.array([t]))[0]
        uv = calib.project((np.r_[centre, 1.0] @ H.T)[None])[0]
        origin = (int(uv[0]) - 100, int(uv[1]) - 50)
        truth = session.scene.ink_mask(Region.of(calib, origin[0], origin[1], 200, 100), t)
        target = render_target(ink, session.texels_per_mm, normalised(H), window_rays(calib, origin))
        assert truth.sum() > 500
        assert int((target != truth).sum()) <= 5  # the same page, pose and sampling: the same pixels
        shifted = render_target(ink, session.texels_per_mm, normalised(H), window_rays(calib, (origin[0] + 1, origin[1])))
        assert int((shifted != truth).sum()) > 300  # one pixel off is visible


def test_homography_from_marker_corners_is_exact_under_distortion(session):
    page, calib = session.marker_page, session.calib
    H = normalised(page_to_camera(session, np.array([0.5]))[0])
    found = {i: project_page(H, calib, c) for i, c in page.markers.items()}
    fit = fit_homography(found, page, calib)
    assert fit is not None
    H_fit, rms = fit
    assert rms < 1e-3
    pts = reference_points(page)
    assert np.abs(project_page(H_fit, calib, pts) - project_page(H, calib, pts)).max() < 1e-3
    assert fit_homography({}, page, calib) is None
    assert fit_homography({0: found[0][:4] * 0 + 5.0}, page, calib) is None  # degenerate: no inliers


def test_pose_track_interpolates_between_detections_and_not_across_gaps():
    ref = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 50.0], [0.0, 50.0]])

    def shifted(dx: float) -> np.ndarray:
        return np.array([[0.001, 0.0, dx], [0.0, 0.001, 0.0], [0.0, 0.0, 1.0]])

    times = np.array([0.0, 10_000.0, 20_000.0, 200_000.0])
    track = PoseTrack.from_detections(times, [shifted(0.0), shifted(0.01), shifted(0.02), shifted(0.03)], ref, max_gap_us=50_000)
    mid = track.at(5_000.0)
    assert mid is not None
    assert np.allclose(apply_h(mid, ref), apply_h(shifted(0.005), ref), atol=1e-9)
    assert track.at(100_000.0) is None  # 180 ms between detections: not interpolated
    assert track.at(-1.0) is None and track.at(250_000.0) is None
    assert np.allclose(apply_h(track.at(200_000.0), ref), apply_h(shifted(0.03), ref))
    # a detection far from what its neighbours say is an outlier
    wild = PoseTrack.from_detections(times[:3], [shifted(0.0), shifted(0.5), shifted(0.02)], ref, 50_000, outlier=0.01)
    assert len(wild) == 2 and 10_000.0 not in wild.t_us


def test_residual_is_zero_for_the_truth_and_the_shift_otherwise():
    calib = random_calibration(np.random.default_rng(3))
    H_cam = np.array([[1e-3, 0, -0.04], [0, 1e-3, -0.02], [0, 0, 0.45]])
    assert alignment_residual(normalised(H_cam), H_cam, calib, (500, 300)) == pytest.approx(0.0, abs=1e-6)
    shift = np.array([[1.0, 0.0, 2.0 / calib.fx], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # ~2 px to the right
    assert alignment_residual(shift @ normalised(H_cam), H_cam, calib, (500, 300)) == pytest.approx(2.0, rel=0.1)


def inside(mm: np.ndarray, boxes: np.ndarray, grow_mm: float) -> np.ndarray:
    """Page points [n, 2] inside any of the boxes [k, 4] (x0 y0 x1 y1) grown by ``grow_mm``."""
    x, y = mm[:, :1], mm[:, 1:]
    b = boxes[None]
    return ((x >= b[..., 0] - grow_mm) & (x <= b[..., 2] + grow_mm) & (y >= b[..., 1] - grow_mm) & (y <= b[..., 3] + grow_mm)).any(axis=1)


def windows_between_markers_and_text(session, t: float):
    """Windows centred between each marker and the text (both in view), under the true pose at ``t``."""
    page, calib = session.marker_page, session.calib
    H = page_to_camera(session, np.array([t]))[0]
    H = H / H[2, 2]
    text_top, text_bottom = page.text_box_mm[1], page.text_box_mm[3]
    for corners in page.markers.values():
        cx = corners[:, 0].mean()
        above = corners[:, 1].max() < text_top
        y = (corners[:, 1].max() + text_top) / 2 if above else (corners[:, 1].min() + text_bottom) / 2
        uv = project_page(H, calib, np.array([[cx, y]]))[0]
        yield H, (int(uv[0]) - 100, int(uv[1]) - 50)


def test_mask_covers_the_markers_ink_and_no_text(session) -> None:
    page, calib = session.marker_page, session.calib
    ink_for, area_for = page_ink_for_pose(page), marker_area_for_pose(page)
    markers = np.array([[*c.min(axis=0), *c.max(axis=0)] for c in page.markers.values()])
    glyphs = np.array([g["box_mm"] for g in page.glyphs])
    checked = 0
    for t in (0.2, 0.8):
        for H, origin in windows_between_markers_and_text(session, t):
            rays = window_rays(calib, origin)
            ink, s = ink_for(H, calib)
            area, s_area = area_for(H, calib)
            target = render_target(ink, s, H, rays).ravel().astype(bool)
            ignore = render_ignore(area, s_area, H, rays).ravel().astype(bool)
            mm = page_coordinates(H, rays)
            on_marker, on_text = inside(mm, markers, 0.3), inside(mm, glyphs, 0.5)
            if not (target & on_marker).any() or not (target & on_text).any():
                continue  # this window does not see both
            checked += 1
            assert ignore[target & on_marker].all()  # every ink pixel of a marker is ignored
            assert not (ignore & on_text).any()  # no pixel of any glyph's box is
            assert not (target & ~ignore & ~on_text).any()  # what ink is left to learn is text
            assert (target & ~ignore).sum() > 100
    assert checked >= 4
