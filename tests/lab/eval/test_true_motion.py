"""The head's motion from the simulator's truth: a window's events land where their page points
were at its newest event, and the scene offset follows the page."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.events import EVENT_CD_DTYPE
from darkread.edge.head_motion import KnownHeadMotion
from darkread.edge.io.calibration import Calibration
from darkread.lab.eval.true_motion import NoTruthError, TrueHeadMotion
from darkread.lab.truth import PageTruth
from darkread.models.train.annotate import project_page

SPEED_MM_PER_S = 20.0  # the page slides right this fast: 20 mm/s -> 80 px/s at 4 px/mm seen from 350 mm


def _sliding_page() -> TrueHeadMotion:
    calib = Calibration(width=1280, height=720, fx=1400.0, fy=1400.0, cx=640.0, cy=360.0,
                        distortion=(0.0, 0.0, 0.0, 0.0), T_event_cpf=np.eye(4), gaze_to_event_time_offset_us=0)
    t = np.arange(0, 200_001, 1000, dtype=np.float64)

    def H(t_us: float) -> np.ndarray:  # page mm -> normalised camera point; the page moves +x over time
        return np.array([[1 / 350, 0, -0.3 + SPEED_MM_PER_S * t_us * 1e-6 / 350], [0, 1 / 350, -0.1], [0, 0, 1.0]])

    truth = PageTruth(np.zeros((240, 480), np.float32), 4.0, H, calib)
    return TrueHeadMotion(truth, t, np.stack([H(x) for x in t]))


def _events_of(motion: TrueHeadMotion, page_mm: np.ndarray, times_us: np.ndarray) -> np.ndarray:
    """Each page point seen at its time (sensor pixel, rounded)."""
    ev = np.zeros(len(times_us), EVENT_CD_DTYPE)
    for i, (point, t) in enumerate(zip(page_mm, times_us)):
        u, v = project_page(motion.truth.pose_at(float(t)), motion.truth.calibration, point[None])[0]
        ev[i] = (round(u), round(v), 1, int(t))
    return ev


def test_it_is_a_known_head_motion() -> None:
    assert isinstance(_sliding_page(), KnownHeadMotion)


def test_a_windows_events_are_moved_to_where_their_page_points_were_at_its_newest_event() -> None:
    motion = _sliding_page()
    point = np.array([[60.0, 40.0]])
    times = np.arange(100_000, 150_001, 5000)  # 50 ms: the page slides 4 px
    smeared = _events_of(motion, np.repeat(point, len(times), axis=0), times)
    assert np.ptp(smeared["x"]) >= 3  # the one point smeared over the window's span
    origin = (int(smeared["x"].min()) - 50, int(smeared["y"].min()) - 50)
    warped = motion.warp(smeared, origin, (100, 200))
    assert len(warped) == len(smeared) and np.ptp(warped["x"]) == 0 and np.ptp(warped["y"]) == 0
    assert warped["x"][0] == smeared["x"][-1]  # where the page was at the newest event
    assert np.array_equal(warped["t"], smeared["t"]) and np.array_equal(warped["p"], smeared["p"])


def test_events_moved_out_of_the_window_are_dropped() -> None:
    motion = _sliding_page()
    times = np.arange(100_000, 150_001, 5000)
    smeared = _events_of(motion, np.repeat([[60.0, 40.0]], len(times), axis=0), times)
    right_edge = int(smeared["x"][-1])
    warped = motion.warp(smeared, (right_edge - 199, int(smeared["y"][0]) - 50), (100, 200))  # newest place on the last column
    assert len(warped) == len(smeared)
    assert len(motion.warp(smeared, (right_edge - 200, int(smeared["y"][0]) - 50), (100, 200))) == 0
    assert len(motion.warp(smeared[:0], (0, 0), (100, 200))) == 0


def test_the_scene_offset_is_the_page_motion_since_the_start() -> None:
    motion = _sliding_page()
    assert motion.scene_px(0) == pytest.approx((0.0, 0.0), abs=1e-9)
    dx, dy = motion.scene_px(100_000)
    assert dx == pytest.approx(SPEED_MM_PER_S * 0.1 / 350 * 1400, rel=1e-6) and dy == pytest.approx(0.0, abs=1e-9)


def test_a_recording_without_truth_is_refused_in_one_line(tmp_path) -> None:
    with pytest.raises(NoTruthError, match="synthetic recordings only"):
        TrueHeadMotion.from_recording(tmp_path)
