"""The one interface every OCR engine implements, and the helpers they share."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Protocol, get_args, runtime_checkable

import numpy as np

from ..errors import OcrError

# The engines a service can read with (``DARKREAD_OCR_BACKEND``, ``cloud serve --ocr``, ``read --backend``):
# local and rapidocr name the same embedded engine.
OcrBackendName = Literal["local", "rapidocr", "tesseract", "google", "openai"]
OCR_BACKENDS: tuple[str, ...] = get_args(OcrBackendName)

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 in image pixels
Quad = tuple[tuple[float, float], tuple[float, float], tuple[float, float], tuple[float, float]]


@dataclass(frozen=True)
class OcrLine:
    text: str
    box: Box | None = None  # None when the engine reports no geometry (LLMs)
    confidence: float | None = None
    quad: Quad | None = None  # corners clockwise from the top-left, when the engine reports a rotated box
    char_scores: tuple[float, ...] | None = None  # each character's probability, when the engine reports them


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
    """Top-to-bottom, then left-to-right; lines whose vertical positions are within half a line
    height of each other count as one row.

    When every line has a rotated box (``quad``), positions are measured across the text's own
    direction (the median slope of the boxes' top edges), so a tilted page, whose lines' upright
    boxes overlap and interleave, still reads line after line."""
    boxed = [line for line in lines if line.box is not None]
    if not boxed:
        return list(lines)
    quads = [(quad, line) for line in boxed if (quad := line.quad) is not None]
    if len(quads) == len(boxed):
        slope = _median_slope(boxed)
        return _rows([(_across_text(quad, slope), _quad_height(quad), quad[0][0], line) for quad, line in quads])
    return _rows([((box[1] + box[3]) / 2, max(1, box[3] - box[1]), box[0], line)
                  for line in boxed if (box := line.box) is not None])


def _median_slope(lines: list[OcrLine]) -> float:
    slopes = sorted(
        (q[1][1] - q[0][1]) / (q[1][0] - q[0][0]) for q in (line.quad for line in lines) if q is not None and q[1][0] != q[0][0]
    )
    return slopes[len(slopes) // 2] if slopes else 0.0


def _across_text(quad: Quad, slope: float) -> float:
    """Where the line's centre line meets x = 0, following the text direction."""
    cx = sum(p[0] for p in quad) / 4
    cy = sum(p[1] for p in quad) / 4
    return cy - slope * cx


def _quad_height(quad: Quad) -> float:
    return max(1.0, ((quad[3][0] - quad[0][0]) ** 2 + (quad[3][1] - quad[0][1]) ** 2) ** 0.5)


def _rows(keyed: list[tuple[float, float, float, OcrLine]]) -> list[OcrLine]:
    """(vertical position, height, left x, line) -> lines in reading order."""
    heights = sorted(height for _, height, _, _ in keyed)
    tolerance = heights[len(heights) // 2] / 2
    rows: list[list[tuple[float, float, float, OcrLine]]] = []
    row_position = None
    for item in sorted(keyed, key=lambda item: item[0]):
        if row_position is None or item[0] - row_position > tolerance:
            rows.append([])
            row_position = item[0]
        rows[-1].append(item)
    return [item[3] for row in rows for item in sorted(row, key=lambda item: item[2])]


def join_lines(lines: list[OcrLine]) -> str:
    return "\n".join(line.text for line in lines if line.text)

