"""A session belongs to the stream that opened it; seqs are contiguous; hello cannot reshape it."""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from darkread.proto.errors import CloseCode
from darkread.proto.messages import Error, Welcome, decode, encode

from .test_stream import API_KEY, LIMIT, frame, hello

LiveServer = Any


async def open_ws(server: LiveServer, session_id: str, **fields: Any) -> tuple[Any, Any]:
    ws = await connect(server.ws_url, additional_headers={"X-API-Key": API_KEY}, max_size=None)
    await ws.send(encode(hello(session_id, **fields)))
    return ws, decode(await ws.recv(), max_bytes=LIMIT)


async def closed_with(ws: Any) -> tuple[int | None, str]:
    """Read until the server closes; the close code and the fatal error's message."""
    message = ""
    try:
        while True:
            reply = decode(await asyncio.wait_for(ws.recv(), 5), max_bytes=LIMIT)
            if isinstance(reply, Error):
                message = reply.message
    except ConnectionClosed:
        pass
    return ws.close_code, message


async def send_acked(ws: Any, seqs: range) -> list[int]:
    for seq in seqs:
        await ws.send(encode(frame(seq)))
    return [decode(await ws.recv(), max_bytes=LIMIT).seq for _ in seqs]


def test_a_second_stream_on_a_live_session_is_refused_and_the_first_continues(server: LiveServer) -> None:
    async def scenario() -> None:
        first, welcome = await open_ws(server, "shared1", stream_id="spool-a")
        assert isinstance(welcome, Welcome)
        assert await send_acked(first, range(3)) == [0, 1, 2]
        second, refused = await open_ws(server, "shared1", stream_id="spool-b")
        assert isinstance(refused, Error) and refused.code == CloseCode.SESSION_BUSY
        assert (await closed_with(second))[0] == CloseCode.SESSION_BUSY
        assert await send_acked(first, range(3, 6)) == [3, 4, 5]
        await first.close()
        # the owner left: another stream still may not write into its seq space
        third, refused = await open_ws(server, "shared1", stream_id="spool-b")
        assert isinstance(refused, Error) and refused.code == CloseCode.FORBIDDEN
        await third.close()

    asyncio.run(scenario())
    assert [f.seq for f in asyncio.run(server.context.store.frames("shared1"))] == list(range(6))


def test_the_same_stream_reconnecting_takes_the_session_over(server: LiveServer) -> None:
    async def scenario() -> None:
        old, _ = await open_ws(server, "takeover", stream_id="spool-a")
        assert await send_acked(old, range(2)) == [0, 1]
        new, welcome = await open_ws(server, "takeover", stream_id="spool-a")  # e.g. after a half-open TCP drop
        assert isinstance(welcome, Welcome) and welcome.last_acked_seq == 1
        code, message = await closed_with(old)
        assert code == CloseCode.TAKEN_OVER and "newer connection" in message
        assert await send_acked(new, range(2, 4)) == [2, 3]
        await new.close()

    asyncio.run(scenario())


def test_another_device_may_not_open_a_session(server: LiveServer) -> None:
    async def scenario() -> None:
        ws, _ = await open_ws(server, "owned", device_id="glasses-1")
        await send_acked(ws, range(1))
        await ws.close()
        other, refused = await open_ws(server, "owned", device_id="glasses-2")
        assert isinstance(refused, Error) and refused.code == CloseCode.FORBIDDEN
        await other.close()

    asyncio.run(scenario())
    assert asyncio.run(server.context.store.session("owned")).device_id == "glasses-1"


@pytest.mark.parametrize("bad_seq", [5, 2**63 - 1])
def test_a_seq_gap_or_wild_seq_is_an_error_not_a_new_high_water_mark(server: LiveServer, bad_seq: int) -> None:
    async def scenario() -> None:
        ws, _ = await open_ws(server, f"poison-{bad_seq}")
        assert await send_acked(ws, range(2)) == [0, 1]
        await ws.send(encode(dataclasses.replace(frame(2), seq=bad_seq)))
        code, message = await closed_with(ws)
        assert code == CloseCode.SEQ_GAP and f"seq {bad_seq}" in message and "expected 2" in message
        ws, welcome = await open_ws(server, f"poison-{bad_seq}")
        assert welcome.last_acked_seq == 1  # the wild value did not move the resume point
        assert await send_acked(ws, range(2, 5)) == [2, 3, 4]
        await ws.close()

    asyncio.run(scenario())
    assert [f.seq for f in asyncio.run(server.context.store.frames(f"poison-{bad_seq}"))] == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("change", [{"mode": "pages"}, {"fovea": (50, 200)}, {"sensor": (640, 480)}])
def test_hello_cannot_change_a_sessions_mode_or_geometry(server: LiveServer, change: dict[str, Any]) -> None:
    async def scenario() -> None:
        ws, _ = await open_ws(server, "shape")
        await send_acked(ws, range(2))
        await ws.close()
        again, refused = await open_ws(server, "shape", **change)
        assert isinstance(refused, Error) and refused.code == CloseCode.SESSION_MISMATCH
        await again.close()

    asyncio.run(scenario())
    info = asyncio.run(server.context.store.session("shape"))
    assert (info.mode, info.fovea, info.sensor) == ("frames", (100, 200), (1280, 720))
