"""A real reader's fixations replayed on a synthetic page."""

from __future__ import annotations

import json

import numpy as np
import pytest

from darkread.models.synth.fonts import face_by_name
from darkread.models.synth.human_scanpath import SHIPPED, HumanScanpath, replay_scanpath
from darkread.models.synth.page import render_page


@pytest.fixture(scope="module")
def page():
    lines = ["the quick brown fox jumps ov", "er the lazy dog and then it", "runs far away into the dark", "wood"]
    return render_page(lines, face_by_name("DejaVu Sans"), 12.0, 1e-4, line_spacing=1.5)


def test_shipped_scanpath_carries_its_licence_and_reads_lines_in_order() -> None:
    doc = json.loads(SHIPPED.read_text())
    assert "MIT License" in doc["license"] and "Vasilev" in doc["license"]
    human = HumanScanpath.load()
    assert len(human.line) > 100 and human.line[0] == 0
    assert np.all(np.diff(human.line) >= 0) and set(human.line) == set(range(10))  # ten lines, top to bottom
    same_line = np.diff(human.line) == 0
    assert np.sum(same_line & (np.diff(human.frac) < 0)) >= 10  # regressions within lines
    assert 100 < np.median(human.duration_ms) < 350


def test_replay_keeps_durations_order_and_vertical_offsets(page) -> None:
    human = HumanScanpath.load()
    rng = np.random.default_rng(0)
    path = replay_scanpath(page, human, 18.0, 0.05, rng)
    fx = path.fixations
    n = len(fx)
    assert path.t[-1] >= 18.0
    np.testing.assert_allclose([f.t1_s - f.t0_s for f in fx[:50]], human.duration_ms[:50] / 1000.0)
    lines = np.array([f.line for f in fx[:60]])
    np.testing.assert_array_equal(lines, (human.line[:60] - human.line.min()) % len(page.lines))
    pitch = float(np.median(np.diff(page.line_y)))
    dy = np.array([(f.y - page.line_y[f.line]) / pitch for f in fx[:60]])
    np.testing.assert_allclose(dy, human.dy_pitch[:60])
    assert {"sweep", "regression", "forward"} <= {f.kind for f in fx}
    assert path.first_pass_end_s() < 20.0  # the page is read once within the recording cap
    # saccades between fixations: the dense track moves between consecutive fixation centres
    mid = (fx[3].t1_s + fx[4].t0_s) / 2
    p = path.position(mid)
    assert min(fx[3].x, fx[4].x) - 1 <= p[0] <= max(fx[3].x, fx[4].x) + 1
    assert n > 40


def test_synth_recording_rejects_a_missing_scanpath_file(tmp_path) -> None:
    from darkread.cli import main

    assert main(["synth", "recording", str(tmp_path / "r"), "--scanpath-file", str(tmp_path / "none.json")]) == 1
