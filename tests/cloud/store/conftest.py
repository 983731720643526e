"""Backend-parametrised store fixtures: every contract test runs once per ``SessionStore`` backend.

A new backend adds one entry to ``BACKENDS`` (a factory that opens the store on a location that
survives reopening) and must then pass ``test_contract.py`` unchanged.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import pytest

from darkread.cloud.store import SessionStore, SqliteStore


async def _sqlite(location: Path) -> SessionStore:
    return SqliteStore(location / "sqlite")


BACKENDS: dict[str, Callable[[Path], Awaitable[SessionStore]]] = {"sqlite": _sqlite}

Opener = Callable[[], Awaitable[SessionStore]]


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(params=sorted(BACKENDS))
def open_store(request: pytest.FixtureRequest, tmp_path: Path) -> Opener:
    """``await open_store()`` opens the backend on this test's location (again: a restart)."""
    factory = BACKENDS[request.param]
    return lambda: factory(tmp_path)


@pytest.fixture
async def store(open_store: Opener) -> AsyncIterator[SessionStore]:
    opened = await open_store()
    yield opened
    await opened.close()
