"""Fixtures the integration tests share."""

from __future__ import annotations

from pathlib import Path

import pytest

from darkread.core.paths import SAMPLE_RECORDING


@pytest.fixture
def recording(request: pytest.FixtureRequest) -> Path:
    """The sample recording shipped with the package, or the shared data's copy when it is not built."""
    if (SAMPLE_RECORDING / "events.raw").is_file():
        return SAMPLE_RECORDING
    return request.getfixturevalue("shared_sample_recording")
