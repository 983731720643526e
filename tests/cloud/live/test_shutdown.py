"""Shutdown is bounded: a session task whose cancellation is lost (as a database driver can lose
it while handing out a connection) is left behind after ``timeout_s``, and the pools still stop,
so a systemd stop or a failover never waits on one stuck session (real SQLite store)."""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path
from typing import Any

import pytest
from page_readings import CountingOcr

from darkread.cloud.live import LiveConfig, LivePages
from darkread.cloud.store import SessionSpec, SqliteStore

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


class LosesOneCancellation(SqliteStore):
    """A store whose frame query for session "s" swallows its cancellation, then blocks until released."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self.entered = asyncio.Event()
        self.release = asyncio.Event()

    async def frames(self, session_id: str, **kwargs: Any) -> list[Any]:
        if session_id != "s":
            return await super().frames(session_id, **kwargs)
        self.entered.set()
        try:
            await asyncio.sleep(3600)
        except asyncio.CancelledError:
            await self.release.wait()  # the cancellation is lost here
        return []


async def test_a_stuck_session_task_does_not_hold_the_shutdown(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = LosesOneCancellation(tmp_path)
    await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
    pages = LivePages(store, CountingOcr(), LiveConfig())
    stuck = pages.get("s")
    healthy = pages.get("other")
    await asyncio.wait_for(store.entered.wait(), 5)
    started = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="darkread.cloud.live.sessions"):
        await pages.close(timeout_s=0.3)
    took = time.monotonic() - started
    assert took < 2.0, f"close took {took:.1f} s"
    assert pages.live_sessions == 0
    assert not stuck.task.done()  # left behind, as the log says
    assert "session s: its page task did not stop within" in caplog.text
    assert healthy.task.done()
    store.release.set()  # the lost cancellation let it run on: this test stops it for good
    await asyncio.sleep(0)
    stuck.task.cancel()
    await asyncio.wait({stuck.task}, timeout=5)
    assert stuck.task.done()
    await store.close()


async def test_close_stops_healthy_sessions_at_once(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = SqliteStore(tmp_path)
    await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
    pages = LivePages(store, CountingOcr(), LiveConfig())
    sessions = [pages.get(name) for name in ("s", "t", "u")]
    await asyncio.sleep(0.05)
    with caplog.at_level(logging.WARNING, logger="darkread.cloud.live.sessions"):
        await pages.close(timeout_s=5.0)
    assert all(session.task.cancelled() for session in sessions)
    assert "did not stop" not in caplog.text
    await store.close()
