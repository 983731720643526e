"""Cloud ingest: frames per second acknowledged (stored and committed) with 1, 10 and 50
concurrent websocket streams on loopback, next to the store alone (no network, no protocol)
measured in the same run; on SQLite, then on PostgreSQL (a real server started for the run with
fsync on, as SQLite's synchronous=FULL), each PostgreSQL figure next to SQLite's.

Then 50 replays at real time (30 frames/s each) spread over two instances on one PostgreSQL; the
first instance is SIGKILLed halfway and restarted, its replays fail over: every frame must be
stored exactly once (``replays.py``).

The service runs in its own process (``darkread cloud serve``) so client and server do not share
an interpreter lock; each stream pipelines up to 32 unacknowledged frames, as the edge uplink does.
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from darkread.cloud.store import SessionSpec, SqliteStore
from darkread.cloud.store.postgres import PostgresStore
from darkread.cloud.stream import stored_frame
from darkread.lab.bench import BenchContext, Figure
from darkread.lab.bench.replays import count_stored_in, run_replays
from darkread.lab.fixtures.pg_server import PostgresUnavailable, TemporaryPostgres
from darkread.proto.messages import Ack, Frame, Hello, Welcome, decode, encode, pack_mask
from darkread.proto.messages import decode as decode_message

if TYPE_CHECKING:
    from darkread.cloud.store import SessionStore
    from darkread.lab.fixtures.pg_server import TemporaryPostgres

API_KEY = "bench-key"
STREAMS = (1, 10, 50)
WINDOW = 32  # unacknowledged frames per stream
FRAME_RATE_HZ = 30  # what one pair of glasses sends at most


def _frame_bytes(count: int) -> list[bytes]:
    rng = np.random.default_rng(0)
    masks = rng.random((8, 100, 200)) < 0.08
    packed = [pack_mask(mask) for mask in masks]
    return [
        encode(Frame(seq, seq, 33_000 * seq, (540, 310), (640.0, 360.0), (0.0, 0.0), 1600, *packed[seq % len(packed)]))
        for seq in range(count)
    ]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def start_server(data_dir: Path, database_url: str | None = None, port: int = 0) -> tuple[subprocess.Popen[bytes], int]:
    port = port or _free_port()
    env = {**os.environ, "DARKREAD_API_KEY": API_KEY}
    if database_url:
        env["DARKREAD_DATABASE_URL"] = database_url
    data_dir.parent.mkdir(parents=True, exist_ok=True)
    with open(data_dir.with_name(data_dir.name + ".log"), "ab") as server_log:  # warnings and errors only
        process = subprocess.Popen(
            [sys.executable, "-m", "darkread.cli", "-q", "cloud", "serve", "--port", str(port), "--data-dir", str(data_dir)],
            env=env,
            stdout=server_log,
            stderr=server_log,
        )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError("the cloud service exited during start-up")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return process, port
        except OSError:
            time.sleep(0.1)
    process.kill()
    process.wait(timeout=30)
    raise RuntimeError("the cloud service did not start within 60 s")


def stop_server(process: subprocess.Popen[bytes], timeout_s: float = 30.0) -> None:
    """SIGTERM, and SIGKILL (said on stderr, with where the service's log is) if it has not shut
    down within ``timeout_s``: its own shutdown is bounded well below that."""
    process.terminate()
    try:
        process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(timeout=30)
        where = process.args[-1] if isinstance(process.args, list) else "?"
        print(f"[bench] warning: the cloud service did not stop within {timeout_s:.0f} s of SIGTERM and was killed;"
              f" its log: {where}.log", file=sys.stderr)


async def _one_stream(url: str, session_id: str, frames: list[bytes], deadline: float) -> int:
    from websockets.asyncio.client import connect

    acked = -1
    async with connect(url, additional_headers={"X-API-Key": API_KEY}, max_size=None) as ws:
        hello = Hello(device_id="bench", session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))
        await ws.send(encode(hello))
        if not isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome):
            raise RuntimeError("no welcome")
        sent = 0
        while acked < len(frames) - 1 and time.monotonic() < deadline:
            while sent < len(frames) and sent - acked - 1 < WINDOW:
                await ws.send(frames[sent])
                sent += 1
            ack = decode(await ws.recv(), max_bytes=1 << 20)
            if isinstance(ack, Ack):
                acked = ack.seq
    return acked + 1


async def _ingest(url: str, streams: int, frames_per_stream: int, time_limit_s: float, tag: str) -> float:
    frames = _frame_bytes(frames_per_stream)
    started = time.monotonic()
    deadline = started + time_limit_s
    counts = await asyncio.gather(*(_one_stream(url, f"{tag}-{i}", frames, deadline) for i in range(streams)))
    return sum(counts) / (time.monotonic() - started)


def _store_alone(open_store: Callable[[], Awaitable[SessionStore]], count: int) -> float:

    messages = [decode_message(data, max_bytes=1 << 20) for data in _frame_bytes(count)]
    frames = [stored_frame(message) for message in messages if isinstance(message, Frame)]

    async def write() -> float:

        store = await open_store()
        try:
            await store.open_session(SessionSpec("alone", "bench", "frames", (1280, 720), (100, 200)))
            started = time.perf_counter()
            pending: list[asyncio.Future[object]] = []
            for frame in frames:
                pending.append(asyncio.ensure_future(store.add_frame("alone", frame)))
                if len(pending) >= WINDOW:
                    await pending.pop(0)
            await asyncio.gather(*pending)
            return count / (time.perf_counter() - started)
        finally:
            await store.close()

    return asyncio.run(write())


def _ingest_rates(data_dir: Path, database_url: str | None, total: int, time_limit_s: float, least: int) -> dict[int, float]:
    """Frames/s acknowledged by one instance with 1, 10 and 50 streams."""
    process, port = start_server(data_dir, database_url)
    try:
        url = f"ws://127.0.0.1:{port}/v1/stream"
        return {
            streams: asyncio.run(_ingest(url, streams, max(total // streams, least), time_limit_s, f"s{streams}"))
            for streams in STREAMS
        }
    finally:
        stop_server(process)


def _replays(ctx: BenchContext, pg: TemporaryPostgres) -> list[Figure]:
    """50 paced replays over two instances, the first killed halfway and restarted."""

    database_url = pg.create_database("replays")
    instances = [start_server(ctx.scratch / f"replay-{name}", database_url) for name in "ab"]
    killed_at: list[float] = []

    def kill_and_restart_a() -> None:
        process, port = instances[0]
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=10)
        killed_at.append(time.monotonic())
        instances[0] = start_server(ctx.scratch / "replay-a", database_url, port=port)

    sessions, seconds = ctx.runs(50, 50, 4), float(ctx.runs(60, 15, 2))
    logging.getLogger("darkread.edge.uplink").setLevel(logging.ERROR)  # 25 failovers, one line each
    try:
        urls = [f"ws://127.0.0.1:{port}/v1/stream" for _, port in instances]
        outcome = run_replays(urls, API_KEY, count_stored_in(database_url), sessions=sessions, seconds=seconds,
                              at_half=kill_and_restart_a)  # fmt: skip
    finally:
        for process, _ in instances:
            stop_server(process)
    what = f"{sessions} replays at 1x over 2 instances, {outcome.seconds:.0f} s, A SIGKILLed halfway"
    ctx.notes.append(
        f"{what}: {outcome.submitted} frames submitted, {outcome.stored} stored, {outcome.lost} lost, "
        f"{outcome.duplicated} duplicated, {outcome.wrong_sessions} sessions with gaps, {outcome.failovers} failovers"
    )
    reference = f"submitted: {outcome.submitted}"
    return [
        Figure("cloud_pg_replays_frames_stored", outcome.stored, f"{what}: frames stored", reference, "= submitted"),
        Figure("cloud_pg_replays_frames_lost", outcome.lost, "  ... frames lost", reference, "0"),
        Figure("cloud_pg_replays_frames_duplicated", outcome.duplicated, "  ... frames stored twice", reference, "0"),
        Figure("cloud_pg_replays_failovers", outcome.failovers, "  ... uplink failovers", "", f">= {sessions // 2}"),
    ]


def run(ctx: BenchContext) -> list[Figure]:

    total = ctx.runs(6000, 1500, 100)  # frames per configuration, split over the streams
    time_limit_s = float(ctx.runs(30, 10, 10))
    least = 2 if ctx.smoke else 20  # frames per stream

    async def open_sqlite() -> SessionStore:
        return SqliteStore(ctx.scratch / "store-alone")

    alone = _store_alone(open_sqlite, total)
    sqlite = _ingest_rates(ctx.scratch / "cloud-bench", None, total, time_limit_s, least)
    figures = [
        Figure(
            key=f"cloud_ingest_frames_per_s_{streams}",
            value=rate,
            label=f"cloud ingest, SQLite, {streams} stream(s) [frames/s]",
            reference=f"store alone, no network: {alone:.0f} frames/s",
            goal=f">= {streams * FRAME_RATE_HZ} ({FRAME_RATE_HZ} frames/s per stream)",
        )
        for streams, rate in sqlite.items()
    ]
    pg = TemporaryPostgres(durable=True)
    try:
        pg.start()
    except PostgresUnavailable as exc:
        pg.stop()
        ctx.notes.append(f"PostgreSQL figures skipped: {exc}")
        return figures
    try:
        alone_url = pg.create_database("alone")
        pg_alone = _store_alone(lambda: PostgresStore.open(alone_url), total)
        rates = _ingest_rates(ctx.scratch / "cloud-bench-pg", pg.create_database("ingest"), total, time_limit_s, least)
        figures += [
            Figure(
                key=f"cloud_ingest_pg_frames_per_s_{streams}",
                value=rate,
                label=f"cloud ingest, PostgreSQL, {streams} stream(s) [frames/s]",
                reference=f"SQLite {sqlite[streams]:.0f}; PG store alone {pg_alone:.0f}",
                goal=f">= {streams * FRAME_RATE_HZ} ({FRAME_RATE_HZ} frames/s per stream)",
            )
            for streams, rate in rates.items()
        ]
        figures += _replays(ctx, pg)
    finally:
        pg.stop()
    return figures
