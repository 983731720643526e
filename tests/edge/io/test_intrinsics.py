"""One camera value (pinhole + radtan) and one parser for its JSON block."""

from __future__ import annotations

from dataclasses import astuple

import cv2
import numpy as np
import pytest

from darkread.edge.calibrate.cameras import rgb_camera_from_calibration
from darkread.edge.calibrate.intrinsics import IntrinsicsResult
from darkread.edge.errors import CalibrationError
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.intrinsics import RECTIFIED, Intrinsics, intrinsics_from_dict, intrinsics_to_dict
from darkread.lab.synth.rgb_camera import RgbCameraModel

CAMERA = Intrinsics(1280, 720, 1400.0, 1401.0, 641.0, 359.0, (-0.05, 0.02, 1e-3, -5e-4))


def test_project_equals_opencv_and_marks_points_behind_as_nan() -> None:
    points = np.array([[0.1, -0.05, 0.5], [-0.2, 0.1, 1.5], [0.0, 0.0, -1.0]])
    expected, _ = cv2.projectPoints(points[:2], np.zeros(3), np.zeros(3), CAMERA.camera_matrix(), CAMERA.distortion_coefficients())
    uv = CAMERA.project(points)
    np.testing.assert_allclose(uv[:2], expected.reshape(-1, 2), atol=1e-9)
    assert np.isnan(uv[2]).all()
    rays = CAMERA.unproject(uv[:2])
    np.testing.assert_allclose(rays, points[:2, :2] / points[:2, 2:], atol=1e-8)


def test_the_json_block_round_trips_and_names_what_is_wrong() -> None:
    assert intrinsics_from_dict(intrinsics_to_dict(CAMERA), "event_camera", "c.json") == CAMERA
    block = intrinsics_to_dict(CAMERA)
    del block["distortion"]["p1"]
    with pytest.raises(CalibrationError, match=r"c.json: missing key event_camera.distortion.p1"):
        intrinsics_from_dict(block, "event_camera", "c.json")
    del block["distortion"]
    assert intrinsics_from_dict(block, "rgb_camera", "c.json", distortion_required=False).distortion == RECTIFIED
    with pytest.raises(CalibrationError, match="missing key event_camera.distortion"):
        intrinsics_from_dict(block, "event_camera", "c.json")


def test_the_rgb_block_is_parsed_by_the_same_parser() -> None:
    block = {**intrinsics_to_dict(CAMERA), "T_rgb_cpf": np.eye(4).tolist()}
    camera, _ = rgb_camera_from_calibration({"rgb_camera": block})
    assert camera == CAMERA
    block["distortion"] = {"model": "fisheye"}
    with pytest.raises(CalibrationError, match="rgb_camera.distortion.model 'fisheye' is not supported"):
        rgb_camera_from_calibration({"rgb_camera": block})


def test_every_camera_of_the_glasses_is_an_intrinsics() -> None:
    calibration = Calibration(*astuple(CAMERA), T_event_cpf=np.eye(4))
    assert isinstance(calibration, Intrinsics) and calibration.intrinsics() == CAMERA
    assert issubclass(IntrinsicsResult, Intrinsics)
    rgb = RgbCameraModel().intrinsics
    assert rgb.distortion == RECTIFIED and rgb.fx == rgb.fy == RgbCameraModel().focal_px
