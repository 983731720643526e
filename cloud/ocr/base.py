"""The one interface every OCR engine implements, and the helpers they share."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 in image pixels


class OcrError(Exception):
    """OCR failed; ``retryable`` says whether trying again later may help (timeouts, 429, 5xx)."""

    def __init__(self, message: str, *, backend: str, retryable: bool = False) -> None:
        super().__init__(f"{backend}: {message}")
        self.backend = backend
        self.retryable = retryable


class OcrUnavailableError(OcrError):
    """The engine is not installed or not configured (missing binary, package or API key)."""


@dataclass(frozen=True)
class OcrLine:
    text: str
    box: Box | None = None  # None when the engine reports no geometry (LLMs)
    confidence: float | None = None


@dataclass(frozen=True)
class OcrResult:
    text: str
    lines: list[OcrLine] = field(default_factory=list)
    truncated: bool = False  # the engine stopped early (e.g. an LLM hit its token limit)


@runtime_checkable
class OcrBackend(Protocol):
    """Reads a uint8 grayscale image, black text on white."""

    name: str

    def read(self, image: np.ndarray) -> OcrResult: ...

    def ready(self) -> bool: ...


def check_image(image: np.ndarray, backend: str) -> np.ndarray:
    """A 2-D uint8 image, or OcrError naming what is wrong."""
    array = np.asarray(image)
    if array.ndim != 2 or array.dtype != np.uint8 or array.size == 0:
        raise OcrError(f"expected a non-empty 2-D uint8 image, got {array.dtype} {array.shape}", backend=backend)
    return array


def reading_order(lines: list[OcrLine]) -> list[OcrLine]:
    """Top-to-bottom, then left-to-right; lines whose vertical centres are within half a line
    height of each other count as one row."""
    boxed = [line for line in lines if line.box is not None]
    if not boxed:
        return list(lines)
    heights = sorted(max(1, line.box[3] - line.box[1]) for line in boxed)  # type: ignore[index]
    tolerance = heights[len(heights) // 2] / 2
    by_centre = sorted(boxed, key=lambda line: (line.box[1] + line.box[3]) / 2)  # type: ignore[index]
    rows: list[list[OcrLine]] = []
    row_centre = None
    for line in by_centre:
        centre = (line.box[1] + line.box[3]) / 2  # type: ignore[index]
        if row_centre is None or centre - row_centre > tolerance:
            rows.append([])
            row_centre = centre
        rows[-1].append(line)
    return [line for row in rows for line in sorted(row, key=lambda line: line.box[0])]  # type: ignore[index]


def join_lines(lines: list[OcrLine]) -> str:
    return "\n".join(line.text for line in lines if line.text)


def encode_png(image: np.ndarray) -> bytes:
    import cv2

    ok, png = cv2.imencode(".png", image)
    if not ok:
        raise OcrError("PNG encoding failed", backend="png")
    return png.tobytes()
