"""Bad input through the real commands: one clear line, a non-zero exit, nothing left behind.

Each case prints ``command | exit | the line`` (run with ``-s`` for the table).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from factories import sum_bins_model as tiny_model

from darkread.core.paths import SAMPLE_RECORDING

pytestmark = pytest.mark.slow


def header_and_body() -> tuple[bytes, bytes]:
    data = (SAMPLE_RECORDING / "events.raw").read_bytes()
    end = data.index(b"% end\n") + len(b"% end\n")
    return data[:end], data[end:]


def recording_with(tmp_path: Path, name: str, raw: bytes | None = None, gaze: str | None = None,
                   calibration: dict | None = None) -> Path:
    out = tmp_path / name
    shutil.copytree(SAMPLE_RECORDING, out)
    if raw is not None:
        (out / "events.raw").write_bytes(raw)
    if gaze is not None:
        (out / "general_eye_gaze.csv").write_text(gaze)
    if calibration is not None:
        (out / "calibration.json").write_text(json.dumps(calibration))
    return out


def bad_recordings(tmp_path: Path) -> dict[str, Path]:
    header, body = header_and_body()
    lines = (SAMPLE_RECORDING / "general_eye_gaze.csv").read_text().splitlines(keepends=True)
    first = lines[1].split(",", 1)
    calibration = json.loads((SAMPLE_RECORDING / "calibration.json").read_text())
    small = {**calibration, "event_camera": {**calibration["event_camera"], "width": 640, "height": 480}}
    garbage = np.random.default_rng(0).integers(0, 256, 100_000, dtype=np.uint8).tobytes()
    cases = {
        "EVT2 header on an EVT3 body": recording_with(tmp_path, "evt2", raw=header.replace(b"evt 3.0", b"evt 2.0")
                                                      .replace(b"format EVT3", b"format EVT2") + body),
        "100 kB of garbage appended": recording_with(tmp_path, "garbage", raw=header + body + garbage),
        "header claims 100x100": recording_with(tmp_path, "small", raw=header.replace(b"height=720;width=1280",
                                                b"height=100;width=100").replace(b"geometry 1280x720", b"geometry 100x100") + body),
        "40-digit gaze timestamp": recording_with(tmp_path, "gaze40", gaze="".join([lines[0], "9" * 40 + "," + first[1], *lines[2:]])),
        "no events (header only)": recording_with(tmp_path, "empty", raw=header),
    }
    cases["640x480 calibration on a 1280x720 RAW"] = recording_with(tmp_path, "calib", calibration=small)
    return cases


def run(*args: str, tmp: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "TMPDIR": str(tmp), "XDG_STATE_HOME": str(tmp / "state")}  # the edge's default spool
    return subprocess.run([sys.executable, "-m", "darkread", *args], capture_output=True, text=True, timeout=180, env=env)


def last_line(stderr: str) -> str:
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def table_row(command: str, result: subprocess.CompletedProcess[str]) -> None:
    print(f"| `{command}` | {result.returncode} | {last_line(result.stderr)[:220]} |")


@pytest.fixture(scope="module")
def cases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return bad_recordings(tmp_path_factory.mktemp("bad"))


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_model(tmp_path_factory.mktemp("model") / "tiny.onnx")


INSPECT_CASES = ["EVT2 header on an EVT3 body", "100 kB of garbage appended", "header claims 100x100", "40-digit gaze timestamp"]


@pytest.mark.parametrize("case", INSPECT_CASES)
def test_inspect_names_what_is_wrong(cases: dict[str, Path], case: str, tmp_path: Path) -> None:
    result = run("inspect", "--no-progress", str(cases[case]), tmp=tmp_path)
    table_row(f"inspect <{case}>", result)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert str(cases[case]) in last_line(result.stderr) and "error" in last_line(result.stderr)


@pytest.mark.parametrize("case", ["EVT2 header on an EVT3 body", "100 kB of garbage appended", "header claims 100x100",
                                  "40-digit gaze timestamp", "no events (header only)"])
def test_edge_run_fails_honestly(cases: dict[str, Path], case: str, model: Path, tmp_path: Path) -> None:
    result = run("edge", "run", "--replay", str(cases[case]), "--speed", "max", "--model", str(model),
                 "--cloud", "ws://127.0.0.1:9/v1/stream", "--drain-timeout", "1", tmp=tmp_path)
    table_row(f"edge run --replay <{case}>", result)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr[-2000:]
    assert last_line(result.stderr).startswith("darkread: error:")


def test_edge_run_warns_about_a_calibration_for_another_sensor(cases: dict[str, Path], model: Path, tmp_path: Path) -> None:
    result = run("edge", "run", "--replay", str(cases["640x480 calibration on a 1280x720 RAW"]), "--speed", "max",
                 "--model", str(model), "--cloud", "ws://127.0.0.1:9/v1/stream", "--drain-timeout", "1", tmp=tmp_path)
    warning = next(line for line in result.stderr.splitlines() if "calibration is for" in line)
    print(f"| `edge run --replay <640x480 calibration>` | {result.returncode} | {warning.split(': ', 1)[-1][:220]} |")
    assert "640x480" in warning and "1280x720" in warning


def test_edge_run_with_a_file_as_spool(model: Path, tmp_path: Path) -> None:
    result = run("edge", "run", "--replay", str(SAMPLE_RECORDING), "--spool", "/etc/hostname", "--model", str(model),
                 tmp=tmp_path)
    table_row("edge run --spool /etc/hostname", result)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "/etc/hostname" in last_line(result.stderr) and "not a directory" in last_line(result.stderr)


@pytest.mark.parametrize("case", ["no events (header only)", "40-digit gaze timestamp"])
def test_read_fails_with_one_line_and_leaves_no_temp_dir(cases: dict[str, Path], case: str, model: Path, tmp_path: Path) -> None:
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    result = run("read", str(cases[case]), "--model", str(model), tmp=scratch)
    table_row(f"read <{case}>", result)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr[-2000:]
    # no HTTP 409 Conflict (the digits alone turn up elsewhere: a session id such as vm-3b409b79d8d5,
    # a log line's milliseconds such as 20:03:17,409)
    assert not re.search(r"409 Conflict|HTTP(?:/[\d.]+)? 409\b", result.stderr)
    assert last_line(result.stderr).startswith("darkread: error:")
    assert [p.name for p in scratch.iterdir() if p.name.startswith("darkread-")] == []  # (libraries keep their own)
