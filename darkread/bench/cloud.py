"""Cloud ingest: frames per second acknowledged (stored and committed) with 1, 10 and 50
concurrent websocket streams on loopback, next to the store alone (no network, no protocol)
measured in the same run.

The service runs in its own process (``darkread cloud serve``) so client and server do not share
an interpreter lock; each stream pipelines up to 32 unacknowledged frames, as the edge uplink does.
"""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from darkread.bench import BenchContext, Figure
from darkread.proto.messages import Ack, Frame, Hello, Welcome, decode, encode, pack_mask

API_KEY = "bench-key"
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


def _start_server(data_dir: Path) -> tuple[subprocess.Popen[bytes], int]:
    port = _free_port()
    env = {**os.environ, "DARKREAD_API_KEY": API_KEY}
    process = subprocess.Popen(
        [sys.executable, "-m", "darkread.cli", "-q", "cloud", "serve", "--port", str(port), "--data-dir", str(data_dir)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError("the cloud service exited during start-up")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return process, port
        except OSError:
            time.sleep(0.1)
    process.terminate()
    raise RuntimeError("the cloud service did not start within 30 s")


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


def _store_alone(data_dir: Path, count: int) -> float:
    from darkread.cloud.store import SessionSpec, SqliteStore
    from darkread.cloud.stream import stored_frame
    from darkread.proto.messages import decode as decode_message

    frames = [stored_frame(decode_message(data, max_bytes=1 << 20)) for data in _frame_bytes(count)]  # type: ignore[arg-type]

    async def write() -> float:
        store = SqliteStore(data_dir)
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


def run(ctx: BenchContext) -> list[Figure]:
    total = ctx.runs(6000, 1500, 100)  # frames per configuration, split over the streams
    time_limit_s = float(ctx.runs(30, 10, 10))
    least = 2 if ctx.smoke else 20  # frames per stream
    alone = _store_alone(ctx.scratch / "store-alone", total)
    reference = f"store alone, no network: {alone:.0f} frames/s"
    process, port = _start_server(ctx.scratch / "cloud-bench")
    figures = []
    try:
        url = f"ws://127.0.0.1:{port}/v1/stream"
        for streams in (1, 10, 50):
            rate = asyncio.run(_ingest(url, streams, max(total // streams, least), time_limit_s, f"s{streams}"))
            figures.append(
                Figure(
                    key=f"cloud_ingest_frames_per_s_{streams}",
                    value=rate,
                    label=f"cloud ingest, {streams} stream(s) [frames/s]",
                    reference=reference,
                    goal=f">= {streams * FRAME_RATE_HZ} ({FRAME_RATE_HZ} frames/s per stream)",
                )
            )
    finally:
        process.terminate()
        process.wait(timeout=30)
    return figures
