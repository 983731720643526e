from __future__ import annotations

import numpy as np

from darkread.models.synth.fonts import FACES
from darkread.models.synth.gaze import gaze_angles, points_from_angles, reading_scanpath
from darkread.models.synth.page import render_page
from darkread.models.synth.text import make_lines


def _scanpath(seed: int = 0):
    rng = np.random.default_rng(seed)
    page = render_page(make_lines("paragraph", 6, 45, rng), FACES[0], 12.0, 1e-4)
    return page, reading_scanpath(page, 40.0, 0.05, rng)


def test_fixation_durations_in_reading_range():
    _, sp = _scanpath()
    d = np.array([f.t1_s - f.t0_s for f in sp.fixations]) * 1000
    normal = np.array([f.kind not in ("sweep",) for f in sp.fixations])
    assert d[normal].min() >= 149.9 and d.max() <= 500.1
    assert 200 <= d[normal].mean() <= 260


def test_forward_saccades_and_regressions():
    _, sp = _scanpath(1)
    fx = sp.fixations
    steps = [b.char - a.char for a, b in zip(fx, fx[1:]) if b.kind == "forward" and a.line == b.line]
    assert 7.0 <= np.mean(steps) <= 9.0
    assert np.percentile(steps, 10) >= 5.5 and np.percentile(steps, 90) <= 10.5
    saccades = [f for f in fx[1:]]
    regressions = sum(f.kind == "regression" for f in saccades) / len(saccades)
    assert 0.05 <= regressions <= 0.18
    assert any(f.kind == "corrective" for f in fx)  # undershooting return sweeps get corrected


def test_saccade_durations_within_20_to_40_ms():
    page, sp = _scanpath(2)
    fx = sp.fixations
    for a, b in zip(fx, fx[1:]):
        if b.kind == "forward":
            assert 0.019 <= b.t0_s - a.t1_s <= 0.041


def test_gaze_angles_follow_the_format_convention():
    p = np.array([[0.05, -0.02, 0.4]])  # to the wearer's left, slightly down
    left, right, pitch, depth = gaze_angles(p)
    assert left[0] > right[0] > 0  # near target: left yaw larger, as in the README
    tc = (np.tan(left) + np.tan(right)) / 2
    back = points_from_angles(np.arctan(tc), pitch, depth)
    np.testing.assert_allclose(back, p, atol=1e-12)


def test_tracker_error_is_one_to_two_degrees_and_partly_constant():
    from darkread.models.synth.gaze import TrackerModel, row_times_us, tracker_rows

    rng = np.random.default_rng(3)
    errors, biases = [], []
    for _ in range(20):
        model = TrackerModel.random(rng)
        t = row_times_us(1_000_000, 5.0, model.rate_hz, model.missing_p, rng)
        assert 0.9 * 5 * 60 < t.size <= 5 * 60 + 1 and np.all(np.diff(t) > 0)
        truth = np.tile([[0.05, -0.03, 0.45]], (t.size, 1))
        left, right, pitch, depth = tracker_rows(truth, t, np.zeros(t.size, bool), model, rng)
        yaw = np.arctan((np.tan(left) + np.tan(right)) / 2)
        err = np.degrees(np.hypot(yaw - np.arctan(0.05 / 0.45), pitch - np.arctan(-0.03 / 0.45)))
        errors.append(np.sqrt(np.mean(err**2)))
        biases.append(np.degrees(np.hypot(*model.bias_rad)))
    assert 0.8 < np.median(errors) < 2.5
    assert np.median(biases) > 0.5  # a constant part
    blink = np.ones(5, bool)
    _, _, pitch_b, _ = tracker_rows(np.tile([[0.0, 0.0, 0.4]], (5, 1)), np.arange(5) * 16_667, blink, model, rng)
    assert np.all(np.degrees(np.abs(pitch_b)) > 5)  # blink rows are far off


def test_first_pass_ends_when_the_reader_leaves_the_last_line():
    page, sp = _scanpath(2)
    end = sp.first_pass_end_s()
    last = len(page.lines) - 1
    before = [f for f in sp.fixations if f.t1_s <= end]
    assert {f.line for f in before} == set(range(len(page.lines)))  # every line was looked at
    assert before[-1].line == last
    after = [f for f in sp.fixations if f.t0_s > end]
    assert after and after[0].line == 0 and after[0].kind == "sweep"  # the re-reading starts over
    page1 = render_page(["one line only"], FACES[0], 12.0, 1e-4)
    assert 0.2 < reading_scanpath(page1, 5.0, 0.05, np.random.default_rng(0)).first_pass_end_s() < 2.0
