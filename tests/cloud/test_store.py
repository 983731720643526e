"""The store: sequencing, duplicates, group commit, restart, deletion."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from darkread.cloud.errors import StoreError
from darkread.cloud.store import Store, WriteResult
from darkread.proto.messages import Frame, Gaze, Hello, Page, pack_mask


def hello(session_id: str, mode: str = "frames") -> Hello:
    return Hello(device_id="g", session_id=session_id, mode=mode, sensor=(1280, 720), fovea=(100, 200))  # type: ignore[arg-type]


def frame(seq: int) -> Frame:
    mask = np.zeros((100, 200), np.uint8)
    mask[seq % 100, :] = 1
    shape, bits = pack_mask(mask)
    return Frame(seq, seq + 10, seq * 100, (seq, 2 * seq), (1.5, 2.5), (0.0, 0.0), 1600, shape, bits)


@pytest.fixture
def store(tmp_path: Path) -> Store:
    opened = Store(tmp_path)
    yield opened
    opened.close()


def test_frames_are_sequenced_and_duplicates_not_stored(store: Store) -> None:
    async def scenario() -> list[WriteResult]:
        assert await store.open_session(hello("s")) == -1
        results = [await store.add_frame("s", frame(seq)) for seq in (0, 1, 1, 0, 2)]
        with pytest.raises(StoreError, match="does not follow the stored seq 2"):
            await store.add_frame("s", frame(5))  # a hole would hide a lost frame behind the resume point
        return results

    results = asyncio.run(scenario())
    assert [(r.stored, r.last_seq) for r in results] == [(True, 0), (True, 1), (False, 1), (False, 1), (True, 2)]
    stored = store.frames("s", 10)
    assert [f.seq for f in stored] == [0, 1, 2]
    assert stored[2].frame_id == 12 and stored[2].origin == (2, 4) and stored[2].mask[2].all()


def test_many_concurrent_writes_share_commits(store: Store) -> None:
    async def scenario() -> list[WriteResult]:
        await asyncio.gather(*(store.open_session(hello(f"s{i}")) for i in range(10)))
        writes = [store.add_frame(f"s{i}", frame(seq)) for seq in range(50) for i in range(10)]
        return await asyncio.gather(*writes)

    results = asyncio.run(scenario())
    assert all(r.stored for r in results)
    assert [s.frames for s in store.sessions()] == [50] * 10


def test_frames_for_an_unknown_session_fail(store: Store) -> None:
    async def scenario() -> None:
        with pytest.raises(StoreError, match="unknown session"):
            await store.add_frame("ghost", frame(0))

    asyncio.run(scenario())


def test_everything_survives_reopening(tmp_path: Path) -> None:
    mask = np.eye(16, 24, dtype=np.uint8)
    shape, bits = pack_mask(mask)

    async def write(store: Store) -> None:
        await store.open_session(hello("s", mode="pages"))
        await store.add_page("s", Page(seq=0, page_id=2, t_us=9, shape=shape, bits=bits, lines=((0, 0, 5, 5),)))
        await store.add_gaze("s", Gaze(seq=1, t_us=(1, 2), px=((3.0, 4.0), (5.0, 6.0))))

    first = Store(tmp_path)
    asyncio.run(write(first))
    first.close()
    second = Store(tmp_path)
    try:
        info = second.session("s")
        assert info is not None and info.last_seq == 1 and info.pages == 1 and info.sensor == (1280, 720)
        page = second.latest_page("s")
        assert page is not None and page.page_id == 2 and page.lines == [(0, 0, 5, 5)]
        np.testing.assert_array_equal(page.image(), np.where(mask == 1, 0, 255))

        async def resend() -> WriteResult:
            assert await second.open_session(hello("s", mode="pages")) == 1
            return await second.add_page("s", Page(seq=0, page_id=2, t_us=9, shape=shape, bits=bits))

        assert asyncio.run(resend()) == WriteResult(stored=False, last_seq=1)
    finally:
        second.close()


def test_delete_removes_rows_and_files(store: Store) -> None:
    shape, bits = pack_mask(np.ones((8, 8), np.uint8))

    async def write() -> None:
        await store.open_session(hello("s", mode="pages"))
        await store.add_page("s", Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits))

    asyncio.run(write())
    assert (store.pages_dir / "s" / "0.png").exists()
    assert store.delete_session("s") is True
    assert store.session("s") is None and store.latest_page("s") is None
    assert not (store.pages_dir / "s").exists()
    assert store.delete_session("s") is False


def test_closed_store_refuses_writes(tmp_path: Path) -> None:
    store = Store(tmp_path)
    store.close()

    async def scenario() -> None:
        with pytest.raises(StoreError, match="closed"):
            store.open_session(hello("s"))

    asyncio.run(scenario())


def test_a_batch_is_one_transaction(store: Store) -> None:
    """Writes queued together commit together: inside the batch, a reader sees none of them yet."""
    import threading

    release, running = threading.Event(), threading.Event()

    def hold_writer(_conn: object) -> None:  # its batch is formed once it runs; the rest queue up
        running.set()
        release.wait(5)

    def count_committed(_conn: object) -> int:
        with store._reader() as reader:
            return int(reader.execute("SELECT COUNT(*) FROM frames").fetchone()[0])

    async def scenario() -> tuple[int, list[WriteResult]]:
        await store.open_session(hello("s"))
        blocker = store._submit(hold_writer)
        while not running.wait(0.001):
            await asyncio.sleep(0.001)
        writes = [store.add_frame("s", frame(seq)) for seq in range(3)]
        seen = store._submit(count_committed)
        release.set()
        await blocker
        return await seen, list(await asyncio.gather(*writes))

    seen_inside, results = asyncio.run(scenario())
    assert seen_inside == 0
    assert all(r.stored for r in results) and len(store.frames("s", 10)) == 3
