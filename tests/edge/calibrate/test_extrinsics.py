from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.calibrate.cameras import Fisheye624Camera
from darkread.edge.calibrate.extrinsics import (
    average_poses,
    extrinsics_from_views,
    page_homography,
    rotation_deg,
)
from darkread.edge.calibrate.markers import BoardSpec, Detection, pose_matrix
from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import RECTIFIED, Intrinsics

FISHEYE = (610.0, 1440.0, 1440.0, 0.40, -0.45, 0.12, 0.70, -1.50, 0.80, 1e-4, -2e-4, 1e-4, -1e-5, 2e-4, -3e-5)

EVENT = Intrinsics(1280, 720, 1410.0, 1412.0, 643.0, 358.0, (-0.03, 0.01, 0.0, 0.0))


def _detection(camera, T_cam_board, rng, noise_px=0.2):
    obj = BoardSpec().board().getChessboardCorners().astype(np.float32)
    pts = obj @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    uv = camera.project(pts) + rng.normal(0, noise_px, (len(obj), 2))
    return Detection(obj, uv.astype(np.float32), np.arange(len(obj)), 17)


def _truth():
    T_event_cpf = pose_matrix(np.radians([1.0, -2.0, 180.0]), [-0.03, 0.01, 0.0])
    T_rgb_cpf = pose_matrix(np.radians([3.0, -9.0, 180.0]), [0.04, 0.006, 0.011])
    return T_event_cpf, T_rgb_cpf


@pytest.mark.parametrize("rgb", [Intrinsics(512, 512, 700.0, 700.0, 255.5, 255.5, RECTIFIED), Fisheye624Camera(2880, 2880, FISHEYE)])
def test_pose_is_recovered_through_either_rgb_model(rgb):
    rng = np.random.default_rng(0)
    T_event_cpf, T_rgb_cpf = _truth()
    views = []
    for k in range(4):
        T_cpf_board = np.linalg.inv(T_event_cpf) @ pose_matrix(np.radians([10.0 * k - 15, 5.0, 2.0]), [-0.12, -0.08, 0.55 + 0.03 * k])
        views.append((_detection(EVENT, T_event_cpf @ T_cpf_board, rng), _detection(rgb, T_rgb_cpf @ T_cpf_board, rng)))
    result = extrinsics_from_views(views, EVENT, rgb, T_rgb_cpf)
    assert result.n_views == 4
    assert rotation_deg(result.T_event_cpf[:3, :3], T_event_cpf[:3, :3]) < 0.5  # the stated tolerance
    assert np.linalg.norm(result.T_event_cpf[:3, 3] - T_event_cpf[:3, 3]) < 0.005
    assert max(result.event_rms_px) < 0.5


def test_average_of_poses_is_a_rotation_near_each():
    poses = [pose_matrix(np.radians([a, 0.0, 0.0]), [a, 0.0, 0.0]) for a in (-1.0, 0.0, 1.0)]
    mean = average_poses(poses)
    assert np.allclose(mean[:3, :3] @ mean[:3, :3].T, np.eye(3))
    assert np.allclose(mean, np.eye(4), atol=1e-9)


def test_no_views_is_an_error():
    with pytest.raises(CalibrationError):
        extrinsics_from_views([], EVENT, EVENT, np.eye(4))


def test_homography_fallback_maps_page_points_only():
    rng = np.random.default_rng(3)
    T_event_cpf, T_rgb_cpf = _truth()
    T_cpf_board = np.linalg.inv(T_event_cpf) @ pose_matrix(np.radians([10.0, -5.0, 2.0]), [-0.12, -0.08, 0.5])
    rgb = Intrinsics(512, 512, 700.0, 700.0, 255.5, 255.5, RECTIFIED)
    pinhole_event = Intrinsics(1280, 720, 1410.0, 1412.0, 643.0, 358.0, RECTIFIED)
    ev = _detection(pinhole_event, T_event_cpf @ T_cpf_board, rng, 0.1)
    rg = _detection(rgb, T_rgb_cpf @ T_cpf_board, rng, 0.1)
    result = page_homography(ev, rg)
    assert result.rms_px < 0.5
    assert "page plane" in result.note
    assert np.abs(result.map(rg.image_points) - ev.image_points).max() < 1.0


def test_homography_fallback_on_a_printed_page_lit_by_a_lamp():
    """Static markers around text (ESIM): first-event latency image vs one RGB frame."""
    from darkread.edge.calibrate.event_image import find_bursts, latency_image
    from darkread.edge.calibrate.markers import detect_board
    from darkread.lab.fixtures.calibration_capture import simulate_page_capture

    page = simulate_page_capture(seed=1)
    bursts = find_bursts(page.events)
    assert len(bursts) == 1 and bursts[0].polarity == 1  # the lamp: everything brightens
    event_det = detect_board(latency_image(page.events, 1280, 720, bursts[0].onset_us - 200), page.markers, min_corners=4)
    rgb_det = detect_board(page.rgb_frame, page.markers, min_corners=4)
    assert event_det is not None and len(event_det) == 16 and rgb_det is not None
    result = page_homography(event_det, rgb_det)
    xs, ys = np.meshgrid(np.linspace(0.0, 0.215, 8), np.linspace(0.0, 0.215, 8))
    pts = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    T_event = page.truth.T_event_cpf @ page.T_cpf_page
    T_rgb = page.T_rgb_cpf @ page.T_cpf_page
    truth_event = page.truth.project(pts @ T_event[:3, :3].T + T_event[:3, 3])
    mapped = result.map(page.rgb_camera.project(pts @ T_rgb[:3, :3].T + T_rgb[:3, 3]))
    assert np.linalg.norm(mapped - truth_event, axis=1).max() < 2.0


def test_lamp_views_find_the_printed_markers():
    from darkread.edge.calibrate.intrinsics import detect_views
    from darkread.lab.fixtures.calibration_capture import simulate_page_capture

    page = simulate_page_capture(seed=3)
    views = detect_views(page.events, page.markers, 1280, 720, lamp=True)
    assert len(views) == 1 and views[0].detection is not None and len(views[0].detection) == 16
