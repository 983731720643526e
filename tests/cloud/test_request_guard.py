"""Every request costs what its caller may spend: the key before the body, bodies bounded per route,
loopback names only without a key, no foreign Origin, nosniff on every answer, event streams per key.

Requests go over raw sockets to a real uvicorn on 127.0.0.1, so the Host and Origin headers and an
announced body size are exactly what an attacker would send.
"""

from __future__ import annotations

import asyncio
import base64
import os
import select
import socket
import subprocess
import sys
import time
from typing import Any
from urllib.parse import urlsplit

import httpx
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus
from websockets.typing import Origin

from darkread.proto.messages import Welcome, decode, encode

from .test_stream import API_KEY, LIMIT, hello
from .test_stream_ownership import open_ws, send_acked

LiveServer = Any
BIG = 64 * 1024 * 1024  # an announced body far beyond any route's limit


def port_of(server: LiveServer) -> int:
    return int(urlsplit(server.url).port or 0)


def raw_request(port: int, method: str, path: str, headers: dict[str, str], body_bytes: int = 0,
                chunked: bool = False) -> tuple[int, dict[str, str], float, int]:  # fmt: skip
    """Send a request (announcing ``body_bytes``, sent until the server answers); the status, the
    headers, seconds to the answer and the body bytes sent before it."""
    lines = [f"{method} {path} HTTP/1.1", *(f"{name}: {value}" for name, value in headers.items())]
    if chunked:
        lines.append("Transfer-Encoding: chunked")
    elif body_bytes:
        lines.append(f"Content-Length: {body_bytes}")
    started = time.monotonic()
    sent = 0
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        piece = b"[" * 65536
        sock.setblocking(False)
        while sent < body_bytes and not select.select([sock], [], [], 0)[0]:
            chunk = piece[: body_bytes - sent]
            data = b"%x\r\n%s\r\n" % (len(chunk), chunk) if chunked else chunk
            try:
                select.select([], [sock], [], 0.05)
                sent += sock.send(data) if not chunked else (sock.sendall(data) or len(chunk))
            except (BlockingIOError, InterruptedError):
                continue
            except (BrokenPipeError, ConnectionResetError):
                break
        sock.setblocking(True)
        answer = b""
        while b"\r\n\r\n" not in answer:
            try:
                more = sock.recv(65536)
            except ConnectionResetError:
                break
            if not more:
                break
            answer += more
    elapsed = time.monotonic() - started
    head = answer.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")
    status = int(head[0].split()[1]) if head and head[0] else 0
    fields = {name.strip().lower(): value.strip() for name, _, value in (line.partition(":") for line in head[1:])}
    return status, fields, elapsed, sent


def ws_upgrade(port: int, headers: dict[str, str]) -> int:
    """The status of a websocket handshake on /v1/stream (101: accepted)."""
    key = base64.b64encode(os.urandom(16)).decode()
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Key": key, "Sec-WebSocket-Version": "13"}
    return raw_request(port, "GET", "/v1/stream", {**upgrade, **headers})[0]


# -- item 1: the key before the body; bodies bounded per route ---------------------------------------


def test_an_anonymous_body_is_refused_before_it_is_read(server: LiveServer) -> None:
    port = port_of(server)
    status, headers, elapsed, sent = raw_request(
        port, "POST", "/v1/sessions/x/ask", {"Host": f"127.0.0.1:{port}", "Content-Type": "application/json"}, BIG
    )
    print(f"anonymous {BIG >> 20} MB body: {status} after {elapsed * 1000:.0f} ms, {sent >> 10} kB sent")
    assert status == 401 and headers.get("connection") == "close"
    assert sent < BIG // 8 and elapsed < 2.0


def test_a_body_over_the_route_limit_is_413_at_once(server: LiveServer) -> None:
    port = port_of(server)
    keyed = {"Host": f"127.0.0.1:{port}", "X-API-Key": API_KEY, "Content-Type": "application/json"}
    status, headers, elapsed, sent = raw_request(port, "POST", "/v1/sessions/x/ask", keyed, BIG)
    assert status == 413 and headers.get("connection") == "close" and sent < BIG // 8 and elapsed < 2.0
    chunked = raw_request(port, "POST", "/v1/sessions/x/ask", keyed, BIG, chunked=True)
    assert chunked[0] == 413 and chunked[3] < BIG // 8
    assert raw_request(port, "GET", "/v1/sessions", keyed, 8192)[0] == 413  # a route that takes no body
    # a question of the largest allowed size still passes (404: the session is unknown)
    with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}) as http:
        assert http.post("/v1/sessions/x/ask", json={"question": "é" * 2000}).status_code == 404
        assert http.post("/v1/sessions/x/ask", json={"question": "q" * 2001}).status_code == 422


# -- item 4: Host and Origin -----------------------------------------------------------------------


def host_origin_table(port: int) -> list[tuple[str, int]]:
    cases: list[tuple[str, str, str, dict[str, str]]] = [
        ("GET /v1/sessions Host 127.0.0.1", "GET", "/v1/sessions", {"Host": f"127.0.0.1:{port}"}),
        ("GET /v1/sessions Host localhost", "GET", "/v1/sessions", {"Host": f"localhost:{port}"}),
        ("GET /v1/sessions Host [::1]", "GET", "/v1/sessions", {"Host": f"[::1]:{port}"}),
        ("GET /v1/sessions Host evil.example", "GET", "/v1/sessions", {"Host": "evil.example:8106"}),
        ("DELETE /v1/sessions/s Host evil.example", "DELETE", "/v1/sessions/s", {"Host": "evil.example:8106"}),
        ("GET / Host evil.example", "GET", "/", {"Host": "evil.example:8106"}),
        ("POST ask Origin http://evil.example", "POST", "/v1/sessions/s/ask",
         {"Host": f"127.0.0.1:{port}", "Origin": "http://evil.example"}),
        ("POST ask Origin null", "POST", "/v1/sessions/s/ask", {"Host": f"127.0.0.1:{port}", "Origin": "null"}),
        ("POST ask Origin same", "POST", "/v1/sessions/s/ask",
         {"Host": f"127.0.0.1:{port}", "Origin": f"http://127.0.0.1:{port}"}),
    ]  # fmt: skip
    table = [(name, raw_request(port, method, path, headers)[0]) for name, method, path, headers in cases]
    table += [
        ("WS /v1/stream Origin http://evil.example", ws_upgrade(port, {"Host": f"127.0.0.1:{port}", "Origin": "http://evil.example"})),
        ("WS /v1/stream Host evil.example", ws_upgrade(port, {"Host": "evil.example:8106"})),
        ("WS /v1/stream Origin http://localhost", ws_upgrade(port, {"Host": f"127.0.0.1:{port}", "Origin": f"http://localhost:{port}"})),
    ]  # fmt: skip
    return table


def test_without_a_key_only_loopback_names_and_origins(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(api_key=None)) as server:
        port = port_of(server)
        table = host_origin_table(port)

        async def evil_websocket() -> str:
            try:
                async with connect(server.ws_url, origin=Origin("http://evil.example"), max_size=None) as ws:
                    await ws.send(encode(hello("planted")))
                    return type(decode(await ws.recv(), max_bytes=LIMIT)).__name__
            except InvalidStatus as exc:
                return f"refused {exc.response.status_code}"

        evil = asyncio.run(evil_websocket())
        sessions = httpx.get(f"{server.url}/v1/sessions").json()
    for name, status in table:
        print(f"no key | {name:<45} | {status}")
    expected = {"Host 127.0.0.1": 200, "Host localhost": 200, "Host [::1]": 200}
    for name, status in table:
        if name.startswith("GET /v1/sessions Host") and name.split(" ", 2)[2] in expected:
            assert status == expected[name.split(" ", 2)[2]], name
        elif "evil" in name or "null" in name:
            assert status == 403, name
    assert dict(table)["POST ask Origin same"] == 404  # allowed: the session is unknown
    assert dict(table)["WS /v1/stream Origin http://localhost"] == 101
    assert evil == "refused 403" and sessions == []


def test_with_keys_origins_come_from_the_allow_list(make_settings: Any, run_server: Any) -> None:
    allowed = "https://reader.example.org"
    with run_server(make_settings(allowed_origins=[allowed])) as server:
        port = port_of(server)
        keyed = {"Host": "cloud.example.org", "X-API-Key": API_KEY}
        table = [
            ("GET /v1/sessions Host cloud.example.org", raw_request(port, "GET", "/v1/sessions", keyed)[0]),
            ("GET /v1/sessions Origin allowed", raw_request(port, "GET", "/v1/sessions", {**keyed, "Origin": allowed})[0]),
            ("GET /v1/sessions Origin same", raw_request(port, "GET", "/v1/sessions", {**keyed, "Origin": "https://cloud.example.org"})[0]),
            ("GET /v1/sessions Origin evil", raw_request(port, "GET", "/v1/sessions", {**keyed, "Origin": "http://evil.example"})[0]),
            ("WS /v1/stream Origin evil", ws_upgrade(port, {**keyed, "Origin": "http://evil.example"})),
            ("WS /v1/stream Origin allowed", ws_upgrade(port, {**keyed, "Origin": allowed})),
        ]  # fmt: skip
    for name, status in table:
        print(f"keys   | {name:<45} | {status}")
    assert [status for _, status in table] == [200, 200, 200, 403, 403, 101]


def test_a_short_key_is_refused_beyond_loopback(tmp_path: Any) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DARKREAD_")}
    serve = [sys.executable, "-m", "darkread", "cloud", "serve", "--port", "9", "--data-dir", str(tmp_path / "d")]
    public = subprocess.run([*serve, "--host", "0.0.0.0"], capture_output=True, text=True, timeout=30,
                            env={**env, "DARKREAD_API_KEY": "short-key"})  # fmt: skip
    assert public.returncode == 2, public.stderr
    lines = public.stderr.strip().splitlines()
    assert len(lines) == 1 and "at least 16 characters" in lines[0] and "short-key" not in lines[0]


# -- item 8: nosniff everywhere, event streams per key -------------------------------------------------


def test_every_answer_says_nosniff(server: LiveServer) -> None:
    async def stream_one() -> None:
        ws, welcome = await open_ws(server, "sniff")
        assert isinstance(welcome, Welcome)
        assert await send_acked(ws, range(3)) == [0, 1, 2]
        await ws.close()

    asyncio.run(stream_one())
    with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=60) as http:
        answers = {
            "json": http.get("/v1/sessions"),
            "401": httpx.get(f"{server.url}/v1/sessions"),
            "404": http.get("/v1/nothing-here"),
            "script": http.get("/ui/static/app.js"),
            "page.png": http.get("/v1/sessions/sniff/page.png"),
            "healthz": http.get("/healthz"),
            "metrics": http.get("/metrics/"),
        }
    for name, response in answers.items():
        assert response.headers.get("x-content-type-options") == "nosniff", (name, response.status_code)
    assert answers["page.png"].status_code == 200 and answers["script"].status_code == 200


def test_event_streams_are_capped_per_key(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(sse_per_key=2)) as server:
        async def scenario() -> list[int]:
            ws, _ = await open_ws(server, "watched")
            assert await send_acked(ws, range(2)) == [0, 1]
            async with httpx.AsyncClient(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=10) as http:
                streams = [http.stream("GET", "/v1/sessions/watched/events") for _ in range(2)]
                opened = [await s.__aenter__() for s in streams]
                third = await http.get("/v1/sessions/watched/events")
                codes = [r.status_code for r in opened] + [third.status_code]
                assert third.headers.get("retry-after") and "2 event streams" in third.json()["detail"]
                for s in streams:
                    await s.__aexit__(None, None, None)
                await asyncio.sleep(0.3)  # the server sees the streams close
                async with http.stream("GET", "/v1/sessions/watched/events") as again:
                    codes.append(again.status_code)
            await ws.close()
            return codes

        assert asyncio.run(scenario()) == [200, 200, 429, 200]
