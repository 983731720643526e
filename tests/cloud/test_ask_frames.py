"""End to end in the cloud: frames over the websocket -> stitched page -> rapidocr -> answer."""

from __future__ import annotations

import asyncio
from typing import Any

import cv2
import httpx
import numpy as np
from page_readings import LINES, reading_frames
from websockets.asyncio.client import connect

from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.proto.messages import Ack, Hello, Welcome, decode, encode

API_KEY = "test-key-7f3a"


def test_streamed_frames_are_stitched_and_read(make_settings: Any, run_server: Any) -> None:
    frames = reading_frames()
    with run_server(make_settings(), ocr=RapidOcrBackend()) as server:

        async def stream() -> None:
            async with connect(server.ws_url, additional_headers={"X-API-Key": API_KEY}) as ws:
                await ws.send(encode(Hello(device_id="g", session_id="reader", mode="frames", sensor=(1280, 720), fovea=(100, 200))))
                assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)
                for message in frames:
                    await ws.send(encode(message))
                acks = [decode(await ws.recv(), max_bytes=1 << 20) for _ in frames]
                assert acks[-1] == Ack(seq=len(frames) - 1)

        asyncio.run(stream())
        with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=30) as http:
            answer = http.post("/v1/sessions/reader/ask", json={"question": "what does this say"}).json()
            png = http.get("/v1/sessions/reader/page.png")
    assert answer["backend"] == "rapidocr"
    assert answer["page"] == 0 and 0 < answer["version"] <= len(frames)  # one page, every frame stitched once
    assert answer["page_id"] == f"stitched-0-v{answer['version']}" and answer["lines_read"] == len(LINES)
    assert answer["text"].split("\n") == LINES
    assert [line["text"] for line in answer["lines"]] == LINES
    page = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    ink_rows = np.flatnonzero((page == 0).any(axis=1))
    assert page.shape[1] >= 250 and ink_rows.size > 0 and ink_rows[-1] - ink_rows[0] >= 60  # three lines tall
