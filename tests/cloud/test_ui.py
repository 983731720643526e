"""The live page's server side through a real uvicorn: shells, the session-list fragment, static files.

The browser side (keyboard, live region, Ask, Speak, accessibility) is tested in a real Chromium
in tests/integration/test_live_page.py.
"""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
from websockets.asyncio.client import connect

from darkread.cloud.auth import KeyRing, Scope
from darkread.proto.messages import Hello, Welcome, decode, encode

API_KEY = "test-key-7f3a"


def open_session(ws_url: str, session_id: str, device_id: str = "glasses-1", key: str = API_KEY) -> None:
    """A session as the glasses open it: hello over the websocket, welcome back."""

    async def hello() -> None:
        async with connect(ws_url, additional_headers={"X-API-Key": key}) as ws:
            await ws.send(encode(Hello(device_id=device_id, session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))))
            assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)

    asyncio.run(hello())


def test_the_page_shells_need_no_key_and_hold_no_data(server: Any) -> None:
    index = httpx.get(f"{server.url}/")
    session = httpx.get(f"{server.url}/sessions/reader-7")
    assert index.status_code == session.status_code == 200
    for page in (index, session):
        assert page.headers["content-type"].startswith("text/html")
        assert '<meta name="viewport" content="width=device-width, initial-scale=1">' in page.text
        assert '<html lang="en">' in page.text and 'id="main"' in page.text
        policy = page.headers["content-security-policy"]
        assert "script-src 'self'" in policy and "form-action 'none'" in policy and "frame-ancestors 'none'" in policy
        assert page.headers["referrer-policy"] == "no-referrer"
    assert 'data-session="reader-7"' in session.text and 'aria-live="polite"' in session.text
    assert httpx.get(f"{server.url}/sessions/..%2Fetc").status_code in (404, 422)


def test_the_login_form_cannot_send_the_key(server: Any) -> None:
    """The key input has no name (a form without script submits nothing) and forms may not submit at all."""
    page = httpx.get(f"{server.url}/").text
    form = page[page.index('<form id="login"'):page.index("</form>")]
    key_input = form[form.index('<input id="key"'):]
    assert "name=" not in key_input.split(">")[0] and 'type="password"' in key_input
    assert "method=" not in form and "action=" not in form


def test_the_session_list_needs_the_key(server: Any) -> None:
    open_session(server.ws_url, "reader-7")
    denied = httpx.get(f"{server.url}/ui/sessions")
    wrong = httpx.get(f"{server.url}/ui/sessions", headers={"X-API-Key": "nope"})
    listed = httpx.get(f"{server.url}/ui/sessions", headers={"X-API-Key": API_KEY})
    assert denied.status_code == wrong.status_code == 401
    assert listed.status_code == 200
    assert 'href="/sessions/reader-7"' in listed.text and "glasses-1" in listed.text and "0 frames" in listed.text


def test_the_session_list_shows_a_device_key_only_its_own_sessions(make_settings: Any, run_server: Any) -> None:
    settings = make_settings()
    ring = KeyRing(settings.keys_path())
    glasses = {name: ring.add(name, {Scope.STREAM, Scope.READ}) for name in ("glasses-1", "glasses-2")}
    stream_only = ring.add("glasses-1", {Scope.STREAM})
    with run_server(settings) as live:
        for name, key in glasses.items():
            open_session(live.ws_url, f"s-{name}", name, key)
        mine = httpx.get(f"{live.url}/ui/sessions", headers={"X-API-Key": glasses["glasses-1"]}).text
        everyone = httpx.get(f"{live.url}/ui/sessions", headers={"X-API-Key": API_KEY}).text
        refused = httpx.get(f"{live.url}/ui/sessions", headers={"X-API-Key": stream_only})
    assert "s-glasses-1" in mine and "s-glasses-2" not in mine
    assert "s-glasses-1" in everyone and "s-glasses-2" in everyone
    assert refused.status_code == 403


def test_the_session_list_says_when_it_is_empty(server: Any) -> None:
    empty = httpx.get(f"{server.url}/ui/sessions", headers={"X-API-Key": API_KEY}).text
    assert "No sessions yet" in empty and "<ul" not in empty


def test_static_files_are_served(server: Any) -> None:
    script = httpx.get(f"{server.url}/ui/static/app.js")
    styles = httpx.get(f"{server.url}/ui/static/app.css")
    assert script.status_code == styles.status_code == 200
    assert "javascript" in script.headers["content-type"] and styles.headers["content-type"].startswith("text/css")
    assert "X-API-Key" in script.text
