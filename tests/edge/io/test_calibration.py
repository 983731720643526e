"""calibration.json: loading, validation, round trip, radtan projection equal to cv2.projectPoints."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from darkread.edge.errors import CalibrationError
from darkread.edge.io.calibration import Calibration, calibration_to_dict, load_calibration, save_calibration


def make_calibration(**overrides: object) -> Calibration:
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, -1.0, 1.0])  # CPF (x left, y up) -> camera (x right, y down)
    T[:3, 3] = [-0.03, 0.01, 0.0]
    fields: dict[str, Any] = dict(
        width=1280, height=720, fx=1403.1, fy=1404.4, cx=643.1, cy=356.5,
        distortion=(-0.045, 0.024, -0.00066, -0.00043), T_event_cpf=T, gaze_to_event_time_offset_us=-1234,
    )
    fields.update(overrides)
    return Calibration(**fields)


def test_projection_equals_cv2_project_points() -> None:
    calib = make_calibration()
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-0.3, 0.3, 500), rng.uniform(-0.2, 0.2, 500), rng.uniform(0.2, 2.0, 500)])
    ours = calib.project(points)
    theirs, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), calib.camera_matrix(), calib.distortion_coefficients())
    assert np.allclose(ours, theirs.reshape(-1, 2), atol=1e-6)


def test_points_behind_the_camera_are_nan() -> None:
    uv = make_calibration().project(np.array([[0.0, 0.0, 1.0], [0.1, 0.0, -1.0], [0.0, 0.0, 0.0]]))
    assert np.all(np.isfinite(uv[0])) and np.all(np.isnan(uv[1:]))
    assert uv[0] == pytest.approx((643.1, 356.5))


def test_on_sensor_uses_pixel_centres() -> None:
    calib = make_calibration()
    uv = np.array([[-0.5, 0.0], [-0.51, 0.0], [1279.49, 719.49], [1279.5, 0.0], [np.nan, 3.0]])
    assert calib.on_sensor(uv).tolist() == [True, False, True, False, False]


def test_save_load_round_trip(tmp_path: Path) -> None:
    calib = make_calibration(rgb_camera={"width": 512, "height": 512, "timestamp_us": 5})
    save_calibration(tmp_path / "calibration.json", calib)
    assert load_calibration(tmp_path / "calibration.json") == calib


@pytest.mark.shared
def test_sample_recording_calibration(shared_sample_recording: Path) -> None:
    calib = load_calibration(shared_sample_recording / "calibration.json")
    assert (calib.width, calib.height) == (1280, 720)
    assert calib.fx == pytest.approx(1403.118) and calib.cy == pytest.approx(356.5)
    assert calib.distortion == pytest.approx((-0.04494, 0.02445, -0.000663, -0.000431))
    assert calib.gaze_to_event_time_offset_us == -10384815387
    assert calib.rgb_camera is not None and calib.rgb_camera["width"] == 512
    # Straight ahead at reading distance lands near the image centre.
    uv = calib.project(calib.cpf_to_event(np.array([[0.0, 0.0, 0.45]])))[0]
    assert abs(uv[0] - 640) < 200 and abs(uv[1] - 360) < 200


def _write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [
        (lambda d: d.pop("T_event_cpf"), "missing key T_event_cpf"),
        (lambda d: d["event_camera"].pop("fx"), "missing key event_camera.fx"),
        (lambda d: d["event_camera"]["distortion"].pop("k2"), "event_camera.distortion.k2"),
        (lambda d: d["event_camera"].update(width=0), "positive integer"),
        (lambda d: d["event_camera"].update(fy="big"), "finite number"),
        (lambda d: d.update(T_event_cpf=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]), "4x4"),
        (lambda d: d.update(T_event_cpf=(2 * np.eye(4)).tolist()), "rigid"),
        (lambda d: d.update(gaze_to_event_time_offset_us=1.5), "integer"),
        (lambda d: d["event_camera"]["distortion"].update(model="fisheye"), "not supported"),
    ],
)
def test_bad_calibration_raises_with_the_key(tmp_path: Path, mutate, fragment: str) -> None:
    doc = calibration_to_dict(make_calibration())
    mutate(doc)
    with pytest.raises(CalibrationError, match=fragment):
        load_calibration(_write(tmp_path, doc))


def test_not_json_and_missing_file(tmp_path: Path) -> None:
    (tmp_path / "c.json").write_text("{oops")
    with pytest.raises(CalibrationError, match="JSON"):
        load_calibration(tmp_path / "c.json")
    with pytest.raises(CalibrationError, match="not found"):
        load_calibration(tmp_path / "none.json")
