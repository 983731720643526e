"""What every ``SessionStore`` backend must do. Written against the protocol only: a second
backend is added in ``conftest.BACKENDS`` and passes these unchanged."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from darkread.cloud.store import (
    GazeRecord,
    PageBreak,
    PageRecord,
    SessionOwnedError,
    SessionShapeError,
    SessionSpec,
    SessionStore,
    StoredFrame,
    StoreError,
    UnknownSessionError,
    WriteResult,
)

pytestmark = pytest.mark.anyio


def spec(session_id: str, mode: str = "frames", device: str = "g") -> SessionSpec:
    return SessionSpec(session_id, device, mode, (1280, 720), (100, 200))


def frame(seq: int) -> StoredFrame:
    mask = np.zeros((100, 200), np.uint8)
    mask[seq % 100, :] = 1
    mask[:, seq % 200] = 1
    return StoredFrame(seq + 10, seq * 100, mask, (seq, 2 * seq), (1.5, 2.5), seq=seq, gaze_rad=(0.25, -0.5), events_used=1600 + seq)


def page(seq: int, ink_row: int = 3) -> PageRecord:
    mask = np.zeros((16, 24), np.uint8)
    mask[ink_row, 2:20] = 1
    return PageRecord(seq, 7, 9_000, mask, ((0, 0, 5, 5), (1, 2, 3, 4)))


async def test_a_new_session_starts_before_seq_zero_and_resumes_at_its_highest_seq(store: SessionStore) -> None:
    assert await store.open_session(spec("s")) == -1
    await store.add_frame("s", frame(0))
    await store.add_frame("s", frame(1))
    assert await store.open_session(spec("s")) == 1
    info = await store.session("s")
    assert info is not None and info.device_id == "g" and info.last_seq == 1 and info.frames == 2
    assert info.sensor == (1280, 720) and info.fovea == (100, 200) and info.mode == "frames"
    assert await store.session("ghost") is None


async def test_a_resent_seq_is_acknowledged_not_stored_again_and_a_gap_is_refused(store: SessionStore) -> None:
    await store.open_session(spec("s"))
    results = [await store.add_frame("s", frame(seq)) for seq in (0, 1, 1, 0, 2, 2)]
    assert [(r.stored, r.last_seq) for r in results] == [
        (True, 0), (True, 1), (False, 1), (False, 1), (True, 2), (False, 2),
    ]  # fmt: skip
    with pytest.raises(StoreError, match="does not follow the stored seq 2"):
        await store.add_frame("s", frame(5))  # a hole would hide a lost frame behind the resume point
    assert [f.seq for f in await store.frames("s")] == [0, 1, 2]


async def test_a_session_belongs_to_the_stream_that_opened_it(store: SessionStore) -> None:
    await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200), stream_id="spool-a"))
    await store.add_frame("s", frame(0))
    with pytest.raises(SessionOwnedError, match="device"):
        await store.open_session(SessionSpec("s", "other", "frames", (1280, 720), (100, 200), stream_id="spool-a"))
    with pytest.raises(SessionOwnedError, match="another stream"):
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200), stream_id="spool-b"))
    with pytest.raises(SessionShapeError, match="fovea"):
        await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (50, 200), stream_id="spool-a"))
    assert await store.open_session(SessionSpec("s", "g", "frames", (1280, 720), (100, 200), stream_id="spool-a")) == 0


async def test_frames_come_back_as_written_oldest_first_in_pages(store: SessionStore) -> None:
    await store.open_session(spec("s"))
    for seq in range(12):
        await store.add_frame("s", frame(seq))
    first = await store.frames("s", limit=5)
    rest = await store.frames("s", after_seq=first[-1].seq, limit=100)
    assert [f.seq for f in first + rest] == list(range(12))
    got, want = rest[2], frame(7)
    assert (got.seq, got.frame_id, got.t_us, got.origin, got.gaze_px, got.gaze_rad, got.events_used) == (
        want.seq, want.frame_id, want.t_us, want.origin, want.gaze_px, want.gaze_rad, want.events_used,
    )  # fmt: skip
    assert got.mask.dtype == np.uint8 and got.mask.shape == (100, 200)
    np.testing.assert_array_equal(got.mask, want.mask)


async def test_the_scene_motion_a_frame_carries_comes_back_and_its_absence_too(store: SessionStore) -> None:
    import dataclasses

    await store.open_session(spec("s"))
    await store.add_frame("s", dataclasses.replace(frame(0), scene_px=(-3.5, 120.25)))
    await store.add_frame("s", frame(1))
    moved, plain = await store.frames("s")
    assert moved.scene_px == (-3.5, 120.25) and plain.scene_px is None


async def test_a_view_keeps_the_shedding_level_the_glasses_made_it_at(store: SessionStore) -> None:
    import dataclasses

    await store.open_session(spec("s"))
    await store.add_frame("s", dataclasses.replace(frame(0), shed_level=3))
    await store.add_frame("s", frame(1))
    starved, kept_up = await store.frames("s")
    assert (starved.shed_level, kept_up.shed_level) == (3, 0)


async def test_a_frame_keeps_the_light_the_glasses_measured(store: SessionStore) -> None:
    import dataclasses

    await store.open_session(spec("s"))
    await store.add_frame("s", dataclasses.replace(frame(0), light_lux=6.25))
    await store.add_frame("s", frame(1))
    dim, unknown = await store.frames("s")
    assert (dim.light_lux, unknown.light_lux) == (6.25, None)


async def test_concurrent_streams_each_get_every_write(store: SessionStore) -> None:
    await asyncio.gather(*(store.open_session(spec(f"s{i}")) for i in range(10)))
    results = await asyncio.gather(*(store.add_frame(f"s{i}", frame(seq)) for seq in range(40) for i in range(10)))
    assert all(r.stored for r in results)
    sessions = await store.sessions()
    assert sorted(s.session_id for s in sessions) == sorted(f"s{i}" for i in range(10))
    assert {s.frames for s in sessions} == {40} and {s.last_seq for s in sessions} == {39}


async def test_sessions_list_the_most_recently_active_first(store: SessionStore) -> None:
    for name in ("a", "b", "c"):
        await store.open_session(spec(name))
        await asyncio.sleep(0.01)
    await store.add_frame("a", frame(0))
    assert [s.session_id for s in await store.sessions()] == ["a", "c", "b"]


async def test_writes_to_an_unknown_session_fail_and_leave_nothing(store: SessionStore) -> None:
    with pytest.raises(UnknownSessionError, match="unknown session"):
        await store.add_frame("ghost", frame(0))
    with pytest.raises(StoreError):
        await store.add_gaze("ghost", GazeRecord(1, (1,), ((1.0, 2.0),)))
    await store.open_session(spec("ghost"))
    assert await store.frames("ghost") == []
    assert (await store.add_frame("ghost", frame(0))).stored


async def test_pages_gaze_and_page_breaks_share_the_session_seq(store: SessionStore) -> None:
    await store.open_session(spec("p", mode="pages"))
    assert await store.latest_page("p") is None
    assert await store.add_page("p", page(0)) == WriteResult(stored=True, last_seq=0)
    assert await store.add_page("p", page(0, ink_row=9)) == WriteResult(stored=False, last_seq=0)
    assert await store.add_gaze("p", GazeRecord(1, (1, 2), ((3.0, 4.0), (5.0, 6.0)))) == WriteResult(True, 1)
    assert await store.add_page_break("p", PageBreak(2, 123)) == WriteResult(True, 2)
    assert await store.add_page_break("p", PageBreak(2, 123)) == WriteResult(False, 2)
    await store.add_page("p", page(3, ink_row=11))
    latest = await store.latest_page("p")
    assert latest is not None and (latest.seq, latest.page_id, latest.t_us) == (3, 7, 9_000)
    assert latest.lines == ((0, 0, 5, 5), (1, 2, 3, 4))
    np.testing.assert_array_equal(latest.mask, page(3, ink_row=11).mask)
    assert await store.page_breaks("p") == [PageBreak(2, 123)]
    info = await store.session("p")
    assert info is not None and info.pages == 2 and info.frames == 0 and info.last_seq == 3


async def test_everything_survives_a_restart(open_store) -> None:  # the fixture's opener
    first = await open_store()
    await first.open_session(spec("s"))
    await first.add_frame("s", frame(0))
    await first.add_page_break("s", PageBreak(1, 50))
    await first.add_frame("s", frame(2))
    await first.open_session(spec("p", mode="pages"))
    await first.add_page("p", page(0))
    await first.close()
    second = await open_store()
    try:
        assert await second.open_session(spec("s")) == 2
        assert [f.seq for f in await second.frames("s")] == [0, 2]
        assert await second.page_breaks("s") == [PageBreak(1, 50)]
        stored = await second.latest_page("p")
        assert stored is not None
        np.testing.assert_array_equal(stored.mask, page(0).mask)
        assert (await second.add_frame("s", frame(2))).stored is False
    finally:
        await second.close()


async def test_delete_removes_everything_of_one_session(store: SessionStore) -> None:
    await store.open_session(spec("s"))
    await store.open_session(spec("keep", mode="pages"))
    await store.add_frame("s", frame(0))
    await store.add_page_break("s", PageBreak(1, 5))
    await store.add_page("keep", page(0))
    assert await store.delete_session("s") is True
    assert await store.session("s") is None
    assert await store.frames("s") == [] and await store.page_breaks("s") == []
    assert await store.delete_session("s") is False
    with pytest.raises(UnknownSessionError):
        await store.add_frame("s", frame(0))
    assert await store.open_session(spec("s")) == -1  # a new session of the same name starts afresh
    assert await store.latest_page("keep") is not None


async def test_an_open_store_answers_ping_and_a_closed_one_refuses_writes(open_store) -> None:
    store = await open_store()
    assert await store.ping() is True
    await store.close()
    with pytest.raises(StoreError, match="closed"):
        await store.open_session(spec("s"))


async def test_subscribers_hear_of_each_commit_once(store: SessionStore) -> None:
    heard: list[tuple[str, int]] = []
    unsubscribe = store.subscribe(lambda session_id, last_seq: heard.append((session_id, last_seq)))
    await store.open_session(spec("s"))
    await store.add_frame("s", frame(0))
    await store.add_frame("s", frame(0))  # a duplicate changes nothing: nobody is told
    await store.add_page_break("s", PageBreak(1, 5))
    await asyncio.sleep(0.2)  # a backend relaying other instances' commits must not echo its own
    assert heard == [("s", 0), ("s", 1)]
    unsubscribe()
    await store.add_frame("s", frame(2))
    assert heard == [("s", 0), ("s", 1)]
