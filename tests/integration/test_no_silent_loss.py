"""No silent loss: real ``darkread edge run`` processes into a real ``darkread cloud serve``.

Every frame an edge makes is either stored by the cloud or still in that edge's spool, and an
edge that could not deliver says so with a non-zero exit status and one line.
"""

from __future__ import annotations

import asyncio
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from factories import sum_bins_model as tiny_model
from websockets.asyncio.client import connect

from darkread.proto.errors import CloseCode
from darkread.proto.messages import Error, Frame, Hello, Welcome, decode, encode, pack_mask

from .test_edge_to_cloud import API_KEY, Cloud, free_port

pytestmark = pytest.mark.slow


def edge_command(recording: Path, port: int, spool: Path, session: str, model: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "darkread", "edge", "run", "--replay", str(recording),
            "--cloud", f"ws://127.0.0.1:{port}/v1/stream", "--speed", "max", "--model", str(model),
            "--spool", str(spool), "--session", session, "--drain-timeout", "20", *extra]


def edge_env() -> dict[str, str]:
    return {**os.environ, "DARKREAD_EDGE_UPLINK_API_KEY": API_KEY}


def spool_counts(spool: Path) -> tuple[int, int]:
    """(messages the spool ever numbered, messages still waiting in it)."""
    with sqlite3.connect(spool / "spool.sqlite3") as db:
        last = db.execute("SELECT value FROM meta WHERE key = 'last_seq'").fetchone()
        pending = db.execute("SELECT COUNT(*) FROM messages").fetchone()[0]
    return (int(last[0]) + 1 if last else 0), int(pending)


def stream_identity(spool: Path) -> str:
    with sqlite3.connect(spool / "spool.sqlite3") as db:
        return str(db.execute("SELECT value FROM meta WHERE key = 'stream_id'").fetchone()[0])


def test_two_edges_on_one_session_one_is_refused_and_nothing_is_lost(tmp_path: Path, recording: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    model = tiny_model(tmp_path / "tiny.onnx")
    try:
        edges = [subprocess.Popen(edge_command(recording, port, tmp_path / f"spool{i}", "shared1", model),
                                  env=edge_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                 for i in range(2)]
        outputs = [edge.communicate(timeout=120)[1] for edge in edges]
        results = [(edge.returncode, err) for edge, err in zip(edges, outputs, strict=True)]
        stored = cloud.stored_seqs("shared1")
    finally:
        cloud.stop()
    codes = sorted(code for code, _ in results)
    assert codes[0] == 0 and codes[1] != 0, [err[-1500:] for _, err in results]
    winner, loser = (0, 1) if results[0][0] == 0 else (1, 0)
    made_w, pending_w = spool_counts(tmp_path / f"spool{winner}")
    made_l, pending_l = spool_counts(tmp_path / f"spool{loser}")
    assert stored == list(range(made_w)) and pending_w == 0  # the owner: every frame stored once
    assert pending_l == made_l  # the refused edge kept every message it made (v2 may not have made one yet)
    last_line = results[loser][1].strip().splitlines()[-1]
    assert "shared1" in last_line and ("another" in last_line or "belongs" in last_line), last_line
    assert "Traceback" not in results[loser][1]
    print(f"two edges, one session: owner made {made_w}, cloud stored {len(stored)}; refused edge made {made_l}, "
          f"kept {pending_l} in its spool (exit {results[loser][0]}): {last_line}")


def test_a_poison_seq_is_refused_and_the_session_goes_on(tmp_path: Path, recording: Path) -> None:
    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    model = tiny_model(tmp_path / "tiny.onnx")
    spool = tmp_path / "spool"
    command = edge_command(recording, port, spool, "poisoned", model)
    try:
        first = subprocess.run(command, env=edge_env(), capture_output=True, text=True, timeout=120)
        assert first.returncode == 0, first.stderr[-2000:]
        made_first, _ = spool_counts(spool)

        async def poison() -> tuple[int | None, str]:
            import socket as socket_

            device = "".join(c if c.isalnum() or c in "._-" else "-" for c in socket_.gethostname())
            async with connect(f"ws://127.0.0.1:{port}/v1/stream", additional_headers={"X-API-Key": API_KEY}) as ws:
                await ws.send(encode(Hello(device_id=device, session_id="poisoned", mode="frames", sensor=(1280, 720),
                                           fovea=(100, 200), stream_id=stream_identity(spool))))
                welcome = decode(await ws.recv(), max_bytes=1 << 22)
                assert isinstance(welcome, Welcome) and welcome.last_acked_seq == made_first - 1
                shape, bits = pack_mask(__import__("numpy").zeros((100, 200), "uint8"))
                await ws.send(encode(Frame(2**63 - 1, 0, 0, (0, 0), (0.0, 0.0), (0.0, 0.0), 0, shape, bits)))
                error = decode(await ws.recv(), max_bytes=1 << 22)
                assert isinstance(error, Error)
                await ws.wait_closed()
                return ws.close_code, error.message

        code, message = asyncio.run(poison())
        assert code == CloseCode.SEQ_GAP, message
        second = subprocess.run(command, env=edge_env(), capture_output=True, text=True, timeout=120)
        stored = cloud.stored_seqs("poisoned")
    finally:
        cloud.stop()
    assert second.returncode == 0, second.stderr[-2000:]
    made_total, pending = spool_counts(spool)
    assert made_total > made_first and pending == 0
    assert stored == list(range(made_total))  # both replays stored, the wild seq never
    print(f"poison seq: close {code} ({message}); first replay {made_first} frames, second "
          f"{made_total - made_first}, cloud stored {len(stored)} of {made_total}")


def test_a_store_failure_closes_the_connection_and_the_edge_resumes(tmp_path: Path, recording: Path) -> None:
    import time
    import urllib.request

    port = free_port()
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    database = tmp_path / "cloud" / "darkread.sqlite3"
    with sqlite3.connect(database) as db:  # a row the store does not expect: its INSERT of seq 5 fails
        db.execute("INSERT INTO frames (session_id, seq, frame_id, t_us, x0, y0, gaze_u, gaze_v, yaw, pitch,"
                   " events_used, rows, cols, bits) VALUES ('clash', 5, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, x'00')")
    spool = tmp_path / "spool"
    edge = subprocess.Popen(edge_command(recording, port, spool, "clash", tiny_model(tmp_path / "tiny.onnx")),
                            env=edge_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    def failures() -> float:
        request = urllib.request.Request(f"http://127.0.0.1:{port}/metrics/", headers={"X-API-Key": API_KEY})
        with urllib.request.urlopen(request, timeout=5) as response:
            for line in response.read().decode().splitlines():
                if line.startswith('darkread_ws_store_failures_total{error="IntegrityError"}'):
                    return float(line.split()[-1])
        return 0.0

    try:
        deadline = time.monotonic() + 60
        while failures() < 2 and time.monotonic() < deadline:  # the edge came back and hit it again
            time.sleep(0.1)
        seen = failures()
        with sqlite3.connect(database) as db:
            db.execute("DELETE FROM frames WHERE session_id = 'clash' AND seq = 5")
        _, stderr = edge.communicate(timeout=120)
        stored = cloud.stored_seqs("clash")
    finally:
        if edge.poll() is None:
            edge.kill()
            edge.communicate()
        cloud.stop()
    made, pending = spool_counts(spool)
    assert seen >= 2, "the store failure was not counted"
    assert edge.returncode == 0, stderr[-2000:]
    assert stored == list(range(made)) and pending == 0  # every frame once, none lost behind the failure
    closes = stderr.count("1011")
    print(f"store failure: {int(seen)} failed stores (IntegrityError, close 1011 each; {closes} seen by the edge), "
          f"the edge resumed: made {made}, stored {len(stored)}, 0 lost")
