"""Line assignment of fixations: the stitcher's logic and eyekit's methods on real readers."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from darkread.lab.gaze import human
from darkread.lab.gaze.lines import STITCHER, eyekit_available, product_lines

needs_eyekit = pytest.mark.skipif(eyekit_available() is not None, reason=str(eyekit_available()))

PASSAGES = {"p": {"__TextBlock__": {"position": [100.0, 200.0], "font_face": "Courier New", "font_size": 20.0,
                                     "line_height": 50.0, "text": ["a" * 40, "b" * 40, "c" * 40]}}}


def reader(drift_px: float = 0.0) -> tuple[dict, list[int]]:
    """Three lines read left to right (one regression on line 2), y drifting down by ``drift_px``."""
    fix, lines, t = [], [], 0
    for line in range(3):
        xs = [110 + 90 * k for k in range(9)]
        if line == 1:
            xs.insert(5, 300)  # a regression
        for x in xs:
            y = 200 + 50 * line + drift_px * len(fix) / 30
            fix.append({"x": x, "y": y, "start": t, "end": t + 200})
            lines.append(line)
            t += 230
    return {"t1": {"participant_id": "1", "age_group": "adult", "passage_id": "p",
                   "fixations": {"__FixationSequence__": fix}}}, lines


def test_stitcher_logic_follows_sweeps_and_drift() -> None:
    doc, gold = reader(drift_px=30.0)
    p = human.Passage("p", 100.0, 200.0, 20.0, 50.0, ["a" * 40] * 3)
    seq = doc["t1"]["fixations"]["__FixationSequence__"]
    x = np.array([f["x"] for f in seq], float)
    y = np.array([f["y"] for f in seq], float)
    assert product_lines(x, y, p.line_y, p.line_h).tolist() == gold
    far = y.copy()
    far[0] = 200 - 5 * 50  # far above the text block: on no line
    assert product_lines(x, far, p.line_y, p.line_h)[0] == -1


def _cli(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "darkread", "gaze", "lines", *args], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)


@pytest.mark.parametrize("method", [STITCHER, pytest.param("vote", marks=needs_eyekit)])
def test_gaze_lines_command(tmp_path: Path, method: str) -> None:
    doc, gold = reader()
    (tmp_path / "fix.json").write_text(json.dumps(doc))
    (tmp_path / "passages.json").write_text(json.dumps(PASSAGES))
    done = _cli(tmp_path, "fix.json", "--passages", "passages.json", "--json", "--method", method)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == {"t1": gold}


def test_gaze_lines_command_rejects_bad_input(tmp_path: Path) -> None:
    (tmp_path / "fix.json").write_text("{not json")
    (tmp_path / "passages.json").write_text(json.dumps(PASSAGES))
    done = _cli(tmp_path, "fix.json", "--passages", "passages.json", "--json", "--method", STITCHER)
    assert done.returncode == 1 and "not in the drift format" in done.stderr and "Traceback" not in done.stderr
    done = _cli(tmp_path, "fix.json", "--passages", "passages.json", "--method", "slice+warp")
    assert done.returncode == 1 and "at least three" in done.stderr
    done = _cli(tmp_path, "--help")
    assert done.returncode == 0 and "null" in done.stdout


@pytest.mark.shared
@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("DARKREAD_LONG_TESTS"), reason="minutes of eyekit warp: set DARKREAD_LONG_TESTS=1 (figures in docs/gaze.md)")
@needs_eyekit
def test_line_assignment_on_the_24_adult_readers(shared_data: Path) -> None:
    """Share of fixations on their gold line: the stitcher's logic, eyekit's best methods and the
    adopted vote; clean and with Aria-like tracker noise."""
    from darkread.lab.gaze.lines import DEFAULT_METHOD
    from darkread.lab.gaze.scores import line_accuracy, method_name

    drift = shared_data / "reading_gaze" / "drift"
    methods = (STITCHER, "slice", "stretch", "warp", DEFAULT_METHOD)  # eyekit's best three (docs/gaze.md: all)
    clean = line_accuracy(drift, methods)
    noisy = line_accuracy(drift, (STITCHER, "slice", "warp", DEFAULT_METHOD), noise=human.NoiseModel())
    print(f"\n| method | clean | Aria-like noise ({human.NoiseModel().rms_deg:.1f} deg RMS) |")
    for m in methods:
        k = method_name(m)
        print(f"| {k} | {clean[k]:.1%} | {f'{noisy[k]:.1%}' if k in noisy else '-'} |")
    adopted = clean[method_name(DEFAULT_METHOD)]
    assert adopted >= max(clean["slice"], clean["stretch"], clean["warp"])
    assert adopted >= 0.994
    assert noisy["warp"] > noisy[method_name(DEFAULT_METHOD)] > noisy["slice"]
