"""Fixtures shared by the whole suite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from darkread.edge.events import EVENT_CD_DTYPE
from darkread.paths import find_shared_data


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; tests that need it skip with a reason when it is absent."""
    path = find_shared_data()
    if path is None:
        pytest.skip("../shared/data is not present (set DARKREAD_SHARED_DATA to run these tests)")
    return path


@pytest.fixture(scope="session")
def shared_sample_recording(shared_data: Path) -> Path:
    return shared_data / "sample_recording"


@pytest.fixture(scope="session")
def real_events_dir(shared_data: Path) -> Path:
    return shared_data / "real_events"


@pytest.fixture(scope="session")
def aria_dir(shared_data: Path) -> Path:
    return shared_data / "aria" / "projectaria_tools"


def random_events(
    n: int, width: int = 1280, height: int = 720, t0: int = 0, rate_hz: float = 1e6, seed: int = 0
) -> np.ndarray:
    """Random time-sorted events (a tonic-style factory)."""
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=EVENT_CD_DTYPE)
    ev["x"] = rng.integers(0, width, n)
    ev["y"] = rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    ev["t"] = t0 + np.sort(rng.integers(0, max(1, int(n / rate_hz * 1e6)), n))
    return ev
