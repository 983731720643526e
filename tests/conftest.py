"""Fixtures shared by the whole suite."""

from __future__ import annotations

from pathlib import Path

import pytest

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


@pytest.fixture(scope="session")
def still_pangram():
    """The pangram read with the head still (``factories.pangram_session``)."""
    from factories import pangram_session

    return pangram_session("still")


@pytest.fixture(scope="session")
def walking_pangram():
    """The pangram read while walking (``factories.pangram_session``)."""
    from factories import pangram_session

    return pangram_session("walking")
