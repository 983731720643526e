"""Any failure of a message's store path ends that connection at once, with a code and a reason."""

from __future__ import annotations

import asyncio
import sqlite3
import time
from typing import Any

from darkread.proto.errors import CloseCode
from darkread.proto.messages import encode

from .test_stream import frame
from .test_stream_ownership import closed_with, open_ws, send_acked

LiveServer = Any


def test_an_integrity_error_closes_within_a_second_and_the_stream_resumes(server: LiveServer) -> None:
    async def scenario() -> float:
        ws, _ = await open_ws(server, "clash", stream_id="s1")
        assert await send_acked(ws, range(3)) == [0, 1, 2]
        with sqlite3.connect(server.settings.data_dir / "darkread.sqlite3") as db:  # e.g. a second writer
            columns = "frame_id, t_us, x0, y0, gaze_u, gaze_v, yaw, pitch, events_used, rows, cols, bits"
            db.execute(f"INSERT INTO frames (session_id, seq, {columns}) SELECT session_id, 3, {columns}"
                       " FROM frames WHERE session_id = 'clash' AND seq = 0")  # a fixed column list
        sent = time.monotonic()
        await ws.send(encode(frame(3)))
        code, message = await closed_with(ws)
        elapsed = time.monotonic() - sent
        assert code == CloseCode.INTERNAL_ERROR and "IntegrityError" in message, message
        with sqlite3.connect(server.settings.data_dir / "darkread.sqlite3") as db:
            db.execute("DELETE FROM frames WHERE session_id = 'clash' AND seq = 3")
        ws, welcome = await open_ws(server, "clash", stream_id="s1")
        assert welcome.last_acked_seq == 2
        assert await send_acked(ws, range(3, 6)) == [3, 4, 5]
        await ws.close()
        return elapsed

    elapsed = asyncio.run(scenario())
    assert elapsed < 1.0
    metrics = server.context.metrics
    assert metrics.store_failures.labels(error="IntegrityError")._value.get() == 1
    assert metrics.errors.labels(code=str(int(CloseCode.INTERNAL_ERROR)))._value.get() == 1
    deadline = time.monotonic() + 2
    while metrics.active._value.get() != 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert metrics.active._value.get() == 0
    assert [f.seq for f in asyncio.run(server.context.store.frames("clash"))] == list(range(6))
    print(f"store failure: connection closed {elapsed * 1000:.0f} ms after the failing frame")


def test_an_os_error_writing_a_page_closes_the_connection(server: LiveServer) -> None:
    import numpy as np

    from darkread.proto.messages import Page, pack_mask

    (server.settings.data_dir / "pages").mkdir(exist_ok=True)
    (server.settings.data_dir / "pages" / "blocked").write_text("a file where the folder goes")
    shape, bits = pack_mask(np.ones((8, 8), np.uint8))

    async def scenario() -> tuple[int | None, str]:
        ws, _ = await open_ws(server, "blocked", mode="pages")
        await ws.send(encode(Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits)))
        return await closed_with(ws)

    code, message = asyncio.run(scenario())
    assert code == CloseCode.INTERNAL_ERROR and ("FileExistsError" in message or "NotADirectory" in message), message
