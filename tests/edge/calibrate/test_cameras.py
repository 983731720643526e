from __future__ import annotations

import json

import numpy as np
import pytest

from darkread.edge.calibrate.cameras import (
    Fisheye624Camera,
    aria_camera_from_device_calibration,
    rgb_camera_from_calibration,
)
from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import Intrinsics

# Gen1-RGB-like Fisheye624 parameters [f, cx, cy, k0..k5, p0, p1, s0..s3]
FISHEYE = (610.0, 1440.0, 1440.0, 0.40, -0.45, 0.12, 0.70, -1.50, 0.80, 1e-4, -2e-4, 1e-4, -1e-5, 2e-4, -3e-5)


def _points(rng, n=200):
    return np.c_[rng.uniform(-1.0, 1.0, (n, 2)), np.ones(n)] * rng.uniform(0.3, 2.0, (n, 1))


def test_pinhole_projection_equals_the_recording_format_formula():
    from darkread.edge.io.calibration import Calibration

    cam = Intrinsics(1280, 720, 1400.0, 1401.0, 641.0, 359.0, (-0.05, 0.02, 1e-3, -5e-4))
    ref = Calibration(1280, 720, 1400.0, 1401.0, 641.0, 359.0, (-0.05, 0.02, 1e-3, -5e-4), np.eye(4))
    pts = _points(np.random.default_rng(0)) * [0.4, 0.4, 1.0]
    assert np.allclose(cam.project(pts), ref.project(pts), atol=1e-6)


@pytest.mark.parametrize("camera", [
    Intrinsics(1280, 720, 1400.0, 1401.0, 640.0, 360.0, (-0.05, 0.02, 1e-3, -5e-4)),
    Fisheye624Camera(2880, 2880, FISHEYE),
])
def test_unproject_inverts_project(camera):
    pts = _points(np.random.default_rng(1)) * [0.5, 0.5, 1.0]
    rays = camera.unproject(camera.project(pts))
    assert np.abs(rays - pts[:, :2] / pts[:, 2:]).max() < 1e-9


def test_fisheye_without_distortion_is_equidistant():
    cam = Fisheye624Camera(1000, 1000, (300.0, 500.0, 500.0) + (0.0,) * 12)
    theta = np.radians(40.0)
    uv = cam.project(np.array([[np.sin(theta), 0.0, np.cos(theta)]]))
    assert np.allclose(uv, [[500.0 + 300.0 * theta, 500.0]])


def test_points_behind_the_camera_project_to_nan():
    cam = Fisheye624Camera(2880, 2880, FISHEYE)
    assert np.isnan(cam.project(np.array([[0.1, 0.0, -1.0]]))).all()


def test_rgb_block_of_the_recording_format_is_read():
    doc = {"rgb_camera": {"width": 512, "height": 512, "fx": 1489.69, "fy": 1489.69, "cx": 255.5, "cy": 255.5,
                          "distortion": {"model": "none"}, "T_rgb_cpf": np.eye(4).tolist()}}
    cam, T = rgb_camera_from_calibration(doc)
    assert cam.fx == 1489.69 and np.array_equal(T, np.eye(4))
    with pytest.raises(CalibrationError, match="rgb_camera"):
        rgb_camera_from_calibration({})


def test_aria_device_calibration_gives_fisheye_and_pose(tmp_path):
    half = np.sqrt(0.5)
    doc = {"CameraCalibrations": [
        {"Label": "camera-slam-left", "Projection": {"Name": "FisheyeRadTanThinPrism", "Params": list(FISHEYE)}},
        {"Label": "camera-rgb", "Projection": {"Name": "FisheyeRadTanThinPrism", "Params": list(FISHEYE)},
         "T_Device_Camera": {"Translation": [0.01, 0.02, 0.03], "UnitQuaternion": [half, [0.0, 0.0, half]]}},
    ]}
    path = tmp_path / "device.json"
    path.write_text(json.dumps(doc))
    cam, T = aria_camera_from_device_calibration(path)
    assert isinstance(cam, Fisheye624Camera) and cam.width == 2880
    assert np.allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 deg about z
    assert np.allclose(T[:3, 3], [0.01, 0.02, 0.03])
    with pytest.raises(CalibrationError, match="camera-et"):
        aria_camera_from_device_calibration(path, label="camera-et")


def test_aria_pose_layout_round_trips():
    from darkread.edge.calibrate.cameras import pose_from_aria_json
    from darkread.edge.calibrate.markers import pose_matrix
    from darkread.lab.fixtures.calibration_capture import aria_pose

    T = pose_matrix(np.radians([20.0, -170.0, 35.0]), [0.01, -0.02, 0.03])
    assert np.allclose(pose_from_aria_json(aria_pose(T)), T, atol=1e-12)
