"""End to end in the cloud: frames over the websocket -> stitched page -> rapidocr -> answer."""

from __future__ import annotations

import asyncio
from typing import Any

import cv2
import httpx
import numpy as np
from PIL import Image, ImageDraw, ImageFont
from websockets.asyncio.client import connect

from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.proto.messages import Ack, Frame, Hello, Welcome, decode, encode, pack_mask

API_KEY = "test-key-7f3a"
LINES = ["the quick brown fox jumps over", "the lazy dog while reading in", "the dark with an event camera"]
PAGE_IN_SENSOR = (300, 200)  # page top-left in sensor pixels (x, y)


def render_page(lines: list[str], x_height_px: int = 10) -> tuple[np.ndarray, list[tuple[int, int, float]]]:
    """Ink mask of the lines, and each line's (x start, x end, y of the x-height centre)."""
    size = 8
    font = ImageFont.load_default(size=size)
    while font.getbbox("x")[3] - font.getbbox("x")[1] < x_height_px:
        size += 1
        font = ImageFont.load_default(size=size)
    pitch = int(x_height_px * 3.2)
    width = max(font.getbbox(line)[2] for line in lines) + 80
    image = Image.new("L", (width, pitch * len(lines) + 80), 255)
    draw = ImageDraw.Draw(image)
    centres = []
    for i, line in enumerate(lines):
        y = 40 + i * pitch
        draw.text((40, y), line, font=font, fill=0)
        box = font.getbbox(line)
        centres.append((40, 40 + box[2], y + (box[1] + box[3]) / 2))
    return (np.asarray(image) < 128).astype(np.uint8), centres


def reading_frames(seed: int = 0) -> list[Frame]:
    """A reader's gaze walks each line in ~45 px steps (two frames per fixation, 3 px gaze noise);
    each frame is the 100 x 200 window around the gaze, cut from the sensor image of the page."""
    page, centres = render_page(LINES)
    sensor = np.zeros((720, 1280), np.uint8)
    sx, sy = PAGE_IN_SENSOR
    sensor[sy : sy + page.shape[0], sx : sx + page.shape[1]] = page
    rng = np.random.default_rng(seed)
    frames: list[Frame] = []
    for x_start, x_end, y_centre in centres:
        for gaze_x in np.arange(x_start + 20, x_end, 45):
            for _ in range(2):
                u, v = sx + gaze_x + rng.normal(0, 3), sy + y_centre + rng.normal(0, 3)
                x0, y0 = int(round(u)) - 100, int(round(v)) - 50
                shape, bits = pack_mask(sensor[y0 : y0 + 100, x0 : x0 + 200])
                seq = len(frames)
                frames.append(Frame(seq, seq, 40_000 * seq, (x0, y0), (float(u), float(v)), (0.0, 0.0), 1600, shape, bits))
    return frames


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
    assert answer["page_id"] == f"frames-0-{len(frames) - 1}"
    assert answer["text"].split("\n") == LINES
    assert [line["text"] for line in answer["lines"]] == LINES
    page = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    ink_rows = np.flatnonzero((page == 0).any(axis=1))
    assert page.shape[1] >= 250 and ink_rows.size > 0 and ink_rows[-1] - ink_rows[0] >= 60  # three lines tall
