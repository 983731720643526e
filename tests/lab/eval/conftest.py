"""A tiny recording with a known gaze: straight ahead, so the fovea sits at the principal point."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from factories import random_events

from darkread.edge.io.calibration import Calibration, save_calibration
from darkread.edge.io.gaze_csv import write_gaze_csv
from darkread.edge.io.raw import write_raw

TINY_CENTRE = (640.0, 360.0)  # principal point = where a straight-ahead gaze lands
TINY_SECONDS = 0.05
GAZE_OFFSET_US = 1_000_000  # event clock = device clock + this


def _tiny_events() -> np.ndarray:
    ev = random_events(30_000, t0=GAZE_OFFSET_US + 10_000, rate_hz=30_000 / TINY_SECONDS, seed=4)
    key = ev["t"].astype(np.int64) * 1_000_000 + ev["y"].astype(np.int64) * 1280 + ev["x"]
    _, first = np.unique(key, return_index=True)  # one event per pixel and microsecond, as a sensor reports
    return ev[np.sort(first)]


@pytest.fixture
def tiny_recording(tmp_path: Path) -> Path:
    folder = tmp_path / "tiny"
    folder.mkdir()
    write_raw(folder / "events.raw", _tiny_events())
    flip = np.diag([-1.0, -1.0, 1.0, 1.0])  # CPF (x left, y up) -> camera (x right, y down), same origin
    calib = Calibration(width=1280, height=720, fx=1400.0, fy=1400.0, cx=TINY_CENTRE[0], cy=TINY_CENTRE[1],
                        distortion=(0.0, 0.0, 0.0, 0.0), T_event_cpf=flip, gaze_to_event_time_offset_us=GAZE_OFFSET_US)
    save_calibration(folder / "calibration.json", calib)
    t = np.arange(0, 100_000, 16_000, dtype=np.int64)
    zeros = np.zeros(t.shape[0])
    write_gaze_csv(folder / "general_eye_gaze.csv", t, zeros, zeros, zeros, np.full(t.shape[0], 0.5))
    (folder / "text.txt").write_text("tiny")
    (folder / "meta.json").write_text(json.dumps({"duration_s": TINY_SECONDS, "lux": 100.0}))
    return folder


@pytest.fixture
def tiny_events() -> np.ndarray:
    """The events of ``tiny_recording`` (time-sorted, at most one per pixel and microsecond)."""
    return _tiny_events()
