"""A question does not wait behind a backlog of stitching: it cuts the batch being stitched short,
waits for the frames stored before it only ``catch_up_s``, and answers from the page stitched so
far, naming its version (real SQLite store, real stitcher; the OCR engine counts ink)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from page_readings import CountingOcr, reading_frames

from darkread.cloud.live import LiveConfig, LivePages
from darkread.cloud.store import SessionSpec, SqliteStore
from darkread.cloud.stream import stored_frame

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


async def stored(tmp_path: Path, passes: int) -> tuple[SqliteStore, list]:
    store = SqliteStore(tmp_path)
    await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200)))
    records = []
    for _ in range(passes):
        t0_us = records[-1].t_us + 200_000 if records else 0
        records += [stored_frame(f) for f in reading_frames(first_seq=len(records), t0_us=t0_us)]
    for record in records:
        await store.add_frame("s", record)
    return store, records


@contextlib.asynccontextmanager
async def hand_fed(tmp_path: Path, cfg: LiveConfig) -> AsyncIterator[tuple[LivePages, object, list]]:
    """Live pages over one stored pass, with the session's own stitch task stopped: fed by hand."""
    store, records = await stored(tmp_path, 1)
    pages = LivePages(store, CountingOcr(), cfg)
    try:
        session = pages.get("s")
        await session.close()
        yield pages, session, records
    finally:
        await pages.close()
        await store.close()


async def test_a_waiting_question_ends_the_batch_after_the_current_frame(tmp_path: Path) -> None:
    store, records = await stored(tmp_path, 1)
    pages = LivePages(store, CountingOcr(), LiveConfig())
    try:
        session = pages.get("s")
        await session.caught_up(60)
        fresh = LivePages(store, CountingOcr(), LiveConfig()).get("s")  # a second paginator, to feed by hand
        await fresh.close()
        assert await asyncio.to_thread(fresh._stitch, records[:10], []) == 10
        fresh._renders_waiting = 1
        assert await asyncio.to_thread(fresh._stitch, records[10:20], []) == 1
        assert fresh.paginator.current.last_seq == records[10].seq
    finally:
        await pages.close()
        await store.close()


async def test_a_question_during_a_backlog_answers_from_the_page_so_far(tmp_path: Path) -> None:
    store, records = await stored(tmp_path, 4)
    ocr = CountingOcr()
    pages = LivePages(store, ocr, LiveConfig(catch_up_s=0.05, batch_frames=64))
    try:
        session = pages.get("s")  # the pages start rebuilding from the store ...
        deadline = asyncio.get_running_loop().time() + 60
        while not session.paginator.pages:  # (a loaded host may take more than a moment for the first batch)
            assert asyncio.get_running_loop().time() < deadline, "no frame stitched within 60 s"
            await asyncio.sleep(0.01)
        answer = await pages.ask("s", upto_seq=records[-1].seq)  # ... and are asked long before they are done
        assert answer.frames_pending and 0 < answer.reading.version < len(records)
        assert answer.page.last_seq < records[-1].seq
        assert await pages.get("s").caught_up(120)
        final = await pages.ask("s", upto_seq=records[-1].seq)
        assert not final.frames_pending and final.reading.version > answer.reading.version
        assert final.page.last_seq == records[-1].seq
    finally:
        await pages.close()
        await store.close()


async def test_stitching_gives_way_while_a_question_is_read_but_never_starves(tmp_path: Path) -> None:
    async with hand_fed(tmp_path, LiveConfig(questions_first_s=0.2)) as (pages, other, records):
        with pages.answering():  # another session's question is being read
            assert await asyncio.to_thread(other._stitch, records[:10], []) == 1
            started = asyncio.get_running_loop().time()
            await pages.questions_first()  # the question goes on: stitching waits its bounded turn
            assert asyncio.get_running_loop().time() - started >= 0.15
        started = asyncio.get_running_loop().time()
        await pages.questions_first()  # answered: no wait
        assert asyncio.get_running_loop().time() - started < 0.1
        assert await asyncio.to_thread(other._stitch, records[1:10], []) == 9


async def test_the_session_a_question_waits_for_does_not_give_way(tmp_path: Path) -> None:
    """With many wearers asking, some question is always being read; a question waiting for its
    own session's frames must not wait for that session's stitching to give way to the others."""
    async with hand_fed(tmp_path, LiveConfig(questions_first_s=5.0)) as (pages, waited, records):
        with pages.answering():  # another session's question is being read
            waited._catching_up = 1  # ... and a question waits for this one
            assert await asyncio.to_thread(waited._stitch, records[:10], []) == 10  # the batch goes on
            waited._wanted.set()
            started = asyncio.get_running_loop().time()
            await pages.questions_first(waited._wanted)
            assert asyncio.get_running_loop().time() - started < 0.1
            waited._wanted.clear()
            pending = asyncio.ensure_future(pages.questions_first(waited._wanted))
            await asyncio.sleep(0.05)
            assert not pending.done()  # nobody waits for it: it gives way ...
            waited._wanted.set()  # ... until a question comes for it
            await asyncio.wait_for(pending, 1.0)


async def test_a_question_keeps_its_session_stitching_under_other_questions(tmp_path: Path) -> None:
    store, records = await stored(tmp_path, 2)
    pages = LivePages(store, CountingOcr(), LiveConfig(questions_first_s=5.0, catch_up_s=3.0, batch_frames=8))
    try:
        with pages.answering():  # another session's question is read the whole time
            started = asyncio.get_running_loop().time()
            assert await pages.get("s").caught_up(3.0, upto_seq=records[-1].seq)
            assert asyncio.get_running_loop().time() - started < 2.5  # not a 5 s pause per batch
    finally:
        await pages.close()
        await store.close()
