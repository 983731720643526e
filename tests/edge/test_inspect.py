"""`darkread inspect`: streamed totals, foveated fraction, JSON fields against known files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from factories import random_events, synthetic_recording

from darkread.cli import build_parser, main
from darkread.edge.events import make_events
from darkread.edge.gaze import GazeMapper
from darkread.edge.inspect import format_report, inspect_path, summarize, write_png
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.gaze_csv import GazeTrack
from darkread.edge.io.imu_csv import IMU_NAME, write_imu_csv

JSON_KEYS = {"width", "height", "format", "events", "on", "off", "t_first_us", "t_last_us", "sum_t_us", "sum_x", "sum_y", "triggers"}
RECORDING_KEYS = {"gaze_samples", "gaze_valid_fraction", "fovea_event_fraction"}


def centre_gaze_mapper(t_end_us: int) -> GazeMapper:
    """Gaze straight ahead -> the principal point (640, 360) for the whole stream."""
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    calib = Calibration(1280, 720, 1000.0, 1000.0, 640.0, 360.0, (0.0, 0.0, 0.0, 0.0), T, 0)
    t = np.arange(0, t_end_us + 20_000, 16_000, dtype=np.int64)
    track = GazeTrack(t, np.zeros(t.size), np.zeros(t.size), np.full(t.size, 0.5), np.ones(t.size, bool), "gen1_vergence", None)
    return GazeMapper(calib, track)


def test_summary_totals_are_exact_over_chunks() -> None:
    events = random_events(10_000, seed=4)
    summary = summarize(np.array_split(events, 7), width=1280, height=720)
    assert summary.events == 10_000
    assert summary.on == int(events["p"].sum())
    assert (summary.t_first_us, summary.t_last_us) == (int(events["t"][0]), int(events["t"][-1]))
    assert summary.sum_t_us == int(events["t"].sum())
    assert summary.sum_x == int(events["x"].astype(np.int64).sum())
    assert summary.sum_y == int(events["y"].astype(np.int64).sum())


def test_fovea_fraction_counts_events_inside_the_moving_window() -> None:
    events = make_events([640, 540, 739, 539, 640, 640], [360, 310, 409, 360, 409, 410], 1, [0, 1, 2, 3, 4, 5])
    summary = summarize([events[:3], events[3:]], width=1280, height=720, mapper=centre_gaze_mapper(10))
    assert summary.gaze_events == 6
    assert summary.fovea_events == 4  # (539, 360) is left of the window, (640, 410) below it


def test_events_without_gaze_are_outside_the_fovea() -> None:
    events = random_events(1000, t0=10_000_000, seed=1)  # long after the gaze track ends
    summary = summarize([events], width=1280, height=720, mapper=centre_gaze_mapper(1000))
    assert summary.gaze_events == 0 and summary.fovea_events == 0


def test_png_and_text_report(tmp_path: Path) -> None:
    events = random_events(5000, seed=2)
    summary = summarize([events], width=1280, height=720, image=True)
    assert summary.counts is not None and summary.counts.sum() == 5000
    out = tmp_path / "events.png"
    mapper = centre_gaze_mapper(int(events["t"][-1]))
    write_png(out, summary.counts, 1280, 720, mapper, mapper.track)
    import cv2

    picture = cv2.imread(str(out))
    assert picture.shape == (720, 1280, 3)
    assert (picture[310, 540:740] == (0, 255, 0)).all(axis=1).any()  # the window outline is drawn
    text = format_report(
        dict(path="x.raw", width=1280, height=720, format="EVT3", events=10, on=4, off=6, t_first_us=0, t_last_us=9,
             duration_s=9e-6, event_rate_hz=1.1e6, sum_t_us=0, sum_x=0, sum_y=0, triggers=0)
    )
    assert "1280 x 720, EVT3" in text and "40.0% ON" in text


def test_inspect_is_registered_with_help() -> None:
    args = build_parser().parse_args(["inspect", "some.raw", "--json", "--png", "out.png"])
    assert args.path == "some.raw" and args.json and args.png == "out.png"


def _inspect_json(capsys, *argv: str) -> dict:
    assert main(["inspect", *argv, "--json", "--no-progress"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.shared
@pytest.mark.parametrize(
    "name",
    ["gen41_hd_evt3__expelliarmus_evt3_sample.raw", "hd_evt3_trigger_erc__event_camera_codecs.raw",
     "vga_evt3_trigger__event_camera_py.raw"],
)
def test_json_matches_expected_stats(real_events_dir: Path, capsys, name: str) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    expected = json.loads((real_events_dir / "expected_stats.json").read_text())[name]
    report = _inspect_json(capsys, str(real_events_dir / name))
    assert JSON_KEYS <= report.keys()
    assert report["format"] == "EVT3"
    assert report["events"] == expected["cd_events"]
    assert (report["on"], report["off"]) == (expected["on"], expected["off"])
    assert (report["t_first_us"], report["t_last_us"]) == (expected["t_first_us"], expected["t_last_us"])
    assert (report["sum_t_us"], report["sum_x"], report["sum_y"]) == (expected["sum_t_us"], expected["sum_x"], expected["sum_y"])
    assert report["triggers"] == expected["ext_triggers"]
    assert report["width"] == expected["x_max"] + 1 and report["height"] == expected["y_max"] + 1


@pytest.mark.shared
def test_sample_recording(shared_sample_recording: Path, capsys, tmp_path: Path) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    out = tmp_path / "sample.png"
    report = _inspect_json(capsys, str(shared_sample_recording), "--png", str(out))
    meta = json.loads((shared_sample_recording / "meta.json").read_text())
    assert JSON_KEYS | RECORDING_KEYS <= report.keys()
    assert (report["width"], report["height"], report["format"]) == (1280, 720, "EVT3")
    assert report["events"] == meta["event_count"] == report["on"] + report["off"]
    assert report["duration_s"] == pytest.approx(meta["duration_s"], abs=0.01)
    assert report["gaze_samples"] == 211 and report["gaze_valid_fraction"] == 1.0
    # Reading a page: about three quarters of the events fall outside the 100x200 window.
    assert 0.18 < report["fovea_event_fraction"] < 0.27
    assert out.is_file() and out.stat().st_size > 1000


@pytest.mark.shared
def test_bare_raw_with_explicit_gaze_and_calibration(shared_sample_recording: Path, capsys) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    report = _inspect_json(
        capsys,
        str(shared_sample_recording / "events.raw"),
        "--gaze", str(shared_sample_recording / "general_eye_gaze.csv"),
        "--calibration", str(shared_sample_recording / "calibration.json"),
    )
    assert RECORDING_KEYS <= report.keys()
    bare = _inspect_json(capsys, str(shared_sample_recording / "events.raw"))
    assert "fovea_event_fraction" not in bare and bare["events"] == report["events"]


@pytest.mark.shared
def test_progress_bar_on_stderr_for_long_files(shared_sample_recording: Path, capsys, monkeypatch) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    import darkread.edge.inspect as inspect_module

    monkeypatch.setattr(inspect_module, "PROGRESS_MIN_BYTES", 0)  # treat the sample as a long file
    report = inspect_module.inspect_path(shared_sample_recording / "events.raw", chunk_bytes=1 << 18)
    assert report["events"] > 0
    assert "inspect events.raw" in capsys.readouterr().err


@pytest.mark.shared
def test_bare_raw_with_only_a_gaze_csv_names_the_missing_calibration(shared_sample_recording: Path, capsys) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    code = main(["inspect", str(shared_sample_recording / "events.raw"), "--gaze", str(shared_sample_recording / "general_eye_gaze.csv")])
    assert code == 1
    assert "--calibration" in capsys.readouterr().err


def test_the_imu_stream_is_shown(tmp_path: Path) -> None:
    recording = synthetic_recording(tmp_path / "rec", n_events=2_000)
    t = np.arange(0, 500_000, 1000, dtype=np.int64)
    omega = np.tile([0.0, np.radians(10.0), 0.0], (t.shape[0], 1))
    write_imu_csv(recording / IMU_NAME, t, omega, np.tile([0.0, 0.0, 0.0, 1.0], (t.shape[0], 1)), graph_uid="g", utc_offset_ns=0)
    report = inspect_path(recording, png=tmp_path / "out.png", progress=False)
    imu = report["imu"]
    assert imu["samples"] == 500 and imu["rate_hz"] == 1000 and imu["duration_s"] == 0.499
    assert imu["speed_deg_s_p50"] == pytest.approx(10.0, abs=1e-3)
    assert "IMU         closed_loop_trajectory.csv: 500 samples at 1000 Hz" in format_report(report)
    assert (tmp_path / "out.png").is_file()
