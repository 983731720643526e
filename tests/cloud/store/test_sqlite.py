"""What only the SQLite backend does: schema migrations, group commit."""

from __future__ import annotations

import asyncio
import sqlite3
import threading
from contextlib import closing
from pathlib import Path

import cv2
import numpy as np
import pytest

from darkread.cloud.store import SessionSpec, SqliteStore, StoredFrame, StoreError, WriteResult
from darkread.cloud.store.sqlite import MIGRATIONS, SCHEMA_VERSION

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


def frame(seq: int) -> StoredFrame:
    return StoredFrame(seq, seq * 100, np.eye(100, 200, dtype=np.uint8), (0, 0), (1.0, 2.0), seq=seq, events_used=1600)


def _old_database(data_dir: Path) -> None:
    """A database and page file as written before the schema was versioned (user_version 0)."""
    (data_dir / "pages" / "old").mkdir(parents=True)
    cv2.imwrite(str(data_dir / "pages" / "old" / "3.png"), np.where(np.eye(8, 12) > 0, 0, 255).astype(np.uint8))
    with closing(sqlite3.connect(data_dir / "darkread.sqlite3")) as conn:
        conn.executescript(MIGRATIONS[0])
        conn.execute("INSERT INTO sessions VALUES ('old', 'g', 'pages', 1280, 720, 100, 200, 1.0, 2.0, 3)")
        conn.execute(
            "INSERT INTO pages VALUES ('old', 3, 1, 5, 8, 12, ?, '[[0, 0, 4, 4]]')",
            (str(data_dir / "pages" / "old" / "3.png"),),
        )
        conn.commit()


async def test_an_unversioned_database_is_migrated_at_start_up(tmp_path: Path) -> None:
    _old_database(tmp_path)
    store = SqliteStore(tmp_path)
    try:
        with closing(sqlite3.connect(store.db_path)) as conn:
            assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
        page = await store.latest_page("old")
        assert page is not None and page.lines == ((0, 0, 4, 4),)
        np.testing.assert_array_equal(page.mask, np.eye(8, 12, dtype=np.uint8))
        assert await store.open_session(SessionSpec("old", "g", "pages", (1280, 720), (100, 200))) == 3
    finally:
        await store.close()
    again = SqliteStore(tmp_path)  # nothing left to migrate
    await again.close()


def test_a_database_from_a_newer_darkread_is_refused(tmp_path: Path) -> None:
    with closing(sqlite3.connect(tmp_path / "darkread.sqlite3")) as conn:
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    with pytest.raises(StoreError, match="schema version"):
        SqliteStore(tmp_path)


async def test_writes_queued_together_commit_together(tmp_path: Path) -> None:
    """Inside a batch a reader sees none of its writes yet: they share one commit (one fsync)."""
    store = SqliteStore(tmp_path)
    release, running = threading.Event(), threading.Event()

    def hold_writer(_conn: object) -> None:  # its batch is formed once it runs; the rest queue up
        running.set()
        release.wait(5)

    def count_committed(_conn: object) -> int:
        with closing(sqlite3.connect(store.db_path)) as reader:
            return int(reader.execute("SELECT COUNT(*) FROM frames").fetchone()[0])

    try:
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
        blocker = store._writer.submit(hold_writer)
        while not running.wait(0.001):
            await asyncio.sleep(0.001)
        writes = [asyncio.ensure_future(store.add_frame("s", frame(seq))) for seq in range(3)]
        await asyncio.sleep(0.01)  # the writes reach the writer's queue
        seen = store._writer.submit(count_committed)
        release.set()
        await blocker
        assert await seen == 0
        assert all(r.stored for r in await asyncio.gather(*writes))
        assert len(await store.frames("s")) == 3
    finally:
        await store.close()


async def test_a_failing_write_fails_alone(tmp_path: Path) -> None:
    store = SqliteStore(tmp_path)
    try:
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
        results = await asyncio.gather(
            store.add_frame("s", frame(0)), store.add_frame("nobody", frame(0)), store.add_frame("s", frame(1)),
            return_exceptions=True,
        )  # fmt: skip
        assert results[0] == WriteResult(True, 0) and results[2] == WriteResult(True, 1)
        assert isinstance(results[1], StoreError)
    finally:
        await store.close()


async def test_reads_keep_one_connection_per_thread_and_see_every_commit(tmp_path: Path) -> None:
    """The live pages read every few frames: a read reuses its worker thread's connection (opening
    one cost more than the query), still sees each commit at once, and close() closes them all."""
    store = SqliteStore(tmp_path)
    try:
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
        for seq in range(40):
            await store.add_frame("s", frame(seq))
            assert [f.seq for f in await store.frames("s", after_seq=seq - 1)] == [seq]  # read after write
        await asyncio.gather(*(store.page_breaks("s") for _ in range(64)))
        readers = list(store._readers)
        assert 1 <= len(readers) <= threading.active_count()  # per thread, not per read
    finally:
        await store.close()
    assert store._readers == []
    with pytest.raises(sqlite3.ProgrammingError):  # closed with the store
        readers[0].execute("SELECT 1")


async def test_a_failed_read_starts_the_next_one_on_a_fresh_connection(tmp_path: Path) -> None:
    store = SqliteStore(tmp_path)
    try:
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
        with pytest.raises(StoreError, match="read failed"):
            await store._read(lambda conn: conn.execute("SELECT * FROM no_such_table").fetchall())
        await store.add_frame("s", frame(0))
        assert [f.seq for f in await store.frames("s")] == [0]
    finally:
        await store.close()
