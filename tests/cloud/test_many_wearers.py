"""Several wearers stream into one real uvicorn at the glasses' pace and ask while they read:
every frame is stored exactly once and every question is answered from the wearer's own page.
(The 20-wearer figures with the real OCR engine are in ``make bench``: ``lab/bench/ask.py``.)"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import httpx
from page_readings import reading_frames
from websockets.asyncio.client import connect

from darkread.proto.messages import Ack, Hello, Welcome, decode, encode

API_KEY = "test-key-7f3a"
AUTH = {"X-API-Key": API_KEY}
WEARERS = 5


async def wearer(server: Any, index: int) -> tuple[list[int], list[dict[str, Any]]]:
    frames = reading_frames(seed=index)
    session_id = f"wearer-{index}"
    statuses: list[int] = []
    answers: list[dict[str, Any]] = []
    done = asyncio.Event()

    async def ask_while_reading(http: httpx.AsyncClient) -> None:
        while not done.is_set():
            await asyncio.sleep(0.3)
            response = await http.post(f"/v1/sessions/{session_id}/ask")
            statuses.append(response.status_code)
            if response.status_code == 200:
                answers.append(response.json())

    async with httpx.AsyncClient(base_url=server.url, headers=AUTH, timeout=60) as http:
        async with connect(server.ws_url, additional_headers=AUTH) as ws:
            await ws.send(encode(Hello(device_id=f"g{index}", session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))))
            assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)
            asker = asyncio.create_task(ask_while_reading(http))
            started = time.perf_counter()
            for frame in frames:  # at the pace the glasses took them (40 ms apart)
                await asyncio.sleep(max(0.0, frame.t_us / 1e6 - (time.perf_counter() - started)))
                await ws.send(encode(frame))
            acks = [decode(await ws.recv(), max_bytes=1 << 20) for _ in frames]
            assert acks[-1] == Ack(seq=len(frames) - 1)
            done.set()
            await asker
        final = await http.post(f"/v1/sessions/{session_id}/ask")
        assert final.status_code == 200
        answers.append(final.json())
    return statuses, answers


def test_wearers_streaming_together_each_get_their_own_page(server: Any) -> None:
    async def everyone() -> list[tuple[list[int], list[dict[str, Any]]]]:
        return await asyncio.gather(*(wearer(server, i) for i in range(WEARERS)))

    results = asyncio.run(everyone())
    for index, (statuses, answers) in enumerate(results):
        stored = asyncio.run(server.context.store.frames(f"wearer-{index}"))
        assert [f.seq for f in stored] == list(range(len(reading_frames(seed=index))))  # each frame exactly once
        assert set(statuses) <= {200, 409}, statuses  # 409 only before the first frame was stitched
        versions = [a["version"] for a in answers]
        assert versions == sorted(versions) and {a["page"] for a in answers} == {0}
        assert answers[-1]["version"] > 0 and answers[-1]["text"]
