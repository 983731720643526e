"""What a caller may cost a real cloud (``darkread cloud serve`` in its own process, its RSS read
from /proc): an anonymous 200 MB body, and ten long answers spoken at once while another caller
reads a session.

The pages are read by the OpenAI-compatible engine against a loopback server speaking its exact
shapes, which transcribes each as a 3,000-word text; espeak-ng is real.
"""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from cloud_process import API_KEY, CloudProcess
from speech_measure import require_espeak

from darkread.cloud.auth import KeyRing, Scope
from darkread.cloud.server import serve_in_thread
from tests.cloud.test_ocr_remote import OPENAI_KEY, openai_app
from tests.cloud.test_request_guard import raw_request
from tests.cloud.test_speech_bounds import long_text, stream_page

pytestmark = [pytest.mark.slow]
ANONYMOUS_BODY = 200 * 1024 * 1024
WEARERS = 10
PARTS_EACH = 3


def test_an_anonymous_200_mb_body_costs_nothing(tmp_path: Path) -> None:
    cloud = CloudProcess(tmp_path / "data", log_path=tmp_path / "cloud.log")
    cloud.start(60)
    try:
        cloud.wait_warm(120)  # the OCR models' load is not the body's cost
        warm = {"Host": f"127.0.0.1:{cloud.port}", "Content-Type": "application/json"}
        assert raw_request(cloud.port, "POST", "/v1/sessions/x/ask", warm, 100)[0] == 401  # code paths loaded once
        before = cloud.settled_memory_mb()
        status, headers, elapsed, sent = raw_request(
            cloud.port, "POST", "/v1/sessions/x/ask", {"Host": f"127.0.0.1:{cloud.port}", "Content-Type": "application/json"},
            ANONYMOUS_BODY,
        )  # fmt: skip
        time.sleep(0.5)
        after, peak = cloud.memory_mb()
    finally:
        cloud.stop()
    print(f"anonymous 200 MB body: {status} after {elapsed * 1000:.0f} ms ({sent >> 10} kB sent); cloud RSS "
          f"{before:.1f} -> {after:.1f} MB (peak {peak:.1f} MB)")
    assert status == 401 and elapsed < 1.0 and sent < ANONYMOUS_BODY // 20
    assert after - before < 10


def test_ten_long_spoken_answers_bound_memory_and_keep_reads_fast(tmp_path: Path) -> None:
    require_espeak()
    state: dict[str, Any] = {"scenario": "text", "calls": 0, "token_param": "max_completion_tokens", "text": long_text(3000)}
    keys = KeyRing(tmp_path / "data" / "keys.json")
    readers = [keys.add(f"d{i}", [Scope.READ]) for i in range(WEARERS)]
    with serve_in_thread(openai_app(state)) as reader_api:
        cloud = CloudProcess(tmp_path / "data", log_path=tmp_path / "cloud.log", env={
            "DARKREAD_OCR_BACKEND": "openai", "DARKREAD_OPENAI_BASE_URL": reader_api.url + "/v1",
            "DARKREAD_OPENAI_API_KEY": OPENAI_KEY, "DARKREAD_OPENAI_MODEL": "vlm-1",
            "DARKREAD_OPENAI_MAX_OUTPUT_TOKENS": "256", "DARKREAD_ASK_RATE_PER_MIN": "6000", "DARKREAD_ASK_BURST": "100",
        })  # fmt: skip
        cloud.start(60)
        peak_rss = 0.0
        sampling = True

        def sample() -> None:
            nonlocal peak_rss
            while sampling:
                peak_rss = max(peak_rss, cloud.memory_mb()[0])
                time.sleep(0.05)

        try:
            async def scenario() -> tuple[list[httpx.Response], list[float], float]:
                await stream_page(cloud.ws_url, "other", "someone", key=API_KEY)
                for i in range(WEARERS):
                    await stream_page(cloud.ws_url, f"s{i}", f"d{i}", key=API_KEY)
                async with httpx.AsyncClient(base_url=cloud.url, timeout=300) as http:
                    for i, key in enumerate(readers):  # each page read once: what follows is speech
                        assert (await http.post(f"/v1/sessions/s{i}/ask", headers={"X-API-Key": key})).status_code == 200
                    before = cloud.memory_mb()[0]
                    speaking = [asyncio.ensure_future(http.post(f"/v1/sessions/s{i}/ask", params={"format": "wav", "part": p},
                                                                headers={"X-API-Key": key}))
                                for i, key in enumerate(readers) for p in range(PARTS_EACH)]  # fmt: skip
                    latencies = []
                    while not all(task.done() for task in speaking):
                        started = time.perf_counter()
                        assert (await http.get("/v1/sessions/other", headers={"X-API-Key": API_KEY})).status_code == 200
                        latencies.append(time.perf_counter() - started)
                        await asyncio.sleep(0.02)
                    return [task.result() for task in speaking], latencies, before

            watcher = threading.Thread(target=sample, daemon=True)
            watcher.start()
            spoken, latencies, before = asyncio.run(scenario())
        finally:
            sampling = False
            _, high_water = cloud.memory_mb()
            cloud.stop()
    codes = [r.status_code for r in spoken]
    made = [r for r in spoken if r.status_code == 200]
    audio_s = sum(float(r.headers["x-speech-seconds"]) for r in made)
    p99 = float(np.percentile(latencies, 99)) * 1000
    print(f"{WEARERS} keys x {PARTS_EACH} parts of a 3,000-word answer at once: {len(made)} spoken ({audio_s:.0f} s of "
          f"audio, {sum(len(r.content) for r in made) >> 20} MB), {codes.count(429)} refused (2 per key at once); cloud "
          f"RSS {before:.0f} MB before, peak {max(peak_rss, 0):.0f} MB sampled, high-water {high_water:.0f} MB; "
          f"GET /v1/sessions/OTHER p99 {p99:.0f} ms (max {max(latencies) * 1000:.0f} ms, {len(latencies)} reads)")
    assert set(codes) <= {200, 429} and len(made) >= 2 * WEARERS
    assert all(r.headers["x-speech-parts"] == made[0].headers["x-speech-parts"] for r in made)
    assert high_water < 300
    assert len(latencies) >= 10 and p99 < 200
