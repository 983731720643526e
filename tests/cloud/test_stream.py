"""WS /v1/stream against a real uvicorn server with the websockets client."""

from __future__ import annotations

import asyncio
from typing import Any

import msgpack
import numpy as np
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from darkread.cloud.errors import StoreError
from darkread.cloud.store import StoredFrame
from darkread.cloud.stream import close_reason
from darkread.proto.errors import CloseCode
from darkread.proto.messages import Ack, Error, Frame, Hello, Page, View, Welcome, decode, encode, pack_mask

LIMIT = 1 << 22
API_KEY = "test-key-7f3a"  # the key the conftest server requires
LiveServer = Any


def hello(session_id: str, **overrides: Any) -> Hello:
    values: dict[str, Any] = dict(device_id="glasses-1", session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))
    values.update(overrides)
    return Hello(**values)


def frame(seq: int, shape: tuple[int, int] = (100, 200)) -> Frame:
    mask = np.zeros(shape, np.uint8)
    mask[40:50, 10 + seq % 50 : 60 + seq % 50] = 1
    packed_shape, bits = pack_mask(mask)
    return Frame(seq, seq, 1000 * seq, (500, 300), (600.0, 350.0), (0.01, -0.02), 1600, packed_shape, bits)


async def open_stream(
    server: LiveServer, session_id: str, *, key: str | None = API_KEY, **hello_fields: Any
) -> tuple[ClientConnection, Welcome]:
    headers = {"X-API-Key": key} if key is not None else {}
    ws = await connect(server.ws_url, additional_headers=headers, max_size=None)
    await ws.send(encode(hello(session_id, **hello_fields)))
    welcome = decode(await ws.recv(), max_bytes=LIMIT)
    assert isinstance(welcome, Welcome)
    return ws, welcome


async def stream_frames(server: LiveServer, session_id: str, seqs: range, pause: float = 0.0) -> list[int]:
    """Send frames one at a time and collect the acks; the healthy neighbour in the bad-input tests."""
    ws, _ = await open_stream(server, session_id)
    acks = []
    async with ws:
        for seq in seqs:
            await ws.send(encode(frame(seq)))
            ack = decode(await ws.recv(), max_bytes=LIMIT)
            assert isinstance(ack, Ack)
            acks.append(ack.seq)
            await asyncio.sleep(pause)
    return acks


async def expect_error_close(ws: ClientConnection) -> tuple[Error, int | None, str | None]:
    error = decode(await ws.recv(), max_bytes=LIMIT)
    assert isinstance(error, Error) and error.fatal
    with pytest.raises(ConnectionClosed):
        await ws.recv()
    return error, ws.close_code, ws.close_reason


def test_frames_are_acked_after_they_are_stored(server: LiveServer) -> None:
    async def scenario() -> None:
        ws, welcome = await open_stream(server, "sess-a")
        assert welcome.last_acked_seq == -1 and welcome.max_message_bytes == 65536
        async with ws:
            for seq in range(5):
                await ws.send(encode(frame(seq)))
                ack = decode(await ws.recv(), max_bytes=LIMIT)
                assert ack == Ack(seq=seq)
                stored = await server.context.store.frames("sess-a")  # stored before the ack arrived
                assert [f.seq for f in stored] == list(range(seq + 1))

    asyncio.run(scenario())
    stored = asyncio.run(server.context.store.frames("sess-a"))
    np.testing.assert_array_equal(stored[3].mask, frame(3).mask())
    assert stored[3].origin == (500, 300) and stored[3].gaze_px == (600.0, 350.0)


def test_the_service_never_deflates_what_is_compressed_already(server: LiveServer) -> None:
    """A client offering permessage-deflate (websockets does by default) gets none: masks and views
    are zlib/PNG already, deflating them again would cost both ends CPU for a few bytes."""

    async def scenario() -> tuple[str | None, str | None]:
        ws, _ = await open_stream(server, "no-deflate")
        async with ws:
            assert ws.response is not None and ws.request is not None
            return ws.request.headers.get("Sec-WebSocket-Extensions"), ws.response.headers.get("Sec-WebSocket-Extensions")

    offered, accepted = asyncio.run(scenario())
    assert offered is not None and "permessage-deflate" in offered
    assert accepted is None


def test_version_2_views_and_compressed_frames_are_stored_as_frame_records(server: LiveServer) -> None:
    levels = np.zeros((100, 200), np.uint8)
    levels[40:50, 20:80] = 3  # surely ink
    levels[40:50, 80:90] = 1  # unlikely ink: paper once thresholded
    view = View(seq=1, view_id=0, t0_us=0, t_us=5000, origin=(500, 300), gaze_px=(600.0, 350.0), gaze_rad=(0.0, 0.0),
                frames=3, events_used=4800, shape=(100, 200), n_levels=4, levels=levels.tobytes())

    async def scenario() -> None:
        ws, welcome = await open_stream(server, "sess-v2", v=2)
        assert welcome.v == 2
        async with ws:
            await ws.send(encode(Frame.of(frame(0).record(), seq=0, enc="zlib")))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=0)
            await ws.send(encode(view))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=1)

    asyncio.run(scenario())
    stored = asyncio.run(server.context.store.frames("sess-v2"))
    np.testing.assert_array_equal(stored[0].mask, frame(0).mask())
    np.testing.assert_array_equal(stored[1].mask, (levels >= 2).astype(np.uint8))
    # the view keeps its grey levels and the frames behind it: the stitcher weighs it by them
    assert stored[0].levels is None and stored[0].frames == 1
    np.testing.assert_array_equal(stored[1].levels, levels)
    assert stored[1].n_levels == 4 and stored[1].frames == 3
    np.testing.assert_allclose(stored[1].ink_probability()[45, 85], 1 / 3)


def test_a_view_larger_than_the_fovea_is_stored_in_version_4_and_refused_before(server: LiveServer) -> None:
    """Version 4: a view is the union of its frames' windows (up to twice the fovea's side); a
    frame is still one window, and a version 3 session keeps its views to the fovea."""

    def view(seq: int, shape: tuple[int, int]) -> View:
        levels = np.zeros(shape, np.uint8)
        levels[shape[0] - 12 : shape[0] - 2, 20:80] = 7  # ink below the fovea's rows
        return View(seq=seq, view_id=seq, t0_us=0, t_us=5000 + seq, origin=(500, 280), gaze_px=(600.0, 350.0),
                    gaze_rad=(0.0, 0.0), frames=2, events_used=3200, shape=shape, n_levels=8, levels=levels.tobytes())

    async def scenario() -> None:
        ws, welcome = await open_stream(server, "sess-wide")
        assert welcome.v == 4
        async with ws:
            await ws.send(encode(view(0, (140, 200))))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=0)
            await ws.send(encode(view(1, (201, 200))))  # beyond twice the fovea's rows
            error, code, _ = await expect_error_close(ws)
            assert code == CloseCode.BAD_MASK and "outside hello.fovea" in error.message
        ws, _ = await open_stream(server, "sess-wide-frame")
        async with ws:
            await ws.send(encode(frame(0, shape=(140, 200))))  # a frame is one window, in every version
            error, code, _ = await expect_error_close(ws)
            assert code == CloseCode.BAD_MASK and "differs from hello.fovea" in error.message
        ws, welcome = await open_stream(server, "sess-wide-v3", v=3)
        assert welcome.v == 3
        async with ws:
            await ws.send(encode(view(0, (140, 200))))
            error, code, _ = await expect_error_close(ws)
            assert code == CloseCode.BAD_MASK and "needs protocol version 4" in error.message

    asyncio.run(scenario())
    stored = asyncio.run(server.context.store.frames("sess-wide"))
    assert len(stored) == 1 and stored[0].mask.shape == (140, 200) and stored[0].mask[130:138, 20:80].all()
    assert asyncio.run(server.context.store.frames("sess-wide-v3")) == []


def test_a_version_1_client_is_still_served_and_kept_to_version_1(server: LiveServer) -> None:
    async def scenario() -> None:
        ws, welcome = await open_stream(server, "sess-v1", v=1)
        assert welcome.v == 1
        async with ws:
            await ws.send(encode(frame(0)))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=0)
            await ws.send(encode(Frame.of(frame(1).record(), seq=1, enc="zlib")))  # version 2 content
            error, code, _ = await expect_error_close(ws)
            assert code == CloseCode.UNEXPECTED

    asyncio.run(scenario())
    assert [f.seq for f in asyncio.run(server.context.store.frames("sess-v1"))] == [0]


def test_pipelined_frames_are_acked_in_order(server: LiveServer) -> None:
    async def scenario() -> list[int]:
        ws, _ = await open_stream(server, "sess-pipe")
        async with ws:
            for seq in range(100):
                await ws.send(encode(frame(seq)))
            return [decode(await ws.recv(), max_bytes=LIMIT).seq for _ in range(100)]  # type: ignore[union-attr]  # every answer is an ack

    assert asyncio.run(scenario()) == list(range(100))
    assert asyncio.run(server.context.store.session("sess-pipe")).frames == 100


def test_resume_reports_last_stored_seq_and_duplicates_are_reacked_not_stored(server: LiveServer) -> None:
    async def scenario() -> None:
        await stream_frames(server, "sess-r", range(0, 4))
        ws, welcome = await open_stream(server, "sess-r", resume_from_seq=1)
        assert welcome.last_acked_seq == 3
        async with ws:
            for seq in (2, 3, 4):  # a client that resends what it has not seen acked
                await ws.send(encode(frame(seq)))
            acks = [decode(await ws.recv(), max_bytes=LIMIT) for _ in range(3)]
        assert acks == [Ack(seq=3), Ack(seq=3), Ack(seq=4)]

    asyncio.run(scenario())
    assert [f.seq for f in asyncio.run(server.context.store.frames("sess-r"))] == [0, 1, 2, 3, 4]


def test_sessions_survive_a_restart(make_settings: Any, run_server: Any) -> None:
    settings = make_settings()
    with run_server(settings) as first:
        asyncio.run(stream_frames(first, "sess-keep", range(7)))
    with run_server(settings) as second:

        async def reconnect() -> Welcome:
            ws, welcome = await open_stream(second, "sess-keep")
            await ws.close()
            return welcome

        assert asyncio.run(reconnect()).last_acked_seq == 6
        assert len(asyncio.run(second.context.store.frames("sess-keep"))) == 7


def _raw_frame(**changes: Any) -> bytes:
    payload = msgpack.unpackb(encode(frame(0)))
    payload.update(changes)
    return msgpack.packb(payload, use_bin_type=True)


BAD_INPUTS = {
    "malformed msgpack": ([b"\xc1\x00\x00"], CloseCode.MALFORMED),
    "not a map": ([msgpack.packb([1, 2, 3])], CloseCode.MALFORMED),
    "wrong protocol version": ([msgpack.packb({**msgpack.unpackb(encode(hello("x"))), "v": 5})], CloseCode.VERSION_MISMATCH),
    "frame before hello": ([encode(frame(0))], CloseCode.UNEXPECTED),
    "oversized message": (["hello", b"\x00" * 70_000], CloseCode.MESSAGE_TOO_BIG),
    "frame of the wrong shape": (["hello", encode(frame(0, shape=(50, 200)))], CloseCode.BAD_MASK),
    "frame with the wrong bit length": (["hello", _raw_frame(bits=b"\x00" * 2499)], CloseCode.BAD_MASK),
    "text message": (["hello", "hello as text"], CloseCode.MALFORMED),
    "second hello": (["hello", encode(hello("bad-client"))], CloseCode.UNEXPECTED),
    "page in frames mode": (["hello", encode(Page(seq=0, page_id=0, t_us=0, shape=(8, 8), bits=b"\0" * 8))], CloseCode.UNEXPECTED),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_closes_only_its_own_connection(server: LiveServer, case: str) -> None:
    sends, expected_code = BAD_INPUTS[case]

    async def scenario() -> None:
        healthy = asyncio.create_task(stream_frames(server, f"healthy-{len(case)}", range(40), pause=0.002))
        await asyncio.sleep(0.02)
        ws = await connect(server.ws_url, additional_headers={"X-API-Key": API_KEY}, max_size=None)
        for item in sends:
            if item == "hello":
                await ws.send(encode(hello("bad-client")))
                assert isinstance(decode(await ws.recv(), max_bytes=LIMIT), Welcome)
            else:
                await ws.send(item)
        error, code, reason = await expect_error_close(ws)
        assert error.code == expected_code == code
        assert reason and reason in error.message
        assert await healthy == list(range(40))

    asyncio.run(scenario())
    assert server.context.metrics.errors.labels(code=str(int(expected_code)))._value.get() == 1


def test_wrong_key_in_header_is_denied_at_handshake(server: LiveServer) -> None:
    async def scenario() -> None:
        with pytest.raises(InvalidStatus) as denied:
            await connect(server.ws_url, additional_headers={"X-API-Key": "wrong"})
        assert denied.value.response.status_code == 403

    asyncio.run(scenario())
    assert server.context.metrics.denied._value.get() == 1


def test_missing_key_closes_with_policy_violation(server: LiveServer) -> None:
    async def scenario() -> None:
        ws = await connect(server.ws_url)
        await ws.send(encode(hello("no-key")))
        error, code, _ = await expect_error_close(ws)
        assert error.code == code == CloseCode.POLICY_VIOLATION

    asyncio.run(scenario())
    assert asyncio.run(server.context.store.session("no-key")) is None


def test_key_in_query_or_hello_token_is_accepted(server: LiveServer) -> None:
    async def scenario() -> None:
        ws = await connect(f"{server.ws_url}?key={API_KEY}")
        await ws.send(encode(hello("by-query")))
        assert isinstance(decode(await ws.recv(), max_bytes=LIMIT), Welcome)
        await ws.close()
        ws, welcome = await open_stream(server, "by-token", key=None, token=API_KEY)
        assert welcome.session_id == "by-token"
        await ws.close()

    asyncio.run(scenario())


def test_client_without_hello_is_closed_after_the_timeout(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(hello_timeout_s=0.2)) as live:

        async def scenario() -> None:
            ws = await connect(live.ws_url, additional_headers={"X-API-Key": API_KEY})
            error, code, _ = await expect_error_close(ws)
            assert error.code == code == CloseCode.UNEXPECTED

        asyncio.run(scenario())


def test_pages_mode_stores_pages_as_png(server: LiveServer) -> None:
    mask = np.zeros((60, 90), np.uint8)
    mask[20:30, 5:80] = 1
    shape, bits = pack_mask(mask)

    async def scenario() -> None:
        ws, _ = await open_stream(server, "sess-pages", mode="pages")
        async with ws:
            await ws.send(encode(Page(seq=0, page_id=7, t_us=5, shape=shape, bits=bits, lines=((5, 20, 80, 30),))))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=0)

    asyncio.run(scenario())
    page = asyncio.run(server.context.store.latest_page("sess-pages"))
    assert page is not None and page.page_id == 7 and page.lines == ((5, 20, 80, 30),)
    np.testing.assert_array_equal(page.mask, mask)


def test_a_g4_page_is_stored_in_version_3_and_refused_in_version_2(server: LiveServer) -> None:
    mask = np.zeros((60, 90), np.uint8)
    mask[20:30, 5:80:3] = 1
    shape, bits = pack_mask(mask)
    page = Page(seq=0, page_id=3, t_us=5, shape=shape, bits=bits, lines=((5, 20, 80, 30),), enc="g4")

    async def scenario() -> None:
        ws, welcome = await open_stream(server, "sess-g4", mode="pages", v=3)
        assert welcome.v == 3
        async with ws:
            await ws.send(encode(page))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=0)
        ws, welcome = await open_stream(server, "sess-g4-v2", mode="pages", v=2)
        assert welcome.v == 2
        async with ws:
            await ws.send(encode(page))  # version 3 content
            error, code, _ = await expect_error_close(ws)
            assert code == CloseCode.UNEXPECTED and "version 3 content in a version 2 session" in error.message

    asyncio.run(scenario())
    stored = asyncio.run(server.context.store.latest_page("sess-g4"))
    assert stored is not None and stored.page_id == 3
    np.testing.assert_array_equal(stored.mask, mask)
    assert asyncio.run(server.context.store.latest_page("sess-g4-v2")) is None


def test_metrics_count_connections_messages_and_bytes(server: LiveServer) -> None:
    asyncio.run(stream_frames(server, "sess-m", range(3)))
    metrics = server.context.metrics
    assert metrics.connections._value.get() == 1
    assert metrics.frames_stored._value.get() == 3
    assert metrics.messages.labels(type="frame")._value.get() == 3
    assert metrics.bytes_received._value.get() == len(encode(hello("sess-m"))) + sum(len(encode(frame(s))) for s in range(3))


def test_storage_failure_closes_with_internal_error_and_the_client_can_resume(server: LiveServer, monkeypatch: pytest.MonkeyPatch) -> None:
    store = server.context.store
    real_add_frame = store.add_frame

    async def failing_add_frame(session_id: str, record: StoredFrame) -> Any:
        if record.seq == 2:
            raise StoreError("disk full")
        return await real_add_frame(session_id, record)

    monkeypatch.setattr(store, "add_frame", failing_add_frame)

    async def scenario() -> None:
        ws, _ = await open_stream(server, "sess-fail")
        for seq in range(3):
            await ws.send(encode(frame(seq)))
        assert [decode(await ws.recv(), max_bytes=LIMIT) for _ in range(2)] == [Ack(seq=0), Ack(seq=1)]
        error, code, _ = await expect_error_close(ws)
        assert error.code == code == CloseCode.INTERNAL_ERROR and "disk full" in error.message
        monkeypatch.setattr(store, "add_frame", real_add_frame)
        ws, welcome = await open_stream(server, "sess-fail")
        assert welcome.last_acked_seq == 1
        async with ws:
            await ws.send(encode(frame(2)))
            assert decode(await ws.recv(), max_bytes=LIMIT) == Ack(seq=2)

    asyncio.run(scenario())


def test_close_reason_fits_the_websocket_limit() -> None:
    reason = close_reason("é" * 200)
    assert len(reason.encode()) <= 123 and reason == "é" * 60
