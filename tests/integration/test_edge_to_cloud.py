"""A recording through a real edge into a real cloud that is killed and restarted mid-stream.

The cloud runs as a subprocess (``darkread cloud serve``, uvicorn on 127.0.0.1, random port);
the edge runs in this process so the test can read exactly which seqs it handed to the uplink.
Every frame must be stored exactly once: the cloud's seqs equal the edge's, no gap, no extra.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
from cloud_process import API_KEY, CloudProcess, free_port
from factories import sum_bins_model

from darkread.edge.builder import build_edge
from darkread.edge.config import load_config
from darkread.edge.daemon import Daemon
from darkread.edge.notify import Notifier

pytestmark = pytest.mark.slow


class Cloud(CloudProcess):
    def stored_seqs(self, session_id: str) -> list[int]:
        with sqlite3.connect(self.data_dir / "darkread.sqlite3") as db:
            return [seq for (seq,) in db.execute("SELECT seq FROM frames WHERE session_id = ? ORDER BY seq", (session_id,))]


def test_cloud_killed_mid_stream_every_frame_delivered_once(tmp_path: Path, recording: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    try:
        config = load_config(
            environ={},
            overrides={
                "source": {"kind": "replay", "path": str(recording), "speed": 1.0},
                "gaze": {"kind": "recording"},
                "pipeline": {"model": str(sum_bins_model(tmp_path / "tiny.onnx")), "infer": "every-window"},  # a frame per window
                "uplink": {
                    "url": f"ws://127.0.0.1:{port}/v1/stream", "api_key": API_KEY,
                    "spool_dir": str(tmp_path / "spool"), "backoff_initial_s": 0.05, "backoff_max_s": 0.3,
                    "drain_timeout_s": 20.0,
                },
            },
        )
        notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        notify.bind(str(tmp_path / "notify.sock"))
        notify.settimeout(0.2)
        states: list[str] = []

        def listen() -> None:  # as systemd does: read every notification as it comes
            with contextlib.suppress(OSError):
                while True:
                    with contextlib.suppress(TimeoutError):
                        states.append(notify.recv(4096).decode())

        threading.Thread(target=listen, daemon=True).start()
        environ = {"NOTIFY_SOCKET": str(tmp_path / "notify.sock"), "WATCHDOG_USEC": "100000"}
        notifier = Notifier(environ)
        service = build_edge(config, watchdog=notifier.watchdog_tick)
        daemon = Daemon(service, notifier, tick_s=0.02)
        result: list[int] = []
        edge = threading.Thread(target=lambda: result.append(daemon.run()))
        edge.start()

        def sent() -> int:  # frames handed to the uplink so far: the spool numbers them from 0
            return service.uplink.spool.last_allocated_seq + 1

        deadline = time.monotonic() + 10
        while sent() < 10 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert sent() >= 10, "the edge made no frames"
        cloud.kill()  # mid-stream: frames in flight and unacknowledged
        killed_at = sent()
        time.sleep(0.5)  # frames keep coming and go to the spool
        assert sent() > killed_at
        cloud.start()  # same data dir, same port

        edge.join(timeout=40)
        assert not edge.is_alive()
        assert result == [0], "the edge did not drain its spool"
        stored = cloud.stored_seqs(service.uplink.session_id)
        assert stored == list(range(sent()))  # every frame exactly once, in order
        assert sent() == service.metrics.totals["frames"]
        assert service.metrics.totals["reconnects"] >= 1
        assert service.uplink.spool.depth == 0

        notify.close()
        assert states[0].startswith("READY=1\nSTATUS=replay 1280x720 open, model tiny.onnx warm")
        assert states.count("WATCHDOG=1") >= 10  # fed from the processing loop, every ~50 ms
        assert "STOPPING=1" in states
    finally:
        if "daemon" in locals():
            daemon.force_exit = True
            daemon.should_exit.set()
            edge.join(timeout=10)
        cloud.stop()


def test_edge_run_cli_stitches_pages_on_the_glasses(tmp_path: Path, recording: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    try:
        env = dict(os.environ, DARKREAD_EDGE_UPLINK_API_KEY=API_KEY)
        run = subprocess.run(
            [sys.executable, "-m", "darkread", "edge", "run", "--replay", str(recording),
             "--cloud", f"ws://127.0.0.1:{port}/v1/stream", "--speed", "max", "--mode", "pages",
             "--model", str(sum_bins_model(tmp_path / "tiny.onnx")), "--spool", str(tmp_path / "spool"),
             "--session", "cli-pages", "--drain-timeout", "15"],
            env=env, capture_output=True, text=True, timeout=60,
        )
        assert run.returncode == 0, run.stderr[-2000:]
        with sqlite3.connect(tmp_path / "cloud" / "darkread.sqlite3") as db:
            pages = db.execute("SELECT seq, rows, cols FROM pages WHERE session_id = 'cli-pages'").fetchall()
            frames = db.execute("SELECT COUNT(*) FROM frames WHERE session_id = 'cli-pages'").fetchone()[0]
        assert pages and frames == 0
        assert all(rows > 0 and cols > 0 for _, rows, cols in pages)
        assert "stopped (clean)" in run.stderr
        # it said plainly where it streams and where the session's live page is; the page is there
        live = f"http://127.0.0.1:{port}/sessions/cli-pages"
        assert f"streaming session cli-pages to ws://127.0.0.1:{port}/v1/stream; live page: {live}" in run.stderr.splitlines()
        page = httpx.get(live, timeout=10)
        assert page.status_code == 200 and "cli-pages" in page.text
    finally:
        cloud.stop()
