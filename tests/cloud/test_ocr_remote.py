"""Google Vision and OpenAI-compatible clients against loopback servers (real HTTP on 127.0.0.1)
that check each request exactly and answer with the services' real response shapes."""

from __future__ import annotations

import asyncio
import base64
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from darkread.cloud.errors import OcrError, OcrUnavailableError
from darkread.cloud.ocr.google_vision import GoogleVisionBackend
from darkread.cloud.ocr.openai_compatible import OpenAiCompatibleBackend, prepare_image
from darkread.cloud.server import serve_in_thread

GOOGLE_KEY = "g-key-123"
OPENAI_KEY = "sk-test-456"
PAGE = np.full((120, 300), 255, np.uint8)
PAGE[30:40, 10:290] = 0


def decode_png_data(content: str) -> np.ndarray:
    raw = base64.b64decode(content, validate=True)
    if not raw.startswith(b"\x89PNG\r\n\x1a\n"):
        raise ValueError("image is not a PNG")
    image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError("PNG does not decode")
    return image


def _symbols(word: str, last_break: str | None) -> list[dict[str, Any]]:
    symbols: list[dict[str, Any]] = [{"text": c, "confidence": 0.99} for c in word]
    if last_break:
        symbols[-1]["property"] = {"detectedBreak": {"type": last_break}}
    return symbols


def _word(word: str, x: int, y: int, last_break: str | None) -> dict[str, Any]:
    vertices = [{"x": x, "y": y}, {"x": x + 10 * len(word), "y": y}, {"x": x + 10 * len(word), "y": y + 12}, {"x": x, "y": y + 12}]
    if x == 0:  # proto3 JSON omits zero coordinates
        vertices = [{k: v for k, v in vertex.items() if v} for vertex in vertices]
    return {"boundingBox": {"vertices": vertices}, "symbols": _symbols(word, last_break), "confidence": 0.98}


GOOGLE_OK = {
    "responses": [
        {
            "textAnnotations": [{"locale": "en", "description": "Hello world\nsecond line\n"}],
            "fullTextAnnotation": {
                "text": "Hello world\nsecond line\n",
                "pages": [
                    {
                        "width": 300,
                        "height": 120,
                        "confidence": 0.97,
                        "blocks": [
                            {
                                "blockType": "TEXT",
                                "paragraphs": [
                                    {
                                        "words": [
                                            _word("Hello", 0, 30, "SPACE"),
                                            _word("world", 60, 30, "EOL_SURE_SPACE"),
                                            _word("second", 10, 60, "SPACE"),
                                            _word("line", 80, 60, "LINE_BREAK"),
                                        ]
                                    }
                                ],
                            }
                        ],
                    }
                ],
            },
        }
    ]
}


def google_app(state: dict[str, Any]) -> FastAPI:
    app = FastAPI()

    @app.get("/")
    async def root() -> JSONResponse:
        return JSONResponse({"error": {"code": 404, "message": "Not Found", "status": "NOT_FOUND"}}, status_code=404)

    @app.post("/v1/images:annotate")
    async def annotate(request: Request) -> JSONResponse:
        state["calls"] += 1
        auth_ok = request.headers.get("x-goog-api-key") == GOOGLE_KEY or request.headers.get("authorization") == "Bearer tok-1"
        if not auth_ok:
            body = {"error": {"code": 403, "message": "The request is missing a valid API key.", "status": "PERMISSION_DENIED"}}
            return JSONResponse(body, status_code=403)
        body = await request.json()
        try:
            (entry,) = body["requests"]
            assert set(body) == {"requests"}
            assert entry["features"] == [{"type": "DOCUMENT_TEXT_DETECTION", "model": "builtin/stable"}]
            assert entry["imageContext"] == {"textDetectionParams": {"enableTextDetectionConfidenceScore": True}}
            state["image"] = decode_png_data(entry["image"]["content"])
        except (AssertionError, KeyError, ValueError, TypeError) as exc:
            body = {"error": {"code": 400, "message": f"Invalid request: {exc!r}", "status": "INVALID_ARGUMENT"}}
            return JSONResponse(body, status_code=400)
        scenario = state["scenario"]
        if scenario == "slow":
            await asyncio.sleep(1.5)
        if scenario == "empty":
            return JSONResponse({"responses": [{}]})
        if scenario == "image_error":
            return JSONResponse({"responses": [{"error": {"code": 3, "message": "Bad image data."}}]})
        if scenario == "quota":
            body = {"error": {"code": 429, "message": "Quota exceeded.", "status": "RESOURCE_EXHAUSTED"}}
            return JSONResponse(body, status_code=429)
        return JSONResponse(GOOGLE_OK)

    return app


def openai_app(state: dict[str, Any]) -> FastAPI:
    app = FastAPI()

    @app.get("/v1/models")
    async def models(request: Request) -> JSONResponse:
        if request.headers.get("authorization") != f"Bearer {OPENAI_KEY}":
            error = {"message": "Incorrect API key provided", "type": "invalid_request_error", "code": "invalid_api_key"}
            return JSONResponse({"error": error}, status_code=401)
        return JSONResponse({"object": "list", "data": [{"id": "vlm-1", "object": "model"}]})

    @app.post("/v1/chat/completions")
    async def completions(request: Request) -> JSONResponse:
        state["calls"] += 1
        if request.headers.get("authorization") != f"Bearer {OPENAI_KEY}":
            body = {"error": {"message": "Incorrect API key provided", "type": "invalid_request_error", "code": "invalid_api_key"}}
            return JSONResponse(body, status_code=401)
        body = await request.json()
        token_param = state["token_param"]
        try:
            assert set(body) == {"model", "temperature", "messages", token_param}, sorted(body)
            assert body["model"] == "vlm-1" and body["temperature"] == 0 and body[token_param] == 256
            system, user = body["messages"]
            assert system["role"] == "system" and "Transcribe" in system["content"]
            assert user["role"] == "user"
            text_part, image_part = user["content"]
            assert text_part["type"] == "text"
            assert image_part["type"] == "image_url" and set(image_part["image_url"]) == {"url", "detail"}
            url = image_part["image_url"]["url"]
            assert url.startswith("data:image/png;base64,")
            state["image"] = decode_png_data(url.split(",", 1)[1])
        except (AssertionError, KeyError, ValueError, TypeError) as exc:
            body = {"error": {"message": f"invalid request: {exc!r}", "type": "invalid_request_error", "code": None}}
            return JSONResponse(body, status_code=400)
        scenario = state["scenario"]
        if scenario == "slow":
            await asyncio.sleep(1.5)
        if scenario == "rate_limited" or (scenario == "rate_limited_once" and state["calls"] == 1):
            body = {"error": {"message": "Rate limit reached", "type": "requests", "code": "rate_limit_exceeded"}}
            return JSONResponse(body, status_code=429, headers={"retry-after": "0.25"})
        if scenario == "bad_request":
            body = {"error": {"message": "Invalid image.", "type": "invalid_request_error", "code": "invalid_image"}}
            return JSONResponse(body, status_code=400)
        content, finish = {"length": ("Hello world\nsec", "length"), "null": (None, "stop"),
                           "text": (state.get("text"), "stop")}.get(scenario, ("Hello world\nsecond line", "stop"))  # fmt: skip
        return JSONResponse(
            {
                "id": "chatcmpl-1",
                "object": "chat.completion",
                "created": 1,
                "model": "vlm-1",
                "choices": [{"index": 0, "message": {"role": "assistant", "content": content, "refusal": None}, "finish_reason": finish}],
                "usage": {"prompt_tokens": 900, "completion_tokens": 6, "total_tokens": 906},
            }
        )

    return app


@pytest.fixture(scope="module")
def google_server() -> Iterator[tuple[str, dict[str, Any]]]:
    state: dict[str, Any] = {"scenario": "ok", "calls": 0}
    with serve_in_thread(google_app(state)) as running:
        yield running.url, state


@pytest.fixture(scope="module")
def openai_server() -> Iterator[tuple[str, dict[str, Any]]]:
    state: dict[str, Any] = {"scenario": "ok", "calls": 0, "token_param": "max_completion_tokens"}
    with serve_in_thread(openai_app(state)) as running:
        yield running.url + "/v1", state


_OPENED: list[Any] = []


@pytest.fixture(autouse=True)
def _close_clients() -> Iterator[None]:
    yield
    while _OPENED:
        _OPENED.pop().close()


def google(url: str, **kwargs: Any) -> GoogleVisionBackend:
    kwargs.setdefault("api_key", GOOGLE_KEY)
    backend = GoogleVisionBackend(base_url=url, **kwargs)
    _OPENED.append(backend)
    return backend


@pytest.fixture
def google_state(google_server: tuple[str, dict[str, Any]]) -> dict[str, Any]:
    google_server[1].update(scenario="ok", calls=0, image=None)
    return google_server[1]


def test_google_reads_lines_and_sends_the_page(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    result = google(google_server[0]).read(PAGE)
    assert result.text == "Hello world\nsecond line"
    assert [line.text for line in result.lines] == ["Hello world", "second line"]
    assert result.lines[0].box == (0, 30, 110, 42) and result.lines[0].confidence == pytest.approx(0.98)
    np.testing.assert_array_equal(google_state["image"], PAGE)


def test_google_bearer_token(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    assert google(google_server[0], api_key=None, bearer_token="tok-1").read(PAGE).text == "Hello world\nsecond line"


def test_google_empty_result(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    google_state["scenario"] = "empty"
    result = google(google_server[0]).read(PAGE)
    assert result.text == "" and result.lines == []


def test_google_per_image_error_inside_http_200(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    google_state["scenario"] = "image_error"
    with pytest.raises(OcrError, match="Bad image data") as caught:
        google(google_server[0]).read(PAGE)
    assert not caught.value.retryable


def test_google_request_errors(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    with pytest.raises(OcrUnavailableError, match="PERMISSION_DENIED"):
        google(google_server[0], api_key="wrong").read(PAGE)
    google_state["scenario"] = "quota"
    with pytest.raises(OcrError, match="RESOURCE_EXHAUSTED") as caught:
        google(google_server[0]).read(PAGE)
    assert caught.value.retryable


def test_google_timeout(google_server: tuple[str, dict[str, Any]], google_state: dict[str, Any]) -> None:
    google_state["scenario"] = "slow"
    with pytest.raises(OcrError, match="timeout") as caught:
        google(google_server[0], timeout_s=0.2).read(PAGE)
    assert caught.value.retryable


def test_google_needs_credentials_and_reports_reachability(google_server: tuple[str, dict[str, Any]]) -> None:
    with pytest.raises(OcrUnavailableError, match="GOOGLE_API_KEY"):
        GoogleVisionBackend(base_url=google_server[0])
    assert google(google_server[0]).ready()
    assert not google("http://127.0.0.1:9").ready()


def openai(url: str, state: dict[str, Any], **kwargs: Any) -> OpenAiCompatibleBackend:
    kwargs.setdefault("api_key", OPENAI_KEY)
    backend = OpenAiCompatibleBackend(
        model="vlm-1", base_url=url, token_param=state["token_param"], max_output_tokens=256, **kwargs
    )
    _OPENED.append(backend)
    return backend


@pytest.fixture
def openai_state(openai_server: tuple[str, dict[str, Any]]) -> dict[str, Any]:
    openai_server[1].update(scenario="ok", calls=0, image=None, token_param="max_completion_tokens")
    return openai_server[1]


@pytest.mark.parametrize("token_param", ["max_completion_tokens", "max_tokens"])
def test_openai_reads_and_sends_an_upscaled_page(
    openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any], token_param: str
) -> None:
    openai_state["token_param"] = token_param
    result = openai(openai_server[0], openai_state).read(PAGE)
    assert result.text == "Hello world\nsecond line" and not result.truncated
    assert [line.text for line in result.lines] == ["Hello world", "second line"]
    sent = openai_state["image"]
    assert min(sent.shape) == 768 and sent.shape[1] / sent.shape[0] == pytest.approx(300 / 120, rel=0.01)


def test_openai_truncation_is_flagged(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    openai_state["scenario"] = "length"
    result = openai(openai_server[0], openai_state).read(PAGE)
    assert result.truncated and result.text == "Hello world\nsec"


def test_openai_null_content_is_empty_text(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    openai_state["scenario"] = "null"
    result = openai(openai_server[0], openai_state).read(PAGE)
    assert result.text == "" and result.lines == []


def test_openai_error_bodies(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    openai_state["scenario"] = "bad_request"
    with pytest.raises(OcrError, match="invalid_request_error: Invalid image") as caught:
        openai(openai_server[0], openai_state).read(PAGE)
    assert not caught.value.retryable
    with pytest.raises(OcrUnavailableError, match="Incorrect API key"):
        openai(openai_server[0], openai_state, api_key="wrong").read(PAGE)


def test_openai_429_honours_retry_after(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    waits: list[float] = []
    openai_state["scenario"] = "rate_limited_once"
    result = openai(openai_server[0], openai_state, sleep=waits.append).read(PAGE)
    assert result.text == "Hello world\nsecond line" and waits == [0.25] and openai_state["calls"] == 2
    openai_state.update(scenario="rate_limited", calls=0)
    waits.clear()
    with pytest.raises(OcrError, match="429") as caught:
        openai(openai_server[0], openai_state, sleep=waits.append, max_retries=2).read(PAGE)
    assert caught.value.retryable and waits == [0.25, 0.25] and openai_state["calls"] == 3


def test_openai_timeout(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    openai_state["scenario"] = "slow"
    with pytest.raises(OcrError, match="timeout") as caught:
        openai(openai_server[0], openai_state, timeout_s=0.2).read(PAGE)
    assert caught.value.retryable


def test_openai_ready_checks_models_with_the_key(openai_server: tuple[str, dict[str, Any]], openai_state: dict[str, Any]) -> None:
    assert openai(openai_server[0], openai_state).ready()
    assert not openai(openai_server[0], openai_state, api_key="wrong").ready()


@pytest.mark.parametrize(
    ("shape", "expected"),
    [((120, 300), (768, 1920)), ((100, 2000), (102, 2048)), ((800, 1000), (800, 1000)), ((3000, 1000), (2048, 683))],
)
def test_prepare_image_sizes(shape: tuple[int, int], expected: tuple[int, int]) -> None:
    assert prepare_image(np.full(shape, 255, np.uint8)).shape == expected
