"""``darkread cloud serve`` at the edges of its life: a stuck store at shutdown, bad data dirs, a
second process on the same data dir. Real processes on 127.0.0.1."""

from __future__ import annotations

import asyncio
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from websockets.asyncio.client import connect

from darkread.proto.messages import Hello, encode

from .test_edge_to_cloud import API_KEY, Cloud, free_port

pytestmark = pytest.mark.slow


def serve(data_dir: Path, port: int, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "darkread", "cloud", "serve", "--port", str(port), "--data-dir", str(data_dir)],
        env={**os.environ, "DARKREAD_API_KEY": API_KEY, **env}, capture_output=True, text=True, timeout=60,
    )


def test_shutdown_with_a_stuck_store_has_a_deadline(tmp_path: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    os.environ["DARKREAD_SHUTDOWN_TIMEOUT_S"] = "2"
    try:
        cloud.start()
    finally:
        del os.environ["DARKREAD_SHUTDOWN_TIMEOUT_S"]
    holder = sqlite3.connect(tmp_path / "cloud" / "darkread.sqlite3", isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")  # the store's writer now waits on the database lock

    async def stuck_client() -> float:
        ws = await connect(f"ws://127.0.0.1:{port}/v1/stream", additional_headers={"X-API-Key": API_KEY})
        await ws.send(encode(Hello(device_id="g", session_id="stuck", mode="frames", sensor=(1280, 720), fovea=(100, 200))))
        await asyncio.sleep(1.0)  # hello handed to the stuck store; no welcome will come
        assert cloud.process is not None
        started = time.monotonic()
        cloud.process.send_signal(signal.SIGTERM)
        await asyncio.to_thread(cloud.process.wait, 60)
        seconds = time.monotonic() - started
        await ws.close()
        return seconds

    try:
        seconds = asyncio.run(stuck_client())
    finally:
        holder.rollback() if holder.in_transaction else None
        holder.close()
        cloud.kill()
    print(f"shutdown with a stuck store: {seconds:.1f} s (graceful deadline 2 s)")
    assert seconds < 15  # a deadline exists (before: 29.5 s, or 19 min with a slow reader); 2 s + 2 s + start-up here


@pytest.mark.parametrize("case", ["file instead of a directory", "corrupt database", "read-only", "not a directory parent"])
def test_an_unusable_data_dir_is_one_line_and_a_non_zero_exit(tmp_path: Path, case: str) -> None:
    if case == "file instead of a directory":
        data_dir = tmp_path / "data"
        data_dir.write_text("not a directory")
    elif case == "corrupt database":
        data_dir = tmp_path / "data"
        data_dir.mkdir()
        (data_dir / "darkread.sqlite3").write_bytes(b"garbage" * 1000)
    elif case == "read-only":
        data_dir = Path("/proc/darkread-data")  # a read-only file system, even for root
    else:
        (tmp_path / "file").write_text("x")
        data_dir = tmp_path / "file" / "data"
    run = serve(data_dir, free_port())
    lines = run.stderr.strip().splitlines()
    print(f"{case}: exit {run.returncode}: {lines[-1] if lines else ''}")
    assert run.returncode != 0
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr[-1500:]
    assert str(data_dir) in lines[0]


def test_a_second_cloud_on_the_same_data_dir_is_refused(tmp_path: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    try:
        run = serve(tmp_path / "cloud", free_port())
    finally:
        cloud.stop()
    lines = run.stderr.strip().splitlines()
    print(f"second cloud on one data dir: exit {run.returncode}: {lines[-1] if lines else ''}")
    assert run.returncode != 0 and len(lines) == 1 and "Traceback" not in run.stderr
    assert "another darkread cloud" in lines[0] and f"pid {cloud.process.pid}" in lines[0]
