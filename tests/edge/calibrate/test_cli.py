from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from darkread.cli import main
from darkread.edge.calibrate.extrinsics import rotation_deg
from darkread.edge.io.calibration import load_calibration, save_calibration
from darkread.lab.fixtures.calibration_capture import write_flash_capture
from darkread.models.synth.camera import rotation_xyz


def test_clock_command_writes_the_offset(still_capture, still_capture_dir, tmp_path, capsys):
    out = tmp_path / "calibration.json"
    assert main(["calibrate", "clock", str(still_capture_dir), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    truth = still_capture.truth.gaze_to_event_time_offset_us
    assert abs(report["offset_us"] - truth) < 2000
    assert abs(load_calibration(out).gaze_to_event_time_offset_us - truth) < 2000


def test_clock_command_from_the_trigger_input(still_capture, still_capture_dir, capsys):
    assert main(["calibrate", "clock", str(still_capture_dir), "--trigger", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["source"] == "trigger"
    assert abs(report["offset_us"] - still_capture.truth.gaze_to_event_time_offset_us) < 2000


def test_missing_board_is_a_clear_error(still_capture_dir, tmp_path, capsys):
    assert main(["calibrate", "intrinsics", str(still_capture_dir), "--board", str(tmp_path / "none.json")]) == 1
    assert "board" in capsys.readouterr().err


def test_check_scores_a_right_calibration_above_a_wrong_one(shared_sample_recording, tmp_path, capsys):
    good_png, bad_png = tmp_path / "good.png", tmp_path / "bad.png"
    assert main(["calibrate", "check", str(shared_sample_recording), "--png", str(good_png), "--json"]) == 0
    good = json.loads(capsys.readouterr().out)
    calib = load_calibration(shared_sample_recording / "calibration.json")
    T = calib.T_event_cpf.copy()
    T[:3, :3] = rotation_xyz(*np.radians([2.5, -3.0, 0.0])) @ T[:3, :3]
    wrong = tmp_path / "wrong.json"
    save_calibration(wrong, dataclasses.replace(calib, T_event_cpf=T))
    assert main(["calibrate", "check", str(shared_sample_recording), "--calibration", str(wrong), "--png", str(bad_png), "--json"]) == 0
    bad = json.loads(capsys.readouterr().out)
    assert good_png.stat().st_size > 0 and bad_png.stat().st_size > 0
    assert good["on_text_fraction"] > bad["on_text_fraction"] + 0.1


@pytest.mark.slow
def test_full_session_through_the_commands(posed_capture, still_capture_dir, tmp_path, capsys):
    """intrinsics -> clock -> extrinsics, each step reading the calibration the one before wrote."""
    posed_dir = write_flash_capture(tmp_path / "posed", posed_capture)
    truth = posed_capture.truth
    c1, c2, c3 = (tmp_path / f"c{i}.json" for i in (1, 2, 3))
    assert main(["calibrate", "intrinsics", str(posed_dir), "--out", str(c1), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rms_px"] < 1.0
    assert main(["calibrate", "clock", str(still_capture_dir), "--calibration", str(c1), "--out", str(c2)]) == 0
    assert main(["calibrate", "extrinsics", str(posed_dir), "--calibration", str(c2), "--out", str(c3), "--json"]) == 0
    final = load_calibration(c3)
    assert rotation_deg(final.T_event_cpf[:3, :3], truth.T_event_cpf[:3, :3]) < 0.5
    assert abs(final.gaze_to_event_time_offset_us - truth.gaze_to_event_time_offset_us) < 2000
    assert final.rgb_camera is not None  # carried through every step


def test_homography_only_on_a_printed_page(tmp_path, capsys):
    from darkread.lab.fixtures.calibration_capture import simulate_page_capture, write_page_capture

    capture = write_page_capture(tmp_path / "page", simulate_page_capture(seed=2))
    before = (capture / "calibration.json").read_bytes()
    assert main(["calibrate", "extrinsics", str(capture), "--homography-only", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_points"] == 16 and report["rms_px"] < 2.0
    assert "page plane" in report["note"]
    assert (capture / "calibration.json").read_bytes() == before  # no pose from a homography


def test_check_picture_from_chunks_equals_from_one_array(shared_sample_recording):
    from darkread.edge.calibrate.check import render_check
    from darkread.edge.io.raw import read_raw
    from darkread.edge.io.recording import open_recording

    recording = open_recording(shared_sample_recording)
    events = read_raw(recording.raw_path).events
    whole = render_check(events, recording.calibration, recording.gaze())
    chunked = render_check(iter(np.array_split(events, 5)), recording.calibration, recording.gaze())
    assert np.array_equal(whole.picture, chunked.picture)
    assert whole.on_text_fraction == chunked.on_text_fraction > 0.7
