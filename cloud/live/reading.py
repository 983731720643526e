"""OCR of only what changed: a page's lines are read one by one, and a line whose ink did not
change since it was last read keeps its text.

Lines are matched by content, not by position (a page's coordinates shift when it grows up or
left): a line is unchanged when a line read before has the same size within ``size_tol_px``
and differs in at most ``diff_tol`` of its ink pixels. An offline engine's dictionary
correction runs over the whole text afterwards, so words still see their neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..ocr.base import OcrBackend, OcrResult
from ..ocr.lexicon import LexiconCorrected, LexiconCorrector
from .paging import Box, RenderedPage


BORDER_PX = 8  # white margin around a line crop: detection misreads glyphs touching the edge (i/I)


@dataclass(frozen=True)
class ReadLine:
    box: Box
    text: str
    confidence: float | None
    read_at_version: int  # the page version whose pixels this text was read from


@dataclass(frozen=True)
class PageReading:
    """The answer for one page version."""

    index: int
    version: int
    lines: tuple[ReadLine, ...]
    text: str
    lines_read: int  # lines OCR actually read for this version (the others were unchanged)
    truncated: bool = False


@dataclass
class _Known:
    ink: np.ndarray = field(repr=False)
    text: str
    confidence: float | None
    version: int


def _same_ink(a: np.ndarray, b: np.ndarray, size_tol_px: int, diff_tol: float, shift_px: int = 1) -> bool:
    """Same size within ``size_tol_px`` and, at the best of the shifts up to ``shift_px`` (a
    re-rendered page may move a line by a pixel), at most ``diff_tol`` of the ink differs."""
    if abs(a.shape[0] - b.shape[0]) > size_tol_px or abs(a.shape[1] - b.shape[1]) > size_tol_px:
        return False
    h, w = min(a.shape[0], b.shape[0]) - 2 * shift_px, min(a.shape[1], b.shape[1]) - 2 * shift_px
    if h <= 0 or w <= 0:
        return False
    allowed = diff_tol * max(int(a.sum()), int(b.sum()), 1)
    core = a[shift_px : shift_px + h, shift_px : shift_px + w]
    for dy in range(2 * shift_px + 1):
        for dx in range(2 * shift_px + 1):
            if np.count_nonzero(core != b[dy : dy + h, dx : dx + w]) <= allowed:
                return True
    return False


class LineReader:
    """Reads the versions of one page, remembering the lines it read. Not thread-safe."""

    def __init__(self, backend: OcrBackend, *, size_tol_px: int = 2, diff_tol: float = 0.06, keep_versions: int = 4) -> None:
        if isinstance(backend, LexiconCorrected):
            self.engine: OcrBackend = backend.engine
            self.corrector: LexiconCorrector | None = backend.corrector
        else:
            self.engine, self.corrector = backend, None
        self.name = backend.name
        self.size_tol_px = size_tol_px
        self.diff_tol = diff_tol
        self.keep_versions = keep_versions
        self._known: list[_Known] = []
        self.readings: dict[int, PageReading] = {}  # version -> answer, the last few

    def read(self, page: RenderedPage) -> PageReading:
        if page.version in self.readings:
            return self.readings[page.version]
        lines, known, fresh, truncated = [], [], 0, False
        for box in page.bands:
            x0, y0, x1, y1 = box
            ink = page.ink[y0:y1, x0:x1]
            match = next((k for k in self._known if _same_ink(k.ink, ink, self.size_tol_px, self.diff_tol)), None)
            if match is None:
                crop = cv2.copyMakeBorder(page.grey[y0:y1, x0:x1], *(BORDER_PX,) * 4, cv2.BORDER_CONSTANT, value=255)
                result: OcrResult = self.engine.read(crop)
                text = " ".join(line.text.strip() for line in result.lines if line.text.strip()) or result.text.strip()
                scores = [line.confidence for line in result.lines if line.confidence is not None]
                match = _Known(ink.copy(), text, float(np.mean(scores)) if scores else None, page.version)
                truncated |= result.truncated
                fresh += 1
            known.append(match)
            if match.text:
                lines.append(ReadLine(box, match.text, match.confidence, match.version))
        self._known = known  # only the lines of the newest version are kept
        raw = "\n".join(line.text for line in lines)
        text = self.corrector.correct(raw) if self.corrector is not None and raw else raw
        corrected = text.split("\n") if text else []
        if len(corrected) == len(lines):
            lines = [ReadLine(ln.box, t, ln.confidence, ln.read_at_version) for ln, t in zip(lines, corrected)]
        reading = PageReading(page.index, page.version, tuple(lines), text, fresh, truncated)
        self.readings[page.version] = reading
        while len(self.readings) > self.keep_versions:
            del self.readings[min(self.readings)]
        return reading
