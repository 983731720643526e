from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.calibrate.markers import (
    BoardSpec,
    board_pose,
    detect_board,
    load_board,
    pose_matrix,
    save_board,
)
from darkread.edge.errors import CalibrationError


def test_board_round_trips_through_json(tmp_path):
    spec = BoardSpec("grid", 4, 3, 0.05, 0.04, "DICT_5X5_50")
    save_board(tmp_path / "board.json", spec)
    assert load_board(tmp_path / "board.json") == spec


@pytest.mark.parametrize(
    "kwargs", [{"kind": "hexagon"}, {"marker_m": 0.05}, {"squares_x": 1}, {"dictionary": "DICT_NOPE"}]
)
def test_impossible_boards_are_refused(kwargs):
    with pytest.raises(CalibrationError):
        BoardSpec(**kwargs)


def test_missing_board_file_names_the_option(tmp_path):
    with pytest.raises(CalibrationError, match="--board"):
        load_board(tmp_path / "nope.json")


@pytest.mark.parametrize("spec", [BoardSpec(), BoardSpec("grid", 4, 3, 0.05, 0.04)])
def test_detected_corners_sit_where_the_board_image_puts_them(spec):
    px_per_m = 4000.0
    image = np.pad(spec.image(px_per_m), 40, constant_values=255)  # quiet zone around the outer markers
    det = detect_board(image, spec)
    assert det is not None
    expected = det.object_points[:, :2] * px_per_m - 0.5 + 40  # pixel centres at integers
    assert np.abs(det.image_points - expected).max() < 0.1
    if spec.kind == "charuco":
        assert len(det) == (spec.squares_x - 1) * (spec.squares_y - 1)
    else:
        assert len(det) == 4 * spec.squares_x * spec.squares_y


def test_blank_image_has_no_board():
    assert detect_board(np.full((200, 300), 255, np.uint8), BoardSpec()) is None


def test_board_pose_recovers_a_known_pose():
    spec = BoardSpec()
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    T = pose_matrix(np.radians([10.0, -20.0, 5.0]), [-0.1, -0.05, 0.6])
    from darkread.edge.calibrate.markers import Detection

    obj = spec.board().getChessboardCorners().astype(np.float32)
    pts = obj @ T[:3, :3].T + T[:3, 3]
    uv = (pts[:, :2] / pts[:, 2:]) * 1000.0 + [640, 360]
    det = Detection(obj, uv.astype(np.float32), np.arange(len(obj)), 0)
    T_est, rms = board_pose(det, K, None)
    assert rms < 1e-3
    assert np.allclose(T_est, T, atol=1e-5)
