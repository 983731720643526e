"""Shutdown is bounded: a session task whose cancellation is lost (as a database driver can lose
it while handing out a connection) is cancelled again, and one that still runs is left behind
after ``timeout_s``; the pools still stop, so a systemd stop or a failover never waits on one
stuck session (real SQLite store)."""

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


class LosesCancellations(SqliteStore):
    """A store whose frame query for session "s" swallows ``lose`` cancellations (all: until
    released), as a database driver can while handing out a connection."""

    def __init__(self, root: Path, lose: int | None) -> None:
        super().__init__(root)
        self.lose = lose
        self.lost = 0
        self.entered = asyncio.Event()
        self.release = asyncio.Event()

    async def frames(self, session_id: str, **kwargs: Any) -> list[Any]:
        if session_id != "s":
            return await super().frames(session_id, **kwargs)
        self.entered.set()
        while not self.release.is_set():
            try:
                await self.release.wait()
            except asyncio.CancelledError:
                if self.lose is not None and self.lost >= self.lose:
                    raise
                self.lost += 1  # lost: the task runs on
        return []


async def open_pages(store: SqliteStore) -> LivePages:
    await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
    return LivePages(store, CountingOcr(), LiveConfig())


async def test_a_lost_cancellation_is_sent_again(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = LosesCancellations(tmp_path, lose=1)
    pages = await open_pages(store)
    stuck = pages.get("s")
    await asyncio.wait_for(store.entered.wait(), 5)
    started = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="darkread.cloud.live.sessions"):
        await pages.close(timeout_s=5.0)
    assert time.monotonic() - started < 1.0
    assert store.lost == 1 and stuck.task.cancelled()
    assert "did not stop" not in caplog.text
    await store.close()


async def test_a_stuck_session_task_does_not_hold_the_shutdown(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = LosesCancellations(tmp_path, lose=None)
    pages = await open_pages(store)
    stuck = pages.get("s")
    healthy = pages.get("other")
    await asyncio.wait_for(store.entered.wait(), 5)
    started = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="darkread.cloud.live.sessions"):
        await pages.close(timeout_s=0.5)
    took = time.monotonic() - started
    assert took < 2.0, f"close took {took:.1f} s"
    assert pages.live_sessions == 0
    assert not stuck.task.done() and store.lost >= 2  # sent again, still lost: left behind, as the log says
    assert "session s: its page task did not stop within 0.5 s" in caplog.text
    assert healthy.task.cancelled()
    store.lose = store.lost  # the next cancellation gets through
    stuck.task.cancel()
    await asyncio.wait({stuck.task}, timeout=5)
    assert stuck.task.cancelled()
    await store.close()


async def test_close_stops_healthy_sessions_at_once(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = SqliteStore(tmp_path)
    pages = await open_pages(store)
    sessions = [pages.get(name) for name in ("s", "t", "u")]
    await asyncio.sleep(0.05)
    with caplog.at_level(logging.WARNING, logger="darkread.cloud.live.sessions"):
        await pages.close(timeout_s=5.0)
    assert all(session.task.cancelled() for session in sessions)
    assert "did not stop" not in caplog.text
    await store.close()
