"""The uplink against a small websockets server that speaks the proto and can be killed."""

from __future__ import annotations

import asyncio
import random
import socket
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from small_disk import small_disk
from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from darkread.edge.config import UplinkConfig
from darkread.edge.errors import SpoolError
from darkread.edge.spool import Spool
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.uplink import Uplink, backoff_delays
from darkread.proto.messages import Ack, Frame, Hello, Welcome, decode, encode, pack_mask

KEY = "test-key"


class ProtoServer:
    """A cloud stand-in: durable per-session storage (survives restarts), cumulative acks.

    ``drop_after`` closes each connection abruptly after that many stored messages, before
    acknowledging the last one (its ack is lost, as on a network drop).
    """

    def __init__(
        self,
        drop_after: int | None = None,
        reject_frame_id: int | None = None,
        stall_after: int | None = None,
        stored: dict[str, list[int]] | None = None,
    ) -> None:
        self.stored: dict[str, list[int]] = {} if stored is None else stored  # shared: instances on one database
        self.stall_after = stall_after  # the first connection stops acking after this many (commits hang)
        self.connections = 0
        self.reject_frame_id = reject_frame_id
        self.received = 0
        self.hellos: list[Hello] = []
        self.drop_after = drop_after
        self.port = 0
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._thread.start()
        self._server = None

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/v1/stream"

    def start(self) -> None:
        async def start() -> None:
            self._server = await serve(self._handler, "127.0.0.1", self.port, process_request=self._auth)
            self.port = self._server.sockets[0].getsockname()[1]

        asyncio.run_coroutine_threadsafe(start(), self._loop).result(5)

    def kill(self) -> None:
        async def kill() -> None:
            self._server.close(close_connections=True)
            await self._server.wait_closed()

        asyncio.run_coroutine_threadsafe(kill(), self._loop).result(5)

    def close(self) -> None:
        if self._server is not None and self._server.is_serving():
            self.kill()
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5)
        self._loop.close()

    def _auth(self, connection: ServerConnection, request: Request) -> Response | None:
        if request.headers.get("X-API-Key") != KEY:
            return Response(403, "Forbidden", Headers(), b"bad key")
        return None

    async def _handler(self, ws: ServerConnection) -> None:
        hello = decode(await ws.recv(), max_bytes=1 << 22)
        assert isinstance(hello, Hello)
        self.hellos.append(hello)
        self.connections += 1
        stalls = self.stall_after is not None and self.connections == 1
        seqs = self.stored.setdefault(hello.session_id, [])
        last = seqs[-1] if seqs else -1
        await ws.send(encode(Welcome(session_id=hello.session_id, last_acked_seq=last, max_message_bytes=1 << 22)))
        count = 0
        async for data in ws:
            message = decode(data, max_bytes=1 << 22)
            self.received += 1
            if not isinstance(message, Frame):
                continue
            if message.frame_id == self.reject_frame_id:
                await ws.close(4422, "bad mask")  # as the cloud does for an invalid message
                return
            if not seqs or message.seq > seqs[-1]:
                seqs.append(message.seq)
                count += 1
            if self.drop_after is not None and count >= self.drop_after:
                ws.transport.abort()  # network drop: the last ack never leaves
                return
            if stalls and self.stall_after is not None and count > self.stall_after:
                continue  # the connection stays open, the acks stop
            await ws.send(encode(Ack(seq=seqs[-1])))


def wait_for(condition, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def frame(frame_id: int) -> Frame:
    mask = np.zeros((100, 200), np.uint8)
    mask[frame_id % 100, :] = 1
    shape, bits = pack_mask(mask)
    return Frame(
        seq=0, frame_id=frame_id, t_us=frame_id * 1000, origin=(10, 20), gaze_px=(110.0, 70.0),
        gaze_rad=(0.01, -0.02), events_used=1600, shape=shape, bits=bits,
    )


def settings(url: str, **kwargs: Any) -> UplinkConfig:
    base: dict[str, Any] = dict(url=url, api_key=KEY, device_id="glasses-1", backoff_initial_s=0.02, backoff_max_s=0.1)
    base.update(kwargs)
    return UplinkConfig(**base)


def make_uplink(config: UplinkConfig, spool: Spool, metrics: EdgeMetrics | None = None) -> Uplink:
    """An uplink for a 1280x720 sensor and the 100x200 window (what its hello announces)."""
    return Uplink(config, spool, metrics, sensor_wh=(1280, 720), fovea_hw=(100, 200))


@pytest.fixture
def server():
    srv = ProtoServer()
    srv.start()
    yield srv
    srv.close()


def test_frames_delivered_in_order_and_acked(server: ProtoServer) -> None:
    metrics = EdgeMetrics()
    uplink = make_uplink(settings(server.url), Spool(None), metrics)
    uplink.start()
    seqs = [uplink.submit(frame(i), submitted_at=time.monotonic()) for i in range(30)]
    assert uplink.stop(drain_timeout_s=5)
    assert seqs == list(range(30))
    assert server.stored[uplink.session_id] == seqs
    assert uplink.spool.depth == 0
    assert metrics.totals["messages_sent"] == 30 and metrics.totals["bytes_sent"] > 30 * 2500
    assert len(metrics.latency_ms) == 30
    hello = server.hellos[0]
    assert hello.device_id == "glasses-1" and hello.fovea == (100, 200) and hello.sensor == (1280, 720)


def test_network_drops_lose_nothing_and_duplicate_nothing() -> None:
    server = ProtoServer(drop_after=7)
    server.start()
    try:
        uplink = make_uplink(settings(server.url), Spool(None))
        uplink.start()
        for i in range(40):
            uplink.submit(frame(i))
        assert uplink.stop(drain_timeout_s=10)
        assert server.stored[uplink.session_id] == list(range(40))
        assert uplink.metrics.totals["reconnects"] >= 5
        assert len(server.hellos) >= 6  # one per connection, same session every time
        assert {h.session_id for h in server.hellos} == {uplink.session_id}
    finally:
        server.close()


def test_cloud_restart_mid_stream_resends_spooled_frames(server: ProtoServer) -> None:
    uplink = make_uplink(settings(server.url), Spool(None))
    uplink.start()
    for i in range(10):
        uplink.submit(frame(i))
    assert uplink.wait_drained(5)
    server.kill()
    for i in range(10, 25):  # produced while the cloud is down: spooled
        uplink.submit(frame(i))
    assert wait_for(lambda: not uplink.connected.is_set())
    assert uplink.spool.depth == 15
    server.start()  # same port, same storage
    assert uplink.stop(drain_timeout_s=5)
    assert server.stored[uplink.session_id] == list(range(25))


def test_a_closed_instance_fails_over_to_the_next_on_the_same_database() -> None:
    database: dict[str, list[int]] = {}
    a, b = ProtoServer(stored=database), ProtoServer(stored=database)
    a.start()
    b.start()
    try:
        uplink = make_uplink(settings(f"{a.url}, {b.url}"), Spool(None))
        uplink.start()
        for i in range(10):
            uplink.submit(frame(i))
        assert uplink.wait_drained(5)
        a.kill()
        for i in range(10, 30):
            uplink.submit(frame(i))
        assert uplink.stop(drain_timeout_s=5)
        assert database[uplink.session_id] == list(range(30))  # nothing lost, nothing twice
        assert uplink.url == b.url and uplink.metrics.totals["failovers"] >= 1
        assert [h.session_id for h in b.hellos] == [uplink.session_id]
    finally:
        a.close()
        b.close()


def test_an_instance_that_refuses_connections_is_skipped_without_backing_off(server: ProtoServer) -> None:
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        dead = f"ws://127.0.0.1:{probe.getsockname()[1]}/v1/stream"
    uplink = make_uplink(settings(f"{dead},{server.url}", backoff_initial_s=30, backoff_max_s=30), Spool(None))
    started = time.monotonic()
    uplink.start()
    for i in range(5):
        uplink.submit(frame(i))
    assert uplink.stop(drain_timeout_s=5)
    assert time.monotonic() - started < 5  # the 30 s backoff waits only after every instance failed
    assert server.stored[uplink.session_id] == list(range(5))


def test_edge_restart_resends_from_disk_spool(tmp_path: Path, server: ProtoServer) -> None:
    server.kill()
    first = make_uplink(settings(server.url), Spool(tmp_path))
    first.start()
    for i in range(12):
        first.submit(frame(i))
    assert not first.stop(drain_timeout_s=0.1)  # cloud down: stays on disk
    first.spool.close()

    server.start()
    second = make_uplink(settings(server.url), Spool(tmp_path))
    assert second.session_id == first.session_id
    second.start()
    for i in range(12, 15):
        second.submit(frame(i))
    assert second.stop(drain_timeout_s=5)
    assert server.stored[first.session_id] == list(range(15))

    second.spool.close()
    third = make_uplink(settings(server.url), Spool(tmp_path))  # nothing pending: a new session
    assert third.session_id != first.session_id
    third.start()
    assert third.submit(frame(15)) == 0  # its own seqs, from 0: no placeholder for the 15 sent before
    assert third.stop(drain_timeout_s=5)
    assert server.stored[third.session_id] == [0]


def test_wrong_key_is_refused_and_kept_in_spool(server: ProtoServer) -> None:
    uplink = make_uplink(settings(server.url, api_key="wrong"), Spool(None))
    uplink.start()
    uplink.submit(frame(0))
    assert wait_for(lambda: "403" in uplink.last_error)
    assert not uplink.stop(drain_timeout_s=0.1)
    assert "403" in uplink.last_error
    assert uplink.spool.depth == 1 and server.stored == {}


def test_in_flight_window_is_respected(server: ProtoServer) -> None:
    uplink = make_uplink(settings(server.url, max_in_flight=4), Spool(None))
    uplink.start()
    for i in range(20):
        uplink.submit(frame(i))
    assert uplink.stop(drain_timeout_s=5)
    assert server.stored[uplink.session_id] == list(range(20))


def test_backoff_grows_with_jitter_and_caps() -> None:
    delays = backoff_delays(0.1, 1.0, random.Random(1))
    values = [next(delays) for _ in range(8)]
    assert 0.05 <= values[0] <= 0.1
    assert 0.1 <= values[1] <= 0.2
    assert all(0.5 <= v <= 1.0 for v in values[4:])
    assert len(set(values)) == len(values)  # jittered


def test_backoff_restarts_small_after_a_stable_connection(server: ProtoServer) -> None:
    server.kill()
    uplink = make_uplink(settings(server.url, backoff_initial_s=0.02, backoff_max_s=5.0, stable_connection_s=0.05), Spool(None))
    delays: list[float] = []
    sleep = uplink._sleep_or_stop

    async def recording_sleep(delay_s: float) -> None:
        delays.append(delay_s)
        await sleep(delay_s)

    uplink._sleep_or_stop = recording_sleep  # type: ignore[method-assign]  # the test records the back-off delays
    uplink.start()
    assert wait_for(lambda: len(delays) >= 4)  # outage 1: the delays grow
    server.start()
    assert wait_for(uplink.connected.is_set)
    n_before = len(delays)
    time.sleep(0.1)  # stable for longer than stable_connection_s
    server.kill()
    assert wait_for(lambda: len(delays) > n_before)
    uplink.stop(drain_timeout_s=0)
    assert delays[3] > delays[0]
    assert delays[n_before] <= 0.02  # outage 2 starts from the shortest delay again


def test_a_message_the_cloud_rejects_is_dropped_not_resent_forever() -> None:
    server = ProtoServer(reject_frame_id=3)
    server.start()
    try:
        uplink = make_uplink(settings(server.url), Spool(None))
        uplink.start()
        for i in range(8):
            uplink.submit(frame(i))
        assert uplink.stop(drain_timeout_s=5)
        assert server.stored[uplink.session_id] == [0, 1, 2, 4, 5, 6, 7]
        assert uplink.metrics.totals["messages_rejected"] == 1
    finally:
        server.close()


def test_acks_that_stop_advancing_make_the_uplink_reconnect() -> None:
    server = ProtoServer(stall_after=3)
    server.start()
    uplink = make_uplink(settings(server.url, ack_timeout_s=0.5, heartbeat_s=0.2), Spool(None))
    try:
        uplink.start()
        started = time.monotonic()
        for i in range(10):
            uplink.submit(frame(i))
        assert uplink.wait_drained(5.0), "stuck behind a connection whose acks stopped"
        elapsed = time.monotonic() - started
    finally:
        uplink.stop(1.0)
        server.close()
    assert server.stored[uplink.session_id] == list(range(10))
    assert uplink.metrics.totals["ack_timeouts"] == 1 and server.connections == 2
    assert 0.5 <= elapsed < 3.0


def test_messages_the_full_spool_evicted_are_reported_as_lost() -> None:
    spool, metrics = Spool(None, max_messages=4), EdgeMetrics()
    make_uplink(settings("ws://127.0.0.1:1/v1/stream"), spool, metrics)  # (never started: nothing connects)
    for _ in range(10):
        spool.append(spool.allocate_seq(), b"x" * 10)
    snap = metrics.snapshot()
    assert snap.spool_depth == 4 and snap.spool_lost == 6 and "(lost 6)" in snap.log_line()


def test_an_ack_the_full_spool_cannot_record_ends_the_uplink_cleanly(server: ProtoServer, tmp_path: Path) -> None:
    """A full disk fails the DELETE of acknowledged messages: the uplink stops with a SpoolError the
    daemon raises (and keeps every message), instead of a thread dead with a traceback."""
    uncaught: list[threading.ExceptHookArgs] = []
    previous_hook, threading.excepthook = threading.excepthook, uncaught.append
    try:
        with small_disk(tmp_path / "disk", 2048) as disk:
            spool = Spool(disk.path / "spool")
            uplink = make_uplink(settings(server.url), spool)
            for i in range(40):  # made while offline: spooled
                uplink.submit(frame(i))
            disk.fill()
            uplink.start()
            assert wait_for(lambda: bool(uplink.fatal_error), 10), uplink.last_error
            assert isinstance(uplink.failure, SpoolError) and "disk is full" in str(uplink.failure)
            assert str(disk.path / "spool") in uplink.fatal_error
            assert uplink.wait_drained(30) is False  # at once: no drain wait for an uplink that stopped
            assert not uplink.stop(drain_timeout_s=30)
            assert not uplink._thread.is_alive()  # type: ignore[union-attr]
            assert spool.depth == 40 and "40 messages stay in the spool" in uplink.left_behind()
            spool.close()
            disk.empty_filler()
            assert [seq for seq, _ in Spool(disk.path / "spool").pending(limit=100)] == list(range(40))
    finally:
        threading.excepthook = previous_hook
    assert uncaught == []
    stored = server.stored[uplink.session_id]
    assert stored == list(range(len(stored)))  # what the cloud has it keeps; it drops the duplicates resent later
