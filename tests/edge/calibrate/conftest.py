"""Synthetic calibration captures shared by the calibration tests (simulated once per session).

One pair of glasses (``device_seed=0``): a still capture in which the board flashes six times (for
the clock) and a capture with the board at six poses (for intrinsics and the pose). Both are kept
small: the board is far enough away that each switch fires a few hundred thousand events.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from darkread.lab.fixtures.calibration_capture import (
    FlashCapture,
    FlashCaptureSpec,
    simulate_flash_capture,
    write_flash_capture,
)


@pytest.fixture(scope="session")
def still_capture() -> FlashCapture:
    return simulate_flash_capture(
        FlashCaptureSpec(seed=2, device_seed=0, start_s=0.0, n_poses=1, pose_s=2.0, flashes_per_pose=6, distance_m=(1.0, 1.1))
    )


@pytest.fixture(scope="session")
def posed_capture() -> FlashCapture:
    return simulate_flash_capture(FlashCaptureSpec(seed=1, device_seed=0, start_s=3.0, n_poses=6))


@pytest.fixture(scope="session")
def still_capture_dir(still_capture: FlashCapture, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flash_capture(tmp_path_factory.mktemp("still_capture"), still_capture)
