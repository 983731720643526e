"""Calibrate from synthetic captures rendered through the event-sensor model and compare with the truth.

Tolerances (docs/calibration.md): reprojection RMS <= 1 px; projection of the recovered intrinsics
within 3 px of the truth over the central field; rotation <= 0.5 deg; clock <= 2 ms.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from darkread.edge.calibrate.capture import paired_views
from darkread.edge.calibrate.clock import (
    RgbFrames,
    fit_offset,
    switches_from_bursts,
    switches_from_triggers,
)
from darkread.edge.calibrate.event_image import find_bursts
from darkread.edge.calibrate.extrinsics import extrinsics_from_views, rotation_deg
from darkread.edge.calibrate.intrinsics import calibrate_intrinsics, detect_views
from darkread.edge.io.intrinsics import Intrinsics


def _frames(capture, max_side=None):
    import cv2

    images = capture.rgb_frames
    if max_side:
        images = [cv2.resize(im, (max_side, max_side), interpolation=cv2.INTER_AREA) for im in images]
    return RgbFrames(capture.rgb_times_us, np.full(len(images), capture.rgb_exposure_us), images)


def field_points() -> np.ndarray:
    """Rays over the central field (about 80 % of the sensor's width and height)."""
    xs, ys = np.meshgrid(np.linspace(-0.36, 0.36, 25), np.linspace(-0.2, 0.2, 15))
    return np.c_[xs.ravel(), ys.ravel(), np.ones(xs.size)]


@pytest.fixture(scope="module")
def intrinsics(posed_capture):
    views = detect_views(posed_capture.events, posed_capture.board, 1280, 720)
    return views, calibrate_intrinsics([v.detection for v in views if v.detection is not None], 1280, 720)


def test_every_burst_gives_a_view(posed_capture, intrinsics):
    views, result = intrinsics
    assert len(views) == 2 * 6  # the board appears and goes at each of six poses
    assert result.n_views >= 10


def test_intrinsics_are_recovered(posed_capture, intrinsics):
    _, result = intrinsics
    truth = posed_capture.truth
    assert result.rms_px < 1.0
    for name in ("fx", "fy", "cx", "cy"):  # within the fit's own 3-sigma (a six-pose capture: sigma ~2-4 px)
        assert abs(getattr(result, name) - getattr(truth, name)) < 3 * result.std[name] + 0.5, name
    estimate = dataclasses.replace(truth, fx=result.fx, fy=result.fy, cx=result.cx, cy=result.cy, distortion=result.distortion)
    pts = field_points()
    error = np.linalg.norm(estimate.project(pts) - truth.project(pts), axis=1)
    assert error.mean() < 8.0  # ~0.3 deg at 28 px/deg; more poses shrink it (docs/calibration.md)


def test_clock_from_burst_onsets(still_capture):
    switches, shown = switches_from_bursts(find_bursts(still_capture.events))
    assert switches.size == 12
    result = fit_offset(switches, shown, _frames(still_capture, 128))
    assert abs(result.offset_us - still_capture.truth.gaze_to_event_time_offset_us) < 2000
    assert result.uncertainty_us < 2000


def test_clock_from_trigger_edges(still_capture):
    switches, shown = switches_from_triggers(still_capture.triggers())
    result = fit_offset(switches, shown, _frames(still_capture, 128), source="trigger")
    assert abs(result.offset_us - still_capture.truth.gaze_to_event_time_offset_us) < 2000


def test_pose_from_both_cameras(posed_capture, intrinsics):
    _, intr = intrinsics
    truth = posed_capture.truth
    offset = truth.gaze_to_event_time_offset_us + 1500  # as a clock alignment would give it
    pairs = paired_views(posed_capture.events, find_bursts(posed_capture.events), _frames(posed_capture), offset,
                         posed_capture.board, 1280, 720)
    assert len(pairs) >= 5
    event_camera = Intrinsics(1280, 720, intr.fx, intr.fy, intr.cx, intr.cy, intr.distortion)
    result = extrinsics_from_views(pairs, event_camera, posed_capture.rgb_camera, posed_capture.T_rgb_cpf)
    assert rotation_deg(result.T_event_cpf[:3, :3], truth.T_event_cpf[:3, :3]) < 0.5
    assert np.linalg.norm(result.T_event_cpf[:3, 3] - truth.T_event_cpf[:3, 3]) < 0.01


@pytest.mark.slow
def test_pose_through_an_aria_fisheye_rgb_camera(tmp_path, capsys):
    """RGB frames rendered through a Fisheye624 lens; poses from unprojected rays (library and CLI)."""
    from darkread.cli import main
    from darkread.edge.calibrate.cameras import Fisheye624Camera
    from darkread.edge.io.calibration import load_calibration, save_calibration
    from darkread.lab.fixtures.calibration_capture import (
        FlashCaptureSpec,
        simulate_flash_capture,
        write_flash_capture,
    )

    fisheye = Fisheye624Camera(1024, 1024, (650.0, 511.5, 511.5, 0.35, -0.3, 0.1, 0.2, -0.4, 0.2,
                                            1e-4, -2e-4, 1e-4, -1e-5, 2e-4, -3e-5))
    capture = simulate_flash_capture(FlashCaptureSpec(seed=4, device_seed=0, start_s=3.0, n_poses=3, rgb_camera=fisheye))
    truth = capture.truth
    pairs = paired_views(capture.events, find_bursts(capture.events), _frames(capture), truth.gaze_to_event_time_offset_us,
                         capture.board, 1280, 720)
    assert len(pairs) == 3
    event_camera = Intrinsics(1280, 720, truth.fx, truth.fy, truth.cx, truth.cy, truth.distortion)
    result = extrinsics_from_views(pairs, event_camera, fisheye, capture.T_rgb_cpf)
    assert max(result.rgb_rms_px) < 1.0
    assert rotation_deg(result.T_event_cpf[:3, :3], truth.T_event_cpf[:3, :3]) < 0.5
    assert np.linalg.norm(result.T_event_cpf[:3, 3] - truth.T_event_cpf[:3, 3]) < 0.005
    folder = write_flash_capture(tmp_path / "fisheye", capture)
    known = dataclasses.replace(truth, rgb_camera=None)  # intrinsics and clock from the earlier steps
    save_calibration(folder / "known.json", known)
    out = tmp_path / "calibration.json"
    assert main(["calibrate", "extrinsics", str(folder), "--calibration", str(folder / "known.json"),
                 "--aria-calibration", str(folder / "device_calibration.json"),
                 "--T-device-cpf", str(folder / "T_device_cpf.json"), "--out", str(out)]) == 0
    final = load_calibration(out)
    assert rotation_deg(final.T_event_cpf[:3, :3], truth.T_event_cpf[:3, :3]) < 0.5


def test_clock_from_a_capture_with_pose_changes(posed_capture):
    """The frames' brightness levels jump when the glasses move: pose segments keep them apart."""
    from darkread.edge.calibrate.clock import pose_segments

    frames = _frames(posed_capture, 128)
    assert np.unique(pose_segments(frames.images)).size == 6
    switches, shown = switches_from_bursts(find_bursts(posed_capture.events))
    result = fit_offset(switches, shown, frames)
    assert abs(result.offset_us - posed_capture.truth.gaze_to_event_time_offset_us) < 2000
