"""Fixtures shared by the whole suite."""

from __future__ import annotations

import os
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from darkread.lab.shared_data import find_shared_data

if TYPE_CHECKING:
    from darkread.lab.fixtures.pg_server import TemporaryPostgres


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


def postgres_required() -> bool:
    """CI (and ``DARKREAD_REQUIRE_POSTGRES=1``) must run the PostgreSQL tests, never skip them."""
    return bool(os.environ.get("CI")) or os.environ.get("DARKREAD_REQUIRE_POSTGRES") == "1"


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[TemporaryPostgres]:
    """One real PostgreSQL server for the session, in a temporary directory on 127.0.0.1."""
    from darkread.lab.fixtures.pg_server import PostgresUnavailable, TemporaryPostgres

    server = TemporaryPostgres()
    try:
        server.start()
    except (PostgresUnavailable, OSError, subprocess.SubprocessError) as exc:
        log_tail = server.log_tail()
        server.stop()
        reason = f"PostgreSQL server could not be started: {exc}" + (f"\n{log_tail}" if log_tail else "")
        if postgres_required():
            pytest.fail(f"{reason} (required because CI or DARKREAD_REQUIRE_POSTGRES=1 is set)", pytrace=False)
        pytest.skip(reason)
    yield server
    server.stop()


@pytest.fixture
def postgres_url(postgres_server: TemporaryPostgres) -> str:
    """The URL of a new, empty database on the session's server."""
    return postgres_server.create_database(f"t{uuid.uuid4().hex[:16]}")


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
