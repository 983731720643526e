"""Error attribution: a window's true ink, placed back by the same pose, is the page's ink again."""

from __future__ import annotations

import dataclasses

import numpy as np

from darkread.edge.io.calibration import Calibration
from darkread.lab.eval.attribution import Attribution, attribution_table, compose, ink_found, place_window, window_truth
from darkread.lab.truth import PageTruth
from darkread.models.train.annotate import window_rays


def _truth() -> PageTruth:
    """A 60 x 120 mm page with two ink bars, 4 px per mm, seen straight on: page mm -> sensor px is
    a scale and a shift (normalised coordinates = mm / 350, focal length 1400 px)."""
    ink = np.zeros((240, 480), np.float32)
    ink[40:60, 40:400] = 1.0
    ink[120:130, 100:300] = 1.0
    calib = Calibration(width=1280, height=720, fx=1400.0, fy=1400.0, cx=640.0, cy=360.0,
                        distortion=(0.0, 0.0, 0.0, 0.0), T_event_cpf=np.eye(4), gaze_to_event_time_offset_us=0)
    H = np.array([[1 / 350, 0, -0.3], [0, 1 / 350, -0.1], [0, 0, 1.0]])
    return PageTruth(ink, 4.0, lambda t_us: H, calib)


def test_true_windows_placed_back_give_the_page_ink() -> None:
    truth = _truth()
    origins = [(250, 200), (330, 215)]
    H = truth.pose_at(0.0)
    rays = [window_rays(truth.calibration, o, (100, 200)) for o in origins]
    windows = [window_truth(truth, r, (100, 200), H) for r in rays]
    assert all(w.any() for w in windows)
    page = compose(windows, [place_window(truth, r, o, (100, 200), H) for r, o in zip(rays, origins)], truth.ink.shape)
    ink = page < 128
    seen = ink.any(axis=0)
    assert ink.sum() > 0
    assert np.mean(truth.ink[ink] > 0.5) > 0.9  # what the windows put on the page is the page's ink
    assert np.mean(ink[truth.ink > 0.5]) > 0.5 * np.mean(seen)  # and a fair share of it where they looked


def test_ink_found_counts_within_one_pixel() -> None:
    target = np.zeros((20, 20), np.uint8)
    target[5, 5:15] = 1
    shifted = np.roll(target, 1, axis=0)  # one pixel off: found
    far = np.roll(target, 4, axis=0)  # four pixels off: not
    assert ink_found(shifted, target) == (10, 10, 10, 10)
    assert ink_found(far, target) == (0, 10, 0, 10)
    assert ink_found(np.zeros_like(target), target) == (0, 10, 0, 0)


def test_table_groups_by_lux_and_motion() -> None:
    rows = [Attribution("a", 10.0, "still", 5, 0.1, 0.1, 0.0, 0.9, 0.9),
            Attribution("b", 10.0, "walking", 5, 1.0, 0.9, 0.05, 0.3, 0.5)]
    table = attribution_table(rows)
    assert "| 10 | still | 1 | 10.0% | – | 10.0% | 0.0% | 90% | 90% |" in table  # not read with the true motion
    assert "| 10 | **all** | 2 | 55.0% | – | 50.0% | 2.5% | 60% | 70% |" in table
    known = [dataclasses.replace(rows[0], cer_true_motion=0.05), dataclasses.replace(rows[1], cer_true_motion=0.4)]
    assert "| 10 | **all** | 2 | 55.0% | 22.5% | 50.0% | 2.5% | 60% | 70% |" in attribution_table(known)
    assert "| 10 | **all** | 2 | 55.0% | – |" in attribution_table([known[0], rows[1]])  # a mean of all or none
