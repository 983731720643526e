"""`darkread calibrate sensor` on simulated calibration recordings: K within 25 %, the noise curve within 20 %,
and bad input as one line."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from darkread.cli import main
from darkread.edge.calibrate.sensor_profile import load_sensor_profile
from darkread.lab.synth.sensor_calibration import CalibrationSpec, true_noise_curve, write_calibration_recordings
from tests.darkread_cli import assert_one_error_line, darkread

LUX = (1.0, 3.0, 10.0)


def _spec(k: float) -> CalibrationSpec:
    return CalibrationSpec(k_hz_per_chip_lux=k, card_lux=LUX, card_seconds=2.0, seed=3)


@pytest.fixture(scope="module")
def recordings_130(tmp_path_factory):
    out = tmp_path_factory.mktemp("sensor_cal") / "k130"
    write_calibration_recordings(out, _spec(130.0))
    return out


@pytest.mark.parametrize("k", [130.0, 400.0])
def test_calibrate_sensor_recovers_k_and_the_noise_curve(k, recordings_130, tmp_path, capsys):
    folder = recordings_130 if k == 130.0 else tmp_path / "rec"
    if k != 130.0:
        write_calibration_recordings(folder, _spec(k))
    out = tmp_path / "profile.json"
    assert main(["calibrate", "sensor", str(folder), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    profile = load_sensor_profile(out)
    assert printed["photoreceptor"]["k_hz_per_chip_lux"] == pytest.approx(profile.k_hz_per_chip_lux, rel=1e-3)
    assert profile.k_hz_per_chip_lux == pytest.approx(k, rel=0.25)
    assert [p.lux for p in profile.noise_points] == list(LUX) and profile.dark_floor_hz is not None
    truth = true_noise_curve(_spec(k), np.array(LUX), pixels=256, seconds=2.0)
    measured = np.array([p.rate_hz for p in profile.noise_points])
    assert np.all(np.abs(measured / truth - 1) < 0.20), (measured, truth)


def test_raw_files_with_their_lux_on_the_command_line(recordings_130, tmp_path):
    args = [f"--card={recordings_130 / f'card-{lux:g}lux' / 'events.raw'}@{lux:g}" for lux in LUX]
    args.append(f"--edge={recordings_130 / 'edge-20lux' / 'events.raw'}@20")
    out = tmp_path / "p.json"
    result = darkread("calibrate", "sensor", *args, "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert load_sensor_profile(out).k_hz_per_chip_lux == pytest.approx(130.0, rel=0.25)
    assert "Hz per chip-lux" in result.stdout


def test_missing_folder(tmp_path):
    assert_one_error_line(darkread("calibrate", "sensor", str(tmp_path / "nope")), "no such folder")


def test_recording_without_lux(recordings_130, tmp_path):
    folder = tmp_path / "rec"
    shutil.copytree(recordings_130, folder)
    meta_path = folder / "card-3lux" / "meta.json"
    meta = json.loads(meta_path.read_text())
    del meta["sensor_calibration"]["lux"]
    meta_path.write_text(json.dumps(meta))
    assert_one_error_line(darkread("calibrate", "sensor", str(folder)), "no lux")
    raw = recordings_130 / "card-3lux" / "events.raw"
    assert_one_error_line(darkread("calibrate", "sensor", "--card", str(raw)), "FILE.raw@LUX")


def test_too_few_light_levels(recordings_130, tmp_path):
    folder = tmp_path / "rec"
    shutil.copytree(recordings_130, folder)
    shutil.rmtree(folder / "card-10lux")
    assert_one_error_line(darkread("calibrate", "sensor", str(folder)), "2 light level(s)")


def test_unreadable_raw(recordings_130, tmp_path, capsys):
    folder = tmp_path / "rec"
    shutil.copytree(recordings_130, folder)
    (folder / "card-1lux" / "events.raw").write_bytes(b"% format EVT3;height=720;width=1280\n% end\n" + b"\xff" * 7)
    assert_one_error_line(darkread("calibrate", "sensor", str(folder)), "card-1lux")
    (folder / "card-1lux" / "events.raw").write_bytes(b"not a raw file at all")
    assert main(["calibrate", "sensor", str(folder)]) == 1
    assert capsys.readouterr().err.startswith("darkread: error: card-1lux: the RAW file cannot be read")
