"""OCR by a vision language model behind an OpenAI-compatible Chat Completions API.

Works with OpenAI, vLLM, llama.cpp ``llama-server`` and Ollama (``base_url`` .../v1). The page is
sent as a PNG data URL in the object form of ``image_url``; small pages are upscaled so the short
side is about 768 px (what ``detail: high`` keeps), so 6-10 px text stays readable.
"""

from __future__ import annotations

import base64
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import cv2
import httpx
import numpy as np

from darkread.core.image_codec import encode_png

from ..errors import OcrError, OcrUnavailableError
from .base import OcrLine, OcrResult, check_image
from .google_vision import RETRYABLE_STATUS

if TYPE_CHECKING:
    from darkread.cloud.settings import Settings

TARGET_SHORT_SIDE = 768
MAX_LONG_SIDE = 2048
MAX_RETRY_AFTER_S = 30.0
USER_TEXT = "Transcribe the text in this image."


def prepare_image(image: np.ndarray) -> np.ndarray:
    """Upscale so the short side reaches ~768 px without the long side passing 2048 px; pages
    larger than that are scaled down to fit, as the API would do anyway."""
    height, width = image.shape
    short, long = min(height, width), max(height, width)
    if long > MAX_LONG_SIDE:
        scale, interpolation = MAX_LONG_SIDE / long, cv2.INTER_AREA
    else:
        scale, interpolation = min(TARGET_SHORT_SIDE / short, MAX_LONG_SIDE / long), cv2.INTER_LINEAR
        if scale <= 1:
            return image
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    return cv2.resize(image, size, interpolation=interpolation)


def build_request(
    png: bytes, *, model: str, prompt: str, token_param: str, max_output_tokens: int, detail: str = "high"
) -> dict[str, Any]:
    url = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    return {
        "model": model,
        "temperature": 0,
        token_param: max_output_tokens,
        "messages": [
            {"role": "system", "content": prompt},
            {
                "role": "user",
                "content": [
                    {"type": "text", "text": USER_TEXT},
                    {"type": "image_url", "image_url": {"url": url, "detail": detail}},
                ],
            },
        ],
    }


def parse_response(payload: Any, backend: str = "openai") -> OcrResult:
    """The JSON body of an HTTP 200 answer -> OcrResult (``truncated`` when cut by the token limit)."""
    if isinstance(payload, dict) and "error" in payload:  # some servers answer errors with 200
        raise OcrError(_error_text(payload), backend=backend)
    try:
        choice = payload["choices"][0]
        message = choice.get("message") or {}
    except (KeyError, IndexError, TypeError, AttributeError) as exc:
        raise OcrError("unexpected response shape (no choices[0])", backend=backend) from exc
    finish = choice.get("finish_reason")
    if finish == "content_filter":
        raise OcrError("the model refused the image (finish_reason content_filter)", backend=backend)
    content = message.get("content")
    if content is None:
        if message.get("refusal"):
            raise OcrError(f"the model refused: {message['refusal']}", backend=backend)
        content = ""
    if not isinstance(content, str):
        raise OcrError(f"message content is {type(content).__name__}, expected text", backend=backend)
    text = content.strip()
    lines = [OcrLine(text=line.strip()) for line in text.splitlines() if line.strip()]
    return OcrResult(text="\n".join(line.text for line in lines), lines=lines, truncated=finish == "length")


def _error_text(payload: Any) -> str:
    error = payload.get("error") if isinstance(payload, dict) else None
    if isinstance(error, dict):
        kind = error.get("type") or error.get("code") or "error"
        return f"{kind}: {error.get('message', 'no message')}"
    if isinstance(error, str):
        return error
    return "unknown error"


def retry_after_s(response: httpx.Response, attempt: int) -> float:
    """Seconds to wait after a 429: the server's ``retry-after`` (seconds), else 1, 2, 4 ... s."""
    header = response.headers.get("retry-after", "")
    try:
        value = float(header)
    except ValueError:
        value = float(2**attempt)
    return min(max(value, 0.0), MAX_RETRY_AFTER_S)


class OpenAiCompatibleBackend:
    name = "openai"

    def __init__(
        self,
        *,
        model: str,
        base_url: str = "https://api.openai.com/v1",
        api_key: str | None = None,
        prompt: str = "Transcribe all text in this image exactly, line by line. Output only the text.",
        token_param: str = "max_completion_tokens",
        max_output_tokens: int = 1024,
        timeout_s: float = 60.0,
        max_retries: int = 2,
        detail: str = "high",
        transport: httpx.BaseTransport | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if token_param not in ("max_tokens", "max_completion_tokens"):
            raise ValueError(f"token_param must be max_tokens or max_completion_tokens, got {token_param!r}")
        self.model, self.prompt, self.token_param = model, prompt, token_param
        self.max_output_tokens, self.max_retries, self.detail = max_output_tokens, max_retries, detail
        self._sleep = sleep
        headers = {"Authorization": f"Bearer {api_key}"} if api_key else {}
        self._client = httpx.Client(base_url=base_url.rstrip("/"), headers=headers, timeout=timeout_s, transport=transport)

    @classmethod
    def from_settings(cls, settings: Settings) -> OpenAiCompatibleBackend:
        return cls(
            model=settings.openai_model,
            base_url=settings.openai_base_url,
            api_key=settings.openai_api_key.get_secret_value() if settings.openai_api_key else None,
            prompt=settings.openai_prompt,
            token_param=settings.openai_token_param,
            max_output_tokens=settings.openai_max_output_tokens,
            timeout_s=settings.ocr_timeout_s,
            max_retries=settings.openai_max_retries,
        )

    def read(self, image: np.ndarray) -> OcrResult:
        png = encode_png(prepare_image(check_image(image, self.name)))
        body = build_request(
            png,
            model=self.model,
            prompt=self.prompt,
            token_param=self.token_param,
            max_output_tokens=self.max_output_tokens,
            detail=self.detail,
        )
        for attempt in range(self.max_retries + 1):
            response = self._post(body)
            if response.status_code == 429 and attempt < self.max_retries:
                self._sleep(retry_after_s(response, attempt))
                continue
            break
        if response.status_code != 200:
            raise self._request_error(response)
        try:
            payload = response.json()
        except ValueError as exc:
            raise OcrError("the answer is not JSON", backend=self.name) from exc
        return parse_response(payload, self.name)

    def _post(self, body: dict[str, Any]) -> httpx.Response:
        try:
            return self._client.post("/chat/completions", json=body)
        except httpx.TimeoutException as exc:
            raise OcrError(f"no answer within the timeout ({type(exc).__name__})", backend=self.name, retryable=True) from exc
        except httpx.TransportError as exc:
            raise OcrError(f"cannot reach the service: {exc}", backend=self.name, retryable=True) from exc

    def _request_error(self, response: httpx.Response) -> OcrError:
        try:
            detail = _error_text(response.json())
        except ValueError:
            detail = response.reason_phrase
        message = f"HTTP {response.status_code}: {detail}"
        if response.status_code in (401, 403):
            return OcrUnavailableError(f"{message}; check DARKREAD_OPENAI_API_KEY", backend=self.name)
        return OcrError(message, backend=self.name, retryable=response.status_code in RETRYABLE_STATUS)

    def ready(self) -> bool:
        """Reachable and authorised: ``GET {base_url}/models`` answers 200."""
        try:
            return self._client.get("/models", timeout=5).status_code == 200
        except httpx.HTTPError:
            return False

    def close(self) -> None:
        self._client.close()
