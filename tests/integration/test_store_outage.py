"""A store outage answers fast with its reason: PostgreSQL stopped under a real uvicorn.

Reads (`GET /v1/sessions/{id}`, `ask`) answer 503 with one line and `Retry-After` within the
store timeout (a few seconds, not psycopg's default 30 s pool wait), `/readyz` answers 503 within
its probe's timeout, and the service serves again once the database is back.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest

from darkread.cloud.app import create_app
from darkread.cloud.server import serve_in_thread
from darkread.cloud.settings import Settings
from darkread.lab.fixtures.pg_server import PostgresUnavailable, TemporaryPostgres

pytestmark = [pytest.mark.postgres]
KEY = "outage-test-key-0123456789"


def timed(call: Callable[[], httpx.Response]) -> tuple[httpx.Response, float]:
    started = time.monotonic()
    response = call()
    return response, time.monotonic() - started


def test_a_stopped_database_is_a_fast_503_with_its_reason(tmp_path: Path) -> None:
    pg = TemporaryPostgres()
    try:
        pg.start()
    except (PostgresUnavailable, OSError) as exc:
        pytest.skip(f"PostgreSQL server could not be started: {exc}")
    try:
        url = pg.create_database("outage")
        settings = Settings(_env_file=None, data_dir=tmp_path / "data", api_key=KEY, database_url=url,
                            ask_rate_per_min=6000.0, ask_burst=100)  # fmt: skip
        with serve_in_thread(create_app(settings)) as running, \
                httpx.Client(base_url=running.url, headers={"X-API-Key": KEY}, timeout=60) as http:  # fmt: skip
            assert http.get("/v1/sessions/nobody").status_code == 404
            pg.halt()
            session, session_s = timed(lambda: http.get("/v1/sessions/nobody"))
            ask, ask_s = timed(lambda: http.post("/v1/sessions/nobody/ask"))
            ready, ready_s = timed(lambda: http.get("/readyz"))
            print(f"PostgreSQL stopped: GET session {session.status_code} in {session_s:.2f} s, ask {ask.status_code} "
                  f"in {ask_s:.2f} s, /readyz {ready.status_code} in {ready_s:.2f} s; {session.json()['detail']!r}")
            for response in (session, ask):
                assert response.status_code == 503 and response.headers["retry-after"].isdigit()
                detail = response.json()["detail"]
                assert "\n" not in detail and detail.startswith("the session store is unavailable")
            assert session_s < 5.0 and ask_s < 5.0
            assert ready.status_code == 503 and ready.json()["checks"]["store"] is False
            assert ready_s < settings.ready_timeout_s + 0.5
            pg.resume()
            deadline = time.monotonic() + 30
            while (back := http.get("/v1/sessions/nobody")).status_code == 503 and time.monotonic() < deadline:
                time.sleep(0.2)
            assert back.status_code == 404
    finally:
        pg.stop()
