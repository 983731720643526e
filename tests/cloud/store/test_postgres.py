"""What only the PostgreSQL backend does: several instances on one database, LISTEN/NOTIFY,
migrations under a lock, page images in the database. Every test runs a real server."""

from __future__ import annotations

import asyncio

import numpy as np
import psycopg
import pytest

from darkread.cloud.store import PageRecord, SessionSpec, StoredFrame, StoreError
from darkread.cloud.store.postgres import SCHEMA_VERSION, PostgresStore

pytestmark = [pytest.mark.anyio, pytest.mark.postgres]


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


def spec(session_id: str, mode: str = "frames") -> SessionSpec:
    return SessionSpec(session_id, "glasses", mode, (1280, 720), (100, 200))


def frame(seq: int) -> StoredFrame:
    mask = np.zeros((100, 200), np.uint8)
    mask[seq % 100, : 1 + seq % 200] = 1
    return StoredFrame(seq, seq * 50_000, mask, (seq, 0), (1.0, 2.0), seq=seq, events_used=1600)


async def test_a_frame_resent_to_another_instance_is_stored_once(postgres_url: str) -> None:
    a, b = await PostgresStore.open(postgres_url), await PostgresStore.open(postgres_url)
    try:
        await a.open_session(spec("s"))
        for seq in range(10):
            await a.add_frame("s", frame(seq))
        assert await b.open_session(spec("s")) == 9  # the failover's welcome: what the database holds
        resent = [await b.add_frame("s", frame(seq)) for seq in range(5, 15)]
        assert [r.stored for r in resent] == [False] * 5 + [True] * 5 and resent[-1].last_seq == 14
        # both instances receive the same seqs at once (an edge that failed over mid-batch)
        both = await asyncio.gather(*(store.add_frame("s", frame(seq)) for seq in range(15, 75) for store in (a, b)))
        assert sum(r.stored for r in both) == 60
        assert [f.seq for f in await a.frames("s", limit=1000)] == list(range(75))
        info = await b.session("s")
        assert info is not None and info.frames == 75 and info.last_seq == 74
    finally:
        await a.close()
        await b.close()


async def test_a_commit_on_one_instance_reaches_subscribers_on_the_other(postgres_url: str) -> None:
    a, b = await PostgresStore.open(postgres_url), await PostgresStore.open(postgres_url)
    heard: asyncio.Queue[tuple[str, int]] = asyncio.Queue()
    b.subscribe(lambda session_id, last_seq: heard.put_nowait((session_id, last_seq)))
    try:
        await asyncio.sleep(0.3)  # b's LISTEN connection is up
        await a.open_session(spec("s"))
        await asyncio.gather(*(a.add_frame("s", frame(seq)) for seq in range(20)))
        last = -1
        while last < 19:
            session_id, last = await asyncio.wait_for(heard.get(), 5)
            assert session_id == "s"
    finally:
        await a.close()
        await b.close()


async def test_instances_starting_together_migrate_once(postgres_url: str) -> None:
    stores = await asyncio.gather(*(PostgresStore.open(postgres_url) for _ in range(3)))
    for store in stores:
        await store.close()
    with psycopg.connect(postgres_url) as conn:
        assert conn.execute("SELECT version FROM schema_version").fetchall() == [(SCHEMA_VERSION,)]


async def test_a_database_from_a_newer_darkread_is_refused(postgres_url: str) -> None:
    await (await PostgresStore.open(postgres_url)).close()  # the current schema
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute("UPDATE schema_version SET version = %s", (SCHEMA_VERSION + 1,))
    with pytest.raises(StoreError, match=f"schema version {SCHEMA_VERSION + 1}"):
        await PostgresStore.open(postgres_url)


async def test_an_unreachable_database_is_one_line_without_the_password() -> None:
    with pytest.raises(StoreError) as caught:
        await PostgresStore.open("postgresql://darkread:s3cret@127.0.0.1:9/nowhere?connect_timeout=2")
    message = str(caught.value)
    assert "s3cret" not in message and "127.0.0.1:9/nowhere" in message and "\n" not in message


async def test_page_images_live_in_the_database_and_go_with_their_session(postgres_url: str) -> None:
    store = await PostgresStore.open(postgres_url)
    try:
        await store.open_session(spec("p", mode="pages"))
        mask = np.zeros((20, 30), np.uint8)
        mask[4, 3:25] = 1
        await store.add_page("p", PageRecord(0, 1, 10, mask, ((3, 4, 25, 5),)))
        with psycopg.connect(postgres_url) as conn:
            (key, size), = conn.execute("SELECT key, length(data) FROM blobs").fetchall()
        assert key == "pages/p/0.png" and size > 0
        assert await store.delete_session("p")
        with psycopg.connect(postgres_url) as conn:
            assert conn.execute("SELECT count(*) FROM blobs").fetchone() == (0,)
    finally:
        await store.close()
