"""Gaze -> event pixel: interpolation, clocks, invalid gaze, cross-check with the recording format."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from factories import angles_at, pixel_at

from darkread.edge.gaze import GazeMapper, gaze_point_cpf, project_gaze
from darkread.edge.io.calibration import Calibration, load_calibration
from darkread.edge.io.gaze_csv import GazeTrack, read_gaze_csv

OFFSET = 1_000_000


def simple_calibration(offset: int = OFFSET) -> Calibration:
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, -1.0, 1.0])  # camera at the CPF origin; x right, y down
    return Calibration(1280, 720, 1000.0, 1000.0, 640.0, 360.0, (0.0, 0.0, 0.0, 0.0), T, offset)


def track(t, yaw, pitch, depth=None, valid=None) -> GazeTrack:
    t = np.asarray(t, dtype=np.int64)
    n = t.shape[0]
    return GazeTrack(
        t_us=t,
        yaw_rad=np.asarray(yaw, dtype=np.float64),
        pitch_rad=np.asarray(pitch, dtype=np.float64),
        depth_m=np.full(n, 0.5) if depth is None else np.asarray(depth, dtype=np.float64),
        valid=np.ones(n, bool) if valid is None else np.asarray(valid),
        schema="gen1_vergence",
        session_uid=None,
    )


def test_gaze_point_cpf_depth_is_euclidean_distance() -> None:
    p = gaze_point_cpf(np.array([0.3, 0.0]), np.array([-0.2, 0.0]), np.array([0.8, 2.0]))
    assert np.allclose(np.linalg.norm(p, axis=1), [0.8, 2.0])
    assert np.allclose(p[1], [0, 0, 2.0])
    assert np.allclose(np.arctan(p[0, 0] / p[0, 2]), 0.3) and np.allclose(np.arctan(p[0, 1] / p[0, 2]), -0.2)
    assert np.allclose(gaze_point_cpf(np.zeros(1), np.zeros(1), -np.ones(1)), 0.0)


def test_straight_ahead_maps_to_the_principal_point_and_left_gaze_to_smaller_x() -> None:
    mapper = GazeMapper(simple_calibration(), track([0, 10_000], [0.0, 0.1], [0.0, 0.0]))
    assert pixel_at(mapper, OFFSET) == pytest.approx((640.0, 360.0))
    # Yaw is positive towards the wearer's left, which is image-left for a forward camera.
    x, y = pixel_at(mapper, OFFSET + 10_000)
    assert x == pytest.approx(640 - 1000 * np.tan(0.1)) and y == pytest.approx(360)


def test_interpolates_between_samples_on_the_event_clock() -> None:
    mapper = GazeMapper(simple_calibration(), track([0, 20_000], [0.0, 0.2], [0.0, -0.1]))
    assert angles_at(mapper, OFFSET + 5_000) == pytest.approx((0.05, -0.025))
    assert angles_at(mapper, 5_000) is None  # the device clock is not the event clock
    mapper.clock_offset_us = 0  # adjustable at run time
    assert angles_at(mapper, 5_000) == pytest.approx((0.05, -0.025))


def test_no_gaze_outside_track_in_gaps_and_blinks() -> None:
    t = [0, 10_000, 20_000, 30_000, 100_000, 110_000]
    valid = [True, True, False, True, True, True]
    mapper = GazeMapper(simple_calibration(), track(t, np.zeros(6), np.zeros(6), valid=valid), max_gap_us=15_000)
    times = OFFSET + np.array([-1, 0, 5_000, 15_000, 25_000, 60_000, 105_000, 110_000, 110_001])
    uv = mapper.pixels_at(times)
    ok = ~np.isnan(uv).any(axis=1)
    # 15 000 and 25 000 fall in the 20 000 us gap left by the blink row; 60 000 in a 70 000 us gap.
    assert ok.tolist() == [False, True, True, False, False, False, True, True, False]
    assert pixel_at(mapper, OFFSET - 1) is None


def test_unknown_depth_uses_the_reading_prior() -> None:
    calib = simple_calibration()
    calib.T_event_cpf[:3, 3] = [0.05, 0.0, 0.0]  # camera 5 cm off the CPF origin -> parallax
    unknown = track([0, 10_000], [0.1, 0.1], [0.0, 0.0], depth=[np.nan, np.nan])
    known = track([0, 10_000], [0.1, 0.1], [0.0, 0.0], depth=[0.45, 0.45])
    far = track([0, 10_000], [0.1, 0.1], [0.0, 0.0], depth=[1.0, 1.0])
    at = OFFSET + 5_000
    assert pixel_at(GazeMapper(calib, unknown), at) == pytest.approx(pixel_at(GazeMapper(calib, known), at))
    assert pixel_at(GazeMapper(calib, unknown), at) != pytest.approx(pixel_at(GazeMapper(calib, far), at))
    assert pixel_at(GazeMapper(calib, unknown, depth_prior_m=1.0), at) == pytest.approx(pixel_at(GazeMapper(calib, far), at))


def test_off_sensor_and_empty_tracks_give_nan() -> None:
    mapper = GazeMapper(simple_calibration(), track([0, 10_000], [0.9, 0.9], [0.0, 0.0]))
    assert pixel_at(mapper, OFFSET + 5_000) is None  # tan(0.9) * 1000 px is off a 1280 px sensor
    assert np.isfinite(mapper.angles_and_depth_at(np.array([OFFSET + 5_000]))[0]).all()  # a gaze, off the sensor
    empty = GazeMapper(simple_calibration(), track([], [], []))
    assert np.isnan(empty.pixels_at(np.arange(3))).all()
    assert empty.event_time_range() is None


def test_vectorised_matches_scalar() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.integers(15_000, 18_000, 50))
    mapper = GazeMapper(simple_calibration(), track(t, rng.normal(0, 0.1, 50), rng.normal(0, 0.1, 50)))
    times = OFFSET + rng.integers(t[0], t[-1], 20)
    uv = mapper.pixels_at(times)
    for time, row in zip(times, uv):
        assert pixel_at(mapper, int(time)) == pytest.approx(tuple(row))


@pytest.mark.shared
def test_sample_recording_worked_example(shared_sample_recording: Path) -> None:
    calib = load_calibration(shared_sample_recording / "calibration.json")
    gaze = read_gaze_csv(shared_sample_recording / "general_eye_gaze.csv")
    mapper = GazeMapper(calib, gaze)
    # The format README's worked example, done by hand for row 0.
    left, right, pitch, depth = -0.07754892855882645, -0.20317938923835754, 0.006430317182093859, 0.4958957180729431
    d = np.array([(np.tan(left) + np.tan(right)) / 2, np.tan(pitch), 1.0])
    p_event = calib.T_event_cpf[:3, :3] @ (depth * d / np.linalg.norm(d)) + calib.T_event_cpf[:3, 3]
    expected = calib.project(p_event[None])[0]
    t_event = int(gaze.t_us[0]) + calib.gaze_to_event_time_offset_us
    assert pixel_at(mapper, t_event) == pytest.approx(tuple(expected))
    uv = mapper.pixels_at(gaze.t_us + calib.gaze_to_event_time_offset_us)
    assert np.isfinite(uv).all()  # the wearer looks at the page, inside the sensor, throughout


def test_one_gaze_in_floats_is_the_array_path_of_one_gaze() -> None:
    """``at`` (plain floats, for the pipeline) gives bit for bit what the numpy path gives one time."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.integers(10_000, 70_000, 80))  # some gaps beyond max_gap_us
    valid = rng.random(80) > 0.1
    calib = simple_calibration()
    calib = Calibration(1280, 720, 900.0, 910.0, 650.0, 350.0, (-0.2, 0.05, 0.001, -0.002), calib.T_event_cpf, OFFSET)
    mapper = GazeMapper(calib, track(t, rng.normal(0, 0.3, 80), rng.normal(0, 0.2, 80), rng.uniform(0.3, 0.8, 80), valid))
    for time in OFFSET + rng.integers(t[0] - 20_000, t[-1] + 20_000, 400):
        yaw, pitch, depth = mapper.angles_and_depth_at(np.array([time]))
        uv = project_gaze(calib, yaw, pitch, depth)[0]
        sample = mapper.at(int(time))
        if np.isnan(uv).any():
            assert sample is None
        else:
            assert sample is not None
            assert sample.pixel == (float(uv[0]), float(uv[1])) and sample.angles == (float(yaw[0]), float(pitch[0]))
