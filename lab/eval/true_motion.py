"""The head's motion of a synthetic recording, taken from the simulator's truth instead of the events.

The simulator writes the page's pose per millisecond (``pose_truth.npz``: page mm -> camera point).
``TrueHeadMotion`` gives the edge's pipeline (``edge.head_motion.KnownHeadMotion``) what an exact
inertial sensor and a perfect tracker would: every event of a window moved, through the page, to
where its page point was at the window's newest event, and the scene's offset as the motion of the
page's centre in the sensor. Reading a recording with it (``darkread eval attribute``) shows how
much of a page's errors the head's motion causes; what remains is the frames' own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darkread.edge.deblur import moved_to
from darkread.edge.events import Events
from darkread.lab.truth import PageTruth, load_truth_and_pose
from darkread.models.train.annotate import project_page


class NoTruthError(ValueError):
    """The recording carries no simulator truth (a real recording)."""


class TrueHeadMotion:
    """``KnownHeadMotion`` from a synthetic recording's ``pose_truth.npz`` and ``calibration.json``."""

    def __init__(self, truth: PageTruth, pose_t_us: np.ndarray, pose_H: np.ndarray) -> None:
        self.truth = truth
        self._t = np.asarray(pose_t_us, np.float64)
        self._H_inv = np.linalg.inv(np.asarray(pose_H, np.float64))
        rows, cols = truth.ink.shape
        self._centre_mm = np.array([[cols / 2 / truth.px_per_mm, rows / 2 / truth.px_per_mm]])
        self._centre_at_start = self._centre_px(float(self._t[0]))

    @classmethod
    def from_recording(cls, recording: str | Path) -> TrueHeadMotion:
        recording = Path(recording)
        loaded = load_truth_and_pose(recording)
        if loaded is None:
            raise NoTruthError(f"{recording}: no simulator truth (pose_truth.npz, page_ink.npz); "
                               "the true-motion read takes synthetic recordings only")
        truth, pose = loaded
        return cls(truth, pose.t_us, pose.H)

    def _centre_px(self, t_us: float) -> np.ndarray:

        return project_page(self.truth.pose_at(t_us), self.truth.calibration, self._centre_mm)[0]

    def scene_px(self, t_us: int) -> tuple[float, float] | None:
        moved = self._centre_px(float(t_us)) - self._centre_at_start
        return None if not np.isfinite(moved).all() else (float(moved[0]), float(moved[1]))

    def warp(self, window: Events, origin: tuple[int, int], shape_hw: tuple[int, int]) -> Events:
        if window.shape[0] == 0:
            return window
        calib = self.truth.calibration
        t = window["t"].astype(np.float64)
        nearest = np.clip(np.searchsorted(self._t, t), 0, len(self._t) - 1)  # the pose per millisecond
        rays = calib.unproject(np.c_[window["x"], window["y"]].astype(np.float64))
        on_page = np.einsum("nij,nj->ni", self._H_inv[nearest], np.c_[rays, np.ones(len(rays))])
        page_mm = on_page[:, :2] / on_page[:, 2:3]
        camera = np.c_[page_mm, np.ones(len(page_mm))] @ self.truth.pose_at(float(t[-1])).T
        uv = calib.project(camera / camera[:, 2:3])
        return moved_to(window, uv[:, 0], uv[:, 1], origin, shape_hw)
