"""Google Cloud Vision ``images:annotate`` with DOCUMENT_TEXT_DETECTION, over plain REST (httpx).

Three kinds of failure arrive differently: request-level errors are HTTP errors with
``{"error": {code, message, status}}``; per-image errors arrive inside HTTP 200 as
``responses[0].error``; an image without text is ``{}`` (proto3 JSON omits empty fields, and
zero coordinates too).
"""

from __future__ import annotations

import base64
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np

from darkread.core.image_codec import encode_png

from ..errors import OcrError, OcrUnavailableError
from .base import OcrLine, OcrResult, check_image, join_lines, reading_order

if TYPE_CHECKING:
    from darkread.cloud.settings import Settings

RETRYABLE_STATUS = {408, 429, 500, 502, 503, 504}
LINE_ENDS = {"EOL_SURE_SPACE", "LINE_BREAK"}


def build_request(png: bytes, model: str = "builtin/stable") -> dict[str, Any]:
    return {
        "requests": [
            {
                "image": {"content": base64.b64encode(png).decode("ascii")},
                "features": [{"type": "DOCUMENT_TEXT_DETECTION", "model": model}],
                "imageContext": {"textDetectionParams": {"enableTextDetectionConfidenceScore": True}},
            }
        ]
    }


def _box(vertices: list[dict[str, Any]]) -> tuple[int, int, int, int]:
    xs = [int(v.get("x", 0)) for v in vertices] or [0]
    ys = [int(v.get("y", 0)) for v in vertices] or [0]
    return min(xs), min(ys), max(xs), max(ys)


def lines_from_annotation(annotation: dict[str, Any]) -> list[OcrLine]:
    """``fullTextAnnotation`` -> lines, split where a symbol carries a line-ending break."""
    lines: list[OcrLine] = []
    for page in annotation.get("pages", []):
        for block in page.get("blocks", []):
            for paragraph in block.get("paragraphs", []):
                text, boxes, confidences = "", [], []
                for word in paragraph.get("words", []):
                    boxes.append(_box(word.get("boundingBox", {}).get("vertices", [])))
                    if "confidence" in word:
                        confidences.append(float(word["confidence"]))
                    for symbol in word.get("symbols", []):
                        text += symbol.get("text", "")
                        kind = symbol.get("property", {}).get("detectedBreak", {}).get("type")
                        if kind in ("SPACE", "SURE_SPACE"):
                            text += " "
                        elif kind == "HYPHEN":
                            text += "-"
                        if kind in LINE_ENDS or kind == "HYPHEN":
                            lines.append(_line(text, boxes, confidences))
                            text, boxes, confidences = "", [], []
                if text.strip():
                    lines.append(_line(text, boxes, confidences))
    return reading_order([line for line in lines if line.text])


def _line(text: str, boxes: list[tuple[int, int, int, int]], confidences: list[float]) -> OcrLine:
    box = (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes)) if boxes else None
    return OcrLine(text=text.strip(), box=box, confidence=sum(confidences) / len(confidences) if confidences else None)


def parse_response(payload: Any, backend: str = "google") -> OcrResult:
    """The JSON body of an HTTP 200 answer -> OcrResult, or OcrError for a per-image error."""
    if not isinstance(payload, dict) or not isinstance(payload.get("responses", []), list):
        raise OcrError("unexpected response shape (no 'responses' list)", backend=backend)
    responses = payload.get("responses") or [{}]
    first = responses[0] if isinstance(responses[0], dict) else {}
    if "error" in first:
        error = first["error"]
        raise OcrError(f"image rejected: {error.get('message', 'unknown error')} (code {error.get('code')})", backend=backend)
    annotation = first.get("fullTextAnnotation")
    if not annotation:
        return OcrResult(text="", lines=[])
    text = str(annotation.get("text", "")).strip()
    return OcrResult(text=text, lines=lines_from_annotation(annotation))


def request_error(response: httpx.Response, backend: str) -> OcrError:
    """A non-200 answer -> OcrError with the service's own message when it sent one."""
    try:
        error = response.json().get("error", {})
        detail = f"{error.get('status') or response.status_code}: {error.get('message') or response.reason_phrase}"
    except (ValueError, AttributeError):
        detail = f"HTTP {response.status_code} {response.reason_phrase}"
    if response.status_code in (401, 403):
        return OcrUnavailableError(f"not authorised ({detail}); check the API key or token", backend=backend)
    return OcrError(detail, backend=backend, retryable=response.status_code in RETRYABLE_STATUS)


class GoogleVisionBackend:
    name = "google"

    def __init__(
        self,
        *,
        base_url: str = "https://vision.googleapis.com",
        api_key: str | None = None,
        bearer_token: str | None = None,
        timeout_s: float = 30.0,
        model: str = "builtin/stable",
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        if not api_key and not bearer_token:
            raise OcrUnavailableError(
                "Google Vision needs DARKREAD_GOOGLE_API_KEY or DARKREAD_GOOGLE_BEARER_TOKEN", backend=self.name
            )
        headers = {"X-Goog-Api-Key": api_key} if api_key else {"Authorization": f"Bearer {bearer_token}"}
        self.model = model
        self._client = httpx.Client(base_url=base_url.rstrip("/"), headers=headers, timeout=timeout_s, transport=transport)

    @classmethod
    def from_settings(cls, settings: Settings) -> GoogleVisionBackend:
        return cls(
            base_url=settings.google_base_url,
            api_key=settings.google_api_key.get_secret_value() if settings.google_api_key else None,
            bearer_token=settings.google_bearer_token.get_secret_value() if settings.google_bearer_token else None,
            timeout_s=settings.ocr_timeout_s,
        )

    def read(self, image: np.ndarray) -> OcrResult:
        png = encode_png(check_image(image, self.name))
        try:
            response = self._client.post("/v1/images:annotate", json=build_request(png, self.model))
        except httpx.TimeoutException as exc:
            raise OcrError(f"no answer within the timeout ({type(exc).__name__})", backend=self.name, retryable=True) from exc
        except httpx.TransportError as exc:
            raise OcrError(f"cannot reach the service: {exc}", backend=self.name, retryable=True) from exc
        if response.status_code != 200:
            raise request_error(response, self.name)
        try:
            payload = response.json()
        except ValueError as exc:
            raise OcrError("the answer is not JSON", backend=self.name) from exc
        result = parse_response(payload, self.name)
        if not result.lines and result.text:
            return OcrResult(text=result.text, lines=[OcrLine(text=t) for t in result.text.splitlines() if t.strip()])
        return OcrResult(text=result.text or join_lines(result.lines), lines=result.lines)

    def ready(self) -> bool:
        """Reachable: the host answers HTTP (any status below 500)."""
        try:
            return self._client.get("/", timeout=5).status_code < 500
        except httpx.HTTPError:
            return False

    def close(self) -> None:
        self._client.close()
