"""Bounded cost per ask: concurrent asks share one reading, a time limit answers 503, a rate limit 429."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np

from darkread.cloud.ocr.base import OcrResult

from .conftest import RecordingOcr
from .test_routes import AUTH, page_mask, send_page


@dataclass
class SlowOcr(RecordingOcr):
    seconds: float = 0.6
    calls: list[float] = field(default_factory=list)

    def read(self, image: np.ndarray) -> OcrResult:
        self.calls.append(time.monotonic())
        time.sleep(self.seconds)
        return super().read(image)


async def concurrent_asks(url: str, n: int) -> list[httpx.Response]:
    async with httpx.AsyncClient(base_url=url, timeout=30) as http:
        return list(await asyncio.gather(*(http.post("/v1/sessions/s/ask", headers=AUTH) for _ in range(n))))


def test_concurrent_asks_share_one_reading(make_settings: Any, run_server: Any) -> None:
    ocr = SlowOcr()
    with run_server(make_settings(), ocr) as live:
        send_page(live, "s", page_mask())
        answers = asyncio.run(concurrent_asks(live.url, 3))
    assert [a.status_code for a in answers] == [200, 200, 200]
    assert len({a.json()["text"] for a in answers}) == 1
    assert len(ocr.calls) == 1  # one reading for the three


def test_an_ask_over_its_time_limit_is_a_clear_503(make_settings: Any, run_server: Any) -> None:
    ocr = SlowOcr(seconds=1.5)
    with run_server(make_settings(ask_timeout_s=0.3), ocr) as live, httpx.Client(base_url=live.url, timeout=30) as http:
        send_page(live, "s", page_mask())
        started = time.monotonic()
        slow = http.post("/v1/sessions/s/ask", headers=AUTH)
        assert time.monotonic() - started < 1.2
        assert slow.status_code == 503 and "0.3 s" in slow.json()["detail"] and slow.headers["retry-after"]
        time.sleep(1.4)  # the reading went on and is kept for the next ask of the same page
        assert http.post("/v1/sessions/s/ask", headers=AUTH).status_code == 200
        assert len(ocr.calls) == 1


def test_asks_are_rate_limited_per_key(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(ask_rate_per_min=6, ask_burst=2)) as live, httpx.Client(base_url=live.url) as http:
        send_page(live, "s", page_mask())
        codes = [http.post("/v1/sessions/s/ask", headers=AUTH).status_code for _ in range(3)]
        assert codes == [200, 200, 429]
        limited = http.get("/v1/sessions/s/page.png", headers=AUTH)
        assert limited.status_code == 429 and 1 <= int(limited.headers["retry-after"]) <= 10
