"""Backend-parametrised store fixtures: every contract test runs once per ``SessionStore`` backend.

A new backend adds one entry to ``BACKENDS`` (the name, its pytest marks, and how to open it on
a location that survives reopening) and must then pass ``test_contract.py`` unchanged.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import pytest

from darkread.cloud.store import SessionStore, SqliteStore

Opener = Callable[[], Awaitable[SessionStore]]


def _sqlite(request: pytest.FixtureRequest, tmp_path: Path) -> Opener:
    async def open_() -> SessionStore:
        return SqliteStore(tmp_path / "sqlite")

    return open_


def _postgres(request: pytest.FixtureRequest, tmp_path: Path) -> Opener:
    from darkread.cloud.store.postgres import PostgresStore

    url = request.getfixturevalue("postgres_url")  # a fresh database on the session's real server
    return lambda: PostgresStore.open(url)


BACKENDS: dict[str, tuple[Callable[[pytest.FixtureRequest, Path], Opener], tuple[pytest.MarkDecorator, ...]]] = {
    "sqlite": (_sqlite, ()),
    "postgres": (_postgres, (pytest.mark.postgres,)),
}


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(params=[pytest.param(name, marks=marks) for name, (_, marks) in sorted(BACKENDS.items())])
def open_store(request: pytest.FixtureRequest, tmp_path: Path) -> Opener:
    """``await open_store()`` opens the backend on this test's location (again: a restart)."""
    factory, _ = BACKENDS[request.param]
    return factory(request, tmp_path)


@pytest.fixture
async def store(open_store: Opener) -> AsyncIterator[SessionStore]:
    opened = await open_store()
    yield opened
    await opened.close()
