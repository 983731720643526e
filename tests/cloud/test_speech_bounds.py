"""Spoken answers are bounded: a long answer is spoken in parts a client pages through, each part's
audio is capped, one key has at most a few syntheses at once, and speech never queues store reads.

The page is read by the OpenAI-compatible engine against a loopback server speaking its exact
shapes (``test_ocr_remote.openai_app``), which transcribes it as a long text; espeak-ng is real.
"""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import pytest
from speech_measure import require_espeak, samples
from websockets.asyncio.client import connect

from darkread.cloud.server import serve_in_thread
from darkread.cloud.speech import MAX_WORD_CHARS, speech_parts, spoken_text
from darkread.proto.messages import Ack, Hello, Welcome, decode, encode

from .test_ocr_remote import OPENAI_KEY, openai_app
from .test_speech import page_message

API_KEY = "test-key-7f3a"
SENTENCE = "The reader moves along the line and the words come back one after another in the dark."


def long_text(words: int) -> str:
    """Plain prose of about ``words`` words, in lines as OCR returns them."""
    sentence = SENTENCE.split()
    out = [sentence[i % len(sentence)] for i in range(words)]
    return "\n".join(" ".join(out[i : i + 12]) for i in range(0, len(out), 12))


def test_speech_parts_keep_every_word_in_bounded_sentences() -> None:
    text = long_text(3000)
    parts = speech_parts(text, 200)
    assert " ".join(parts).split() == spoken_text(text).split()
    assert all(100 < len(part.split()) <= 200 for part in parts[:-1])
    assert all(part.endswith(".") for part in parts[:-1])  # a sentence end lay in each part's second half
    assert speech_parts("x" * 5000, 200) == ["x" * MAX_WORD_CHARS]
    assert speech_parts("", 200) == [spoken_text("")]


async def stream_page(ws_url: str, session_id: str, device_id: str, key: str = API_KEY) -> None:
    async with connect(ws_url, additional_headers={"X-API-Key": key}) as ws:
        await ws.send(encode(Hello(device_id=device_id, session_id=session_id, mode="pages", sensor=(1280, 720), fovea=(100, 200))))
        assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)
        await ws.send(encode(page_message(["a page"])))
        assert decode(await ws.recv(), max_bytes=1 << 20) == Ack(seq=0)


@pytest.fixture
def long_reader() -> Any:
    state: dict[str, Any] = {"scenario": "text", "calls": 0, "token_param": "max_completion_tokens",
                             "text": long_text(3000)}  # fmt: skip
    with serve_in_thread(openai_app(state)) as running:
        yield running.url + "/v1", state


def reading_settings(make_settings: Any, url: str, **overrides: Any) -> Any:
    return make_settings(ocr_backend="openai", openai_base_url=url, openai_api_key=OPENAI_KEY, openai_model="vlm-1",
                         openai_max_output_tokens=256, **overrides)  # fmt: skip


def test_a_long_answer_is_spoken_in_parts(make_settings: Any, long_reader: Any) -> None:
    require_espeak()
    from darkread.cloud.app import create_app

    settings = reading_settings(make_settings, long_reader[0], speech_max_seconds=30.0)
    with serve_in_thread(create_app(settings)) as server:
        asyncio.run(stream_page(server.ws_url, "long", "g"))
        with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY, "Accept": "audio/wav"}, timeout=60) as http:
            first = http.post("/v1/sessions/long/ask")
            count = int(first.headers["x-speech-parts"])
            last = http.post("/v1/sessions/long/ask", params={"part": count - 1})
            beyond = http.post("/v1/sessions/long/ask", params={"part": count})
    parts = speech_parts(long_reader[1]["text"], settings.speech_part_words)
    assert first.status_code == 200 and count == len(parts) == 16 and first.headers["x-speech-part"] == "0"
    rate, pcm = samples(first.content)
    seconds = pcm.size / rate
    # 200 words at 140 wpm are about 86 s: the 30-s cap cuts the part and says so
    assert seconds == pytest.approx(30.0, abs=0.01) and first.headers["x-speech-truncated"] == "true"
    assert float(first.headers["x-speech-seconds"]) == pytest.approx(seconds, abs=1e-3)
    rate, pcm = samples(last.content)
    assert last.status_code == 200 and pcm.size / rate <= 30.0
    assert beyond.status_code == 404 and f"{count} parts" in beyond.json()["detail"]
    assert long_reader[1]["calls"] == 1  # the page was read once; every part speaks that reading


def test_one_key_has_a_few_syntheses_at_once(make_settings: Any, long_reader: Any) -> None:
    require_espeak()
    from darkread.cloud.app import create_app

    settings = reading_settings(make_settings, long_reader[0], speech_per_key=2, speech_threads=1)
    with serve_in_thread(create_app(settings)) as server:
        asyncio.run(stream_page(server.ws_url, "busy", "g"))

        async def at_once(n: int) -> list[httpx.Response]:
            async with httpx.AsyncClient(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=60) as http:
                await http.post("/v1/sessions/busy/ask")  # the reading first: then the asks only speak
                return await asyncio.gather(*(http.post("/v1/sessions/busy/ask", params={"format": "wav", "part": i})
                                              for i in range(n)))  # fmt: skip

        answers = asyncio.run(at_once(6))
    codes = sorted(r.status_code for r in answers)
    assert codes == [200, 200, 429, 429, 429, 429], codes
    refused = next(r for r in answers if r.status_code == 429)
    assert refused.headers["retry-after"] == "1" and "DARKREAD_SPEECH_PER_KEY" in refused.json()["detail"]
