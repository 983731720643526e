"""Spoken answers: ask with Accept: audio/wav through a real uvicorn, a real OCR engine and espeak-ng."""

from __future__ import annotations

import asyncio
import io
import wave
from typing import Any

import httpx
import jiwer
import numpy as np
import pytest
from PIL import Image, ImageDraw, ImageFont
from pydantic import ValidationError
from speech_measure import band_share, require_espeak, samples, transcribe, voiced_share
from websockets.asyncio.client import connect

from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.cloud.settings import Settings
from darkread.cloud.speech import NOTHING_READ, Voice, spoken_text, synthesize, wants_wav, wav_info, with_true_sizes
from darkread.proto.messages import Ack, Hello, Page, Welcome, decode, encode, pack_mask

API_KEY = "test-key-7f3a"
LINES = ["the quick brown fox jumps over", "the lazy dog while reading in", "the dark with an event camera"]
OTHER_TEXT = "a letter from my aunt said that the garden needs more water and two new chairs"


# -- pure parts ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("accept", "format_", "spoken"),
    [
        ("audio/wav", None, True),
        ("audio/x-wav", None, True),
        ("application/json", None, False),
        ("*/*", None, False),
        (None, None, False),
        ("application/json;q=0.5, audio/wav", None, True),
        ("audio/wav;q=0.2, application/json", None, False),
        ("audio/wav;q=0", None, False),
        ("application/json", "wav", True),
        ("audio/wav", "json", False),
    ],
)
def test_speech_is_chosen_by_accept_or_format(accept: str | None, format_: str | None, spoken: bool) -> None:
    assert wants_wav(accept, format_) is spoken


def test_spoken_text_reads_lines_as_one_sentence() -> None:
    assert spoken_text("progression, they\nsicken into a muddy\npool of confor-\nmity") == (
        "progression, they sicken into a muddy pool of conformity"
    )
    assert spoken_text("  \n ") == NOTHING_READ


def test_streamed_wav_header_is_rewritten_with_the_true_sizes() -> None:
    pcm = (np.sin(np.arange(2205) / 5) * 8000).astype(np.int16).tobytes()
    fmt = (16).to_bytes(4, "little") + bytes.fromhex("0100 0100") + (22050).to_bytes(4, "little")
    fmt += (44100).to_bytes(4, "little") + bytes.fromhex("0200 1000")
    placeholder = (0x7FFFF000).to_bytes(4, "little")
    streamed = b"RIFF" + placeholder + b"WAVEfmt " + fmt + b"data" + placeholder + pcm
    fixed = with_true_sizes(streamed)
    assert int.from_bytes(fixed[4:8], "little") == len(fixed) - 8
    info = wav_info(fixed)
    assert (info.sample_rate, info.channels, info.frames) == (22050, 1, 2205)


def test_voice_settings_are_checked_where_configured() -> None:
    settings = Settings(_env_file=None, speech_language="en-gb", speech_voice="", speech_rate_wpm=200)
    assert settings.voice() == Voice("en-gb", "", 200) and settings.voice().espeak_name == "en-gb"
    assert Voice("en-us", "f2").espeak_name == "en-us+f2"
    for bad in ({"speech_voice": "-w /etc/x"}, {"speech_language": "en us"}, {"speech_rate_wpm": 20}):
        with pytest.raises(ValidationError):
            Settings(_env_file=None, **bad)


# -- the engine ------------------------------------------------------------------------------------


@pytest.mark.parametrize("rate_wpm", [110, 140, 200])
def test_espeak_wav_lasts_as_long_as_the_words_at_the_rate(rate_wpm: int) -> None:
    require_espeak()
    text = spoken_text("\n".join(LINES))
    riff = synthesize(text, Voice(rate_wpm=rate_wpm))
    rate, pcm = samples(riff)
    seconds_per_word = pcm.size / rate / len(text.split())
    # espeak-ng keeps close to its rate; leading/trailing silence and word length move it a little.
    assert 0.6 * 60 / rate_wpm <= seconds_per_word <= 1.4 * 60 / rate_wpm, seconds_per_word
    assert band_share(pcm, rate) > 0.9
    assert 0.4 < voiced_share(pcm, rate) < 0.97


def test_missing_engine_is_a_clear_error() -> None:
    from darkread.cloud.errors import SpeechUnavailableError

    with pytest.raises(SpeechUnavailableError, match="espeak-ng-missing.*apt-get install espeak-ng"):
        synthesize("hello", Voice(), executable="espeak-ng-missing")


# -- through the service -------------------------------------------------------------------------


def page_message(lines: list[str]) -> Page:
    """One glasses page (mode 'pages') with ``lines`` printed large and crisp."""
    font = ImageFont.load_default(size=28)
    width = max(int(font.getbbox(line)[2]) for line in lines) + 60
    image = Image.new("L", (width, 50 * len(lines) + 40), 255)
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((30, 20 + 50 * i), line, font=font, fill=0)
    shape, bits = pack_mask((np.asarray(image) < 128).astype(np.uint8))
    return Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits)


def send_page(ws_url: str, session_id: str, page: Page) -> None:
    async def stream() -> None:
        async with connect(ws_url, additional_headers={"X-API-Key": API_KEY}) as ws:
            await ws.send(encode(Hello(device_id="g", session_id=session_id, mode="pages", sensor=(1280, 720), fovea=(100, 200))))
            assert isinstance(decode(await ws.recv(), max_bytes=1 << 20), Welcome)
            await ws.send(encode(page))
            assert decode(await ws.recv(), max_bytes=1 << 20) == Ack(seq=0)

    asyncio.run(stream())


@pytest.fixture(scope="module")
def ocr() -> RapidOcrBackend:
    return RapidOcrBackend()


@pytest.mark.slow  # the recogniser takes ~10 s
def test_ask_answers_in_speech_that_says_the_page(make_settings: Any, run_server: Any, ocr: RapidOcrBackend) -> None:
    require_espeak()
    with run_server(make_settings(), ocr=ocr) as server:
        send_page(server.ws_url, "spoken", page_message(LINES))
        with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=60) as http:
            answer = http.post("/v1/sessions/spoken/ask").raise_for_status().json()
            spoken = http.post("/v1/sessions/spoken/ask", headers={"Accept": "audio/wav"}).raise_for_status()
            by_query = http.post("/v1/sessions/spoken/ask", params={"format": "wav"}).raise_for_status()
    assert answer["text"].split() == " ".join(LINES).split()
    assert spoken.headers["content-type"] == "audio/wav" and by_query.headers["content-type"] == "audio/wav"
    assert spoken.content[:4] == b"RIFF" and spoken.content[8:12] == b"WAVE"
    assert spoken.content == by_query.content  # the same page, the same voice: the same audio
    assert spoken.headers["x-page-id"] == "page-0" and spoken.headers["x-ocr-backend"] == "rapidocr"

    rate, pcm = samples(spoken.content)
    words = len(answer["text"].split())
    assert float(spoken.headers["x-speech-seconds"]) == pytest.approx(pcm.size / rate, abs=1e-3)
    assert 0.6 * 60 / 140 <= pcm.size / rate / words <= 1.4 * 60 / 140  # the default 140 words per minute
    heard = transcribe(spoken.content)
    said = jiwer.wer(spoken_text(answer["text"]), heard)
    unrelated = jiwer.wer(OTHER_TEXT, heard)
    print(f"spoken answer: {len(spoken.content)} bytes, {pcm.size / rate:.2f} s, {words} words; heard {heard!r}, "
          f"WER {said:.2f} against the answer, {unrelated:.2f} against an unrelated sentence")
    # A formant voice through a recogniser trained on people: many words are lost, but what is heard is
    # this answer (an unrelated sentence of the same length scores near 1).
    assert said <= 0.7 and said < unrelated - 0.3


@pytest.mark.slow  # the recogniser takes ~10 s
def test_each_line_is_spoken_on_its_own(make_settings: Any, run_server: Any, ocr: RapidOcrBackend) -> None:
    """What an app following the live push fetches, line by line: the line's words, and a 404 past the last."""
    require_espeak()
    with run_server(make_settings(), ocr=ocr) as server:
        send_page(server.ws_url, "by-line", page_message(LINES))
        with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=60) as http:
            answer = http.post("/v1/sessions/by-line/ask").raise_for_status().json()
            spoken = [http.get(f"/v1/sessions/by-line/lines/{i}/speech") for i in range(len(answer["lines"]))]
            beyond = http.get(f"/v1/sessions/by-line/lines/{len(answer['lines'])}/speech")
            unknown = http.get("/v1/sessions/nobody/lines/0/speech")
        voice = server.context.settings.voice()
    assert [line["text"] for line in answer["lines"]] == LINES
    for line, response in zip(answer["lines"], spoken, strict=True):
        assert response.status_code == 200 and response.headers["content-type"] == "audio/wav"
        assert response.headers["x-line-count"] == str(len(LINES)) and response.headers["x-page-id"] == "page-0"
        assert response.content == synthesize(spoken_text(line["text"]), voice)  # this line's words, nothing else
        rate, pcm = samples(response.content)
        assert 0.6 * 60 / 140 <= pcm.size / rate / len(line["text"].split()) <= 1.4 * 60 / 140
    assert beyond.status_code == 404 and "3 lines read so far, no line 3" in beyond.json()["detail"]
    assert unknown.status_code == 404


def test_speech_without_an_engine_is_a_one_line_503(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(speech_engine="espeak-ng-missing")) as server:
        send_page(server.ws_url, "mute", page_message(LINES[:1]))
        with httpx.Client(base_url=server.url, headers={"X-API-Key": API_KEY}, timeout=30) as http:
            response = http.post("/v1/sessions/mute/ask", params={"format": "wav"})
            still_json = http.post("/v1/sessions/mute/ask")
    assert response.status_code == 503
    detail = response.json()["detail"]
    assert "\n" not in detail and "espeak-ng-missing" in detail and "not installed" in detail
    assert still_json.status_code == 200 and server.ocr.images == [server.ocr.images[0]]  # no OCR for the 503


def test_speech_needs_the_api_key(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings()) as server:
        response = httpx.post(f"{server.url}/v1/sessions/any/ask", headers={"Accept": "audio/wav"})
    assert response.status_code == 401


def test_wav_info_reads_what_synthesize_wrote() -> None:
    require_espeak()
    riff = synthesize("one two three", Voice())
    with wave.open(io.BytesIO(riff)) as reader:
        assert wav_info(riff).frames == reader.getnframes() > 0
