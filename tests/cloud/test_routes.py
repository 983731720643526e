"""REST routes against a real uvicorn server: auth, 404s, ask, page.png, sessions, health, OpenAPI."""

from __future__ import annotations

import asyncio
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from websockets.asyncio.client import connect

from darkread.proto.messages import Ack, Hello, Page, Welcome, decode, encode, pack_mask

API_KEY = "test-key-7f3a"
AUTH = {"X-API-Key": API_KEY}


def page_mask() -> np.ndarray:
    mask = np.zeros((80, 120), np.uint8)
    mask[20:30, 10:110] = 1
    mask[50:60, 10:70] = 1
    return mask


def send_page(server: Any, session_id: str, mask: np.ndarray, page_id: int = 3) -> None:
    shape, bits = pack_mask(mask)

    async def scenario() -> None:
        async with connect(server.ws_url, additional_headers=AUTH) as ws:
            await ws.send(encode(Hello(device_id="g", session_id=session_id, mode="pages", sensor=(1280, 720), fovea=(100, 200))))
            assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)
            lines = ((10, 20, 110, 30), (10, 50, 70, 60))
            await ws.send(encode(Page(seq=0, page_id=page_id, t_us=1, shape=shape, bits=bits, lines=lines)))
            assert decode(await ws.recv(), max_bytes=1 << 20) == Ack(seq=0)

    asyncio.run(scenario())


@pytest.fixture
def client(server: Any) -> httpx.Client:
    with httpx.Client(base_url=server.url, timeout=10) as http:
        yield http


def test_health_needs_no_key(client: httpx.Client) -> None:
    assert client.get("/healthz").json() == {"status": "ok", "checks": {}}
    ready = client.get("/readyz")
    assert ready.status_code == 200 and ready.json()["checks"] == {"store": True, "ocr:recording": True}


@pytest.mark.parametrize(
    ("method", "path"),
    [("GET", "/v1/sessions"), ("POST", "/v1/sessions/s/ask"), ("GET", "/v1/sessions/s/page.png"), ("DELETE", "/v1/sessions/s")],
)
@pytest.mark.parametrize("headers", [{}, {"X-API-Key": "wrong"}])
def test_routes_need_the_key(client: httpx.Client, method: str, path: str, headers: dict[str, str]) -> None:
    response = client.request(method, path, headers=headers)
    assert response.status_code == 401
    assert "API key" in response.json()["detail"]


@pytest.mark.parametrize(
    ("method", "path"),
    [("GET", "/v1/sessions/nope"), ("POST", "/v1/sessions/nope/ask"), ("GET", "/v1/sessions/nope/page.png"), ("DELETE", "/v1/sessions/nope")],
)
def test_unknown_session_is_404(client: httpx.Client, method: str, path: str) -> None:
    response = client.request(method, path, headers=AUTH)
    assert response.status_code == 404
    assert "nope" in response.json()["detail"]


def test_invalid_session_id_is_rejected(client: httpx.Client) -> None:
    assert client.post("/v1/sessions/..%2Fetc/ask", headers=AUTH).status_code in (404, 422)


def test_ask_reads_the_latest_page(server: Any, client: httpx.Client) -> None:
    mask = page_mask()
    send_page(server, "sess-ask", mask)
    answer = client.post("/v1/sessions/sess-ask/ask", headers=AUTH).json()
    assert answer["backend"] == "recording" and answer["page_id"] == "page-3"
    assert answer["question"] == "what does this say"
    assert answer["text"] == f"80x120 ink={int(mask.sum())}" and answer["latency_ms"] >= 0
    assert answer["lines"] == [{"text": answer["text"], "box": [0, 0, 120, 80], "confidence": 1.0, "status": "read",
                               "reasons": [], "evidence": {}}]  # an engine without character scores: answered as read
    np.testing.assert_array_equal(server.ocr.images[-1], np.where(mask == 1, 0, 255))  # black on white
    asked = client.post("/v1/sessions/sess-ask/ask", headers=AUTH, json={"question": "read it"}).json()
    assert asked["question"] == "read it"


def test_key_in_query_works_for_rest(server: Any, client: httpx.Client) -> None:
    assert client.get("/v1/sessions", params={"key": API_KEY}).status_code == 200


def test_page_png_is_the_page(server: Any, client: httpx.Client) -> None:
    mask = page_mask()
    send_page(server, "sess-png", mask)
    response = client.get("/v1/sessions/sess-png/page.png", headers=AUTH)
    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    assert response.headers["x-page-id"] == "page-3"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    np.testing.assert_array_equal(image, np.where(mask == 1, 0, 255))


def test_session_without_data_answers_409(server: Any, client: httpx.Client) -> None:
    async def hello_only() -> None:
        async with connect(server.ws_url, additional_headers=AUTH) as ws:
            await ws.send(encode(Hello(device_id="g", session_id="empty", mode="frames", sensor=(1280, 720), fovea=(100, 200))))
            await ws.recv()

    asyncio.run(hello_only())
    assert client.post("/v1/sessions/empty/ask", headers=AUTH).status_code == 409
    assert client.get("/v1/sessions/empty/page.png", headers=AUTH).status_code == 409
    # a frames session's pages are the cloud's, listed by /pages: no count that could disagree with it
    assert client.get("/v1/sessions/empty", headers=AUTH).json()["pages"] is None


def test_list_and_delete_sessions(server: Any, client: httpx.Client) -> None:
    send_page(server, "sess-1", page_mask())
    send_page(server, "sess-2", page_mask())
    listed = client.get("/v1/sessions", headers=AUTH).json()
    assert {s["session_id"] for s in listed} == {"sess-1", "sess-2"}
    assert listed[0]["pages"] == 1 and listed[0]["last_seq"] == 0 and listed[0]["mode"] == "pages"
    assert client.delete("/v1/sessions/sess-1", headers=AUTH).status_code == 204
    assert [s["session_id"] for s in client.get("/v1/sessions", headers=AUTH).json()] == ["sess-2"]
    assert not (server.settings.data_dir / "pages" / "sess-1").exists()
    assert client.delete("/v1/sessions/sess-1", headers=AUTH).status_code == 404


def test_metrics_endpoint_exposes_stream_counters(server: Any, client: httpx.Client) -> None:
    send_page(server, "sess-metrics", page_mask())
    text = client.get("/metrics/", headers=AUTH).text  # an admin key
    assert "darkread_ws_connections_total 1.0" in text
    assert "darkread_ws_pages_stored_total 1.0" in text
    assert 'darkread_ws_messages_total{type="page"} 1.0' in text


def test_openapi_documents_every_route(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(api_docs=True)) as live, httpx.Client(base_url=live.url) as client:
        spec = client.get("/openapi.json").json()
    expected = {
        ("/healthz", "get"), ("/readyz", "get"), ("/v1/sessions", "get"), ("/v1/sessions/{session_id}", "get"),
        ("/v1/sessions/{session_id}", "delete"), ("/v1/sessions/{session_id}/page.png", "get"),
        ("/v1/sessions/{session_id}/ask", "post"),
    }  # fmt: skip
    documented = {(path, method) for path, item in spec["paths"].items() for method in item}
    assert expected <= documented
    for path, method in expected:
        operation = spec["paths"][path][method]
        assert operation["summary"], (path, method)
        assert any(code.startswith("2") for code in operation["responses"])
    ask = spec["paths"]["/v1/sessions/{session_id}/ask"]["post"]
    assert ask["responses"]["200"]["content"]["application/json"]["schema"]["$ref"].endswith("AskResponse")
