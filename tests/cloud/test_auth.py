"""Auth by default: per-device keys with scopes, loopback-only without a key, keys never logged."""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.asyncio.client import connect

from darkread.cloud.auth import KeyRing, Scope
from darkread.proto.errors import CloseCode
from darkread.proto.messages import Ack, Error, Frame, Hello, Welcome, decode, encode, pack_mask

ADMIN = "test-key-7f3a"  # the conftest server's DARKREAD_API_KEY: an admin key
LIMIT = 1 << 22


def darkread(*args: str, env: dict[str, str] | None = None, timeout: float = 20) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "darkread", *args], capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **(env or {})})


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def frame(seq: int) -> Frame:
    mask = np.zeros((100, 200), np.uint8)
    mask[40:50, 10:60] = 1
    shape, bits = pack_mask(mask)
    return Frame(seq, seq, 1000 * seq, (500, 300), (600.0, 350.0), (0.0, 0.0), 1600, shape, bits)


async def stream(url: str, key: str, session_id: str, device_id: str, n: int = 2) -> Any:
    """Hello then ``n`` frames; the acks, or the error the server closed with."""
    async with connect(url, additional_headers={"X-API-Key": key}, max_size=None) as ws:
        await ws.send(encode(Hello(device_id=device_id, session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))))
        reply = decode(await ws.recv(), max_bytes=LIMIT)
        if isinstance(reply, Error):
            return reply
        assert isinstance(reply, Welcome)
        for seq in range(n):
            await ws.send(encode(frame(seq)))
        return [decode(await ws.recv(), max_bytes=LIMIT) for _ in range(n)]


def test_keys_are_stored_hashed_and_printed_once(tmp_path: Path) -> None:
    run = darkread("cloud", "keys", "add", "--data-dir", str(tmp_path), "--device", "glasses-1", "--scope", "stream,read")
    assert run.returncode == 0, run.stderr
    key = run.stdout.strip()
    assert key.startswith("drk_") and len(key) > 30
    stored = (tmp_path / "keys.json").read_text()
    secret = key.split("_", 2)[2]  # drk_<id>_<secret>; the secret itself may hold "_"
    assert key not in stored and secret not in stored
    assert oct((tmp_path / "keys.json").stat().st_mode & 0o777) == "0o600"
    principal = KeyRing(tmp_path / "keys.json").authenticate(key)
    assert principal is not None and principal.device == "glasses-1"
    assert principal.scopes == frozenset({Scope.STREAM, Scope.READ})
    assert KeyRing(tmp_path / "keys.json").authenticate(key + "x") is None
    listed = darkread("cloud", "keys", "list", "--data-dir", str(tmp_path))
    assert "glasses-1" in listed.stdout and key not in listed.stdout
    bad = darkread("cloud", "keys", "add", "--data-dir", str(tmp_path), "--device", "g", "--scope", "everything")
    assert bad.returncode != 0 and "scope" in bad.stderr and "Traceback" not in bad.stderr


def test_device_keys_stream_and_read_only_their_own_sessions(make_settings: Any, run_server: Any, tmp_path: Path) -> None:
    settings = make_settings()
    ring = KeyRing(settings.keys_path())
    key1 = ring.add("glasses-1", {Scope.STREAM, Scope.READ})
    key2 = ring.add("glasses-2", {Scope.STREAM, Scope.READ})
    reader = ring.add("glasses-1", {Scope.READ})
    with run_server(settings) as live:
        assert asyncio.run(stream(live.ws_url, key1, "s1", "glasses-1")) == [Ack(seq=0), Ack(seq=1)]
        assert asyncio.run(stream(live.ws_url, key2, "s2", "glasses-2")) == [Ack(seq=0), Ack(seq=1)]
        # a key streams only as its own device, and only into that device's sessions
        spoofed = asyncio.run(stream(live.ws_url, key2, "s3", "glasses-1"))
        assert isinstance(spoofed, Error) and spoofed.code == CloseCode.FORBIDDEN
        hijack = asyncio.run(stream(live.ws_url, key2, "s1", "glasses-2"))
        assert isinstance(hijack, Error) and hijack.code == CloseCode.FORBIDDEN
        read_only = asyncio.run(stream(live.ws_url, reader, "s4", "glasses-1"))
        assert isinstance(read_only, Error) and read_only.code == CloseCode.FORBIDDEN
        with httpx.Client(base_url=live.url, timeout=10) as http:
            mine = http.get("/v1/sessions", headers={"X-API-Key": reader}).json()
            assert [s["session_id"] for s in mine] == ["s1"]
            assert http.get("/v1/sessions/s2", headers={"X-API-Key": reader}).status_code == 404
            assert http.get("/v1/sessions/s2/page.png", headers={"X-API-Key": key1}).status_code == 404
            assert http.delete("/v1/sessions/s1", headers={"X-API-Key": key1}).status_code == 403
            everyone = http.get("/v1/sessions", headers={"X-API-Key": ADMIN}).json()
            assert {s["session_id"] for s in everyone} == {"s1", "s2"}
            assert http.delete("/v1/sessions/s2", headers={"X-API-Key": ADMIN}).status_code == 204
            # /metrics needs an admin key, /docs is off unless configured
            assert http.get("/metrics/").status_code == 401
            assert http.get("/metrics/", headers={"X-API-Key": key1}).status_code == 403
            assert http.get("/metrics/", headers={"X-API-Key": ADMIN}).status_code == 200
            assert http.get("/docs").status_code == 404 and http.get("/openapi.json").status_code == 404


def test_docs_and_public_metrics_are_settings(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(api_docs=True, metrics_public=True)) as live, httpx.Client(base_url=live.url) as http:
        assert http.get("/docs").status_code == 200 and http.get("/openapi.json").status_code == 200
        assert http.get("/metrics/").status_code == 200


def test_without_a_key_only_loopback_clients_are_served(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(api_key=None)) as live, httpx.Client(base_url=live.url) as http:
        assert http.get("/v1/sessions").status_code == 200  # 127.0.0.1: a developer's own machine
        assert live.context.authenticate(None, client_host="192.0.2.7") is None
        assert live.context.authenticate(None, client_host="::1") is not None


def test_serve_on_a_public_address_without_a_key_refuses_to_start(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DARKREAD_")}
    started = time.monotonic()
    run = subprocess.run(
        [sys.executable, "-m", "darkread", "cloud", "serve", "--host", "0.0.0.0", "--port", str(free_port()),
         "--data-dir", str(tmp_path / "d")],
        capture_output=True, text=True, timeout=30, env=env,
    )
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr
    assert "DARKREAD_API_KEY" in lines[0] and "darkread cloud keys add" in lines[0] and "--insecure" in lines[0]
    assert time.monotonic() - started < 15


def test_empty_api_key_is_an_error_not_no_auth(tmp_path: Path) -> None:
    run = darkread("cloud", "serve", "--port", str(free_port()), "--data-dir", str(tmp_path / "d"), "--api-key", "")
    assert run.returncode == 2 and "empty" in run.stderr and "Traceback" not in run.stderr
    env_run = darkread("cloud", "serve", "--port", str(free_port()), "--data-dir", str(tmp_path / "d"),
                       env={"DARKREAD_API_KEY": ""})
    assert env_run.returncode == 2 and "DARKREAD_API_KEY" in env_run.stderr


def test_the_key_never_appears_in_the_log(tmp_path: Path) -> None:
    port, secret = free_port(), "s3cret-key-never-logged"
    process = subprocess.Popen(
        [sys.executable, "-m", "darkread", "-v", "cloud", "serve", "--port", str(port), "--data-dir", str(tmp_path / "d")],
        env={**os.environ, "DARKREAD_API_KEY": secret}, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1).close()
                break
            except OSError:
                assert process.poll() is None and time.monotonic() < deadline
                time.sleep(0.1)
        urllib.request.urlopen(f"http://127.0.0.1:{port}/v1/sessions?key={secret}", timeout=5).close()
        url = f"ws://127.0.0.1:{port}/v1/stream?key={secret}"
        assert asyncio.run(stream(url, secret, "logged", "glasses-1", n=1)) == [Ack(seq=0)]
        time.sleep(0.3)
    finally:
        process.terminate()
        output, _ = process.communicate(timeout=20)
    assert "/v1/stream" in output  # the connection is logged ...
    assert secret not in output  # ... but not its key
