"""OCR of only what changed: a page's lines are read one by one, and a line whose ink did not
change since it was last read keeps its text.

A changed line is read from its own crop; a line whose crop reads nothing takes its text from a
reading in place: all changed lines together, each box where it is on the page and the rest of
the page white, so the text detector sees them at the page's own scale and layout. (On a crop of one 15-30 px line it
often finds nothing: on a 30-lux page of words two lines of three read nothing. The page as a
whole is no cure: the detector then reads faint grey beside a line into it, "ahe quickbrown".)
An engine that reports no boxes (a multimodal LLM) reads crops only.

Lines are matched by content, not by position (a page's coordinates shift when it grows up or
left): a line is unchanged when a line read before has the same size within ``size_tol_px``
and differs in at most ``diff_tol`` of its ink pixels. An offline engine's dictionary
correction runs over the whole text afterwards, so words still see their neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ..confidence import ConfidenceModel, LineJudgement, LineRead, PageConditions, judge_lines, load_model
from ..ocr.base import OcrBackend, OcrLine, OcrResult
from ..ocr.lexicon import LexiconCorrected, LexiconCorrector
from .paging import Box, RenderedPage

_Text = tuple[str, float | None, tuple[float, ...] | None]  # a band's text, mean confidence, characters' probabilities
BORDER_PX = 8  # white margin around a line crop: detection misreads glyphs touching the edge (i/I)


@dataclass(frozen=True)
class ReadLine:
    box: Box
    text: str
    confidence: float | None
    read_at_version: int  # the page version whose pixels this text was read from
    char_scores: tuple[float, ...] | None = None  # each character's probability, when the engine reports them
    raw_text: str = ""  # as the engine read it, before the correction
    judgement: LineJudgement | None = None  # calibrated confidence and status (None: the engine gave no character scores)


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
    char_scores: tuple[float, ...] | None = None


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

    def __init__(self, backend: OcrBackend, *, size_tol_px: int = 2, diff_tol: float = 0.06, keep_versions: int = 4,
                 confidence: ConfidenceModel | None = None) -> None:
        """``confidence``: the line-confidence model each line is judged by (default the shipped one)."""
        if isinstance(backend, LexiconCorrected):
            self.engine: OcrBackend = backend.engine
            self.corrector: LexiconCorrector | None = backend.corrector
        else:
            self.engine, self.corrector = backend, None
        self.name = backend.name
        self.size_tol_px = size_tol_px
        self.diff_tol = diff_tol
        self.keep_versions = keep_versions
        self.confidence = confidence or load_model()
        self._known: list[_Known] = []
        self.readings: dict[int, PageReading] = {}  # version -> answer, the last few

    def read(self, page: RenderedPage) -> PageReading:
        if page.version in self.readings:
            return self.readings[page.version]
        inks = [page.ink[y0:y1, x0:x1] for x0, y0, x1, y1 in page.bands]
        matches = [next((k for k in self._known if _same_ink(k.ink, ink, self.size_tol_px, self.diff_tol)), None) for ink in inks]
        changed = [i for i, match in enumerate(matches) if match is None]
        truncated = False
        if changed:
            texts, truncated = self._read_changed(page, changed)
            for i in changed:
                text, confidence, chars = texts[i]
                matches[i] = _Known(inks[i].copy(), text, confidence, page.version, chars)
        known = [match for match in matches if match is not None]
        # a band of ink the engine read nothing in is a line too: an unclear one (it is not left out silently)
        lines = [ReadLine(box, m.text, m.confidence, m.version, m.char_scores, m.text) for box, m in zip(page.bands, known)
                 if m.text or _line_shaped(box)]
        fresh = len(changed)
        self._known = known  # only the lines of the newest version are kept
        read = [i for i, line in enumerate(lines) if line.text]
        raw = "\n".join(lines[i].text for i in read)
        text = self.corrector.correct(raw) if self.corrector is not None and raw else raw
        corrected = text.split("\n") if text else []
        if len(corrected) == len(read):
            for i, t in zip(read, corrected):
                lines[i] = replace(lines[i], text=t)
        lines = self._judged(page, lines)
        reading = PageReading(page.index, page.version, tuple(lines), text, fresh, truncated)
        self.readings[page.version] = reading
        while len(self.readings) > self.keep_versions:
            del self.readings[min(self.readings)]
        return reading

    def _judged(self, page: RenderedPage, lines: list[ReadLine]) -> list[ReadLine]:
        motion = page.motion
        conditions = (PageConditions(motion.frame_rate_hz(), motion.head_speed_px_s(), motion.shed_level(), motion.light_lux())
                      if motion is not None else PageConditions())
        read = [LineRead(ln.text, ln.raw_text or ln.text, ln.box, ln.char_scores) for ln in lines]
        judgements = judge_lines(read, page.grey, self.confidence, known=self.corrector.known if self.corrector else None,
                                 views=page.views, conditions=conditions)
        return [replace(ln, judgement=j) for ln, j in zip(lines, judgements)]

    def _read_changed(self, page: RenderedPage, changed: list[int]) -> tuple[dict[int, _Text], bool]:
        """Text and mean confidence of each changed band, and whether the engine stopped early:
        each band's own crop first; if a crop read nothing, every changed band is read again in
        place (the more of the page's layout the detector sees, the more it finds: on two pages
        it found one more line than with the empty lines alone), and the bands whose crop read
        nothing take that text."""
        texts, truncated = self._read_crops(page, changed)
        empty = [i for i in changed if not texts[i][0]]
        if empty:
            in_place, stopped = self._read_in_place(page, changed)
            texts.update({i: in_place[i] for i in empty if in_place.get(i, ("", None, None))[0]})
            truncated |= stopped
        return texts, truncated

    def _read_in_place(self, page: RenderedPage, bands: list[int]) -> tuple[dict[int, _Text], bool]:
        """The given bands read together, each where it is on the page and the rest of the page
        white; each text found goes to the band its box lies in. Nothing from an engine that
        reports no boxes."""
        canvas = np.full_like(page.grey, 255)
        for i in bands:
            x0, y0, x1, y1 = page.bands[i]
            canvas[y0:y1, x0:x1] = page.grey[y0:y1, x0:x1]
        result: OcrResult = self.engine.read(_bordered(canvas))
        if any(line.box is None for line in result.lines):
            return {}, result.truncated
        found: dict[int, list[OcrLine]] = {i: [] for i in bands}
        for line in result.lines:
            if line.text.strip() and line.box is not None:
                found[_band_of(line.box, page.bands, bands)].append(line)
        return {i: _joined(band_lines) for i, band_lines in found.items()}, result.truncated

    def _read_crops(self, page: RenderedPage, changed: list[int]) -> tuple[dict[int, _Text], bool]:
        """The changed bands one crop at a time."""
        texts, truncated = {}, False
        for i in changed:
            x0, y0, x1, y1 = page.bands[i]
            result = self.engine.read(_bordered(page.grey[y0:y1, x0:x1]))
            text, confidence, chars = _joined(result.lines)
            texts[i] = (text or result.text.strip(), confidence, chars)
            truncated |= result.truncated
        return texts, truncated


def _joined(lines: list[OcrLine]) -> _Text:
    """One line's text from the pieces the engine found in it, their mean confidence and their
    characters' probabilities."""
    scores = [line.confidence for line in lines if line.confidence is not None]
    chars = [p for line in lines if line.text.strip() and line.char_scores for p in line.char_scores]
    return (" ".join(line.text.strip() for line in lines if line.text.strip()), float(np.mean(scores)) if scores else None,
            tuple(chars) if chars else None)


def _line_shaped(box: Box) -> bool:
    """Whether a band could be a line of text: at least three times as wide as high."""
    x0, y0, x1, y1 = box
    return x1 - x0 >= 3 * (y1 - y0)


def _bordered(image: np.ndarray) -> np.ndarray:
    return cv2.copyMakeBorder(image, *(BORDER_PX,) * 4, cv2.BORDER_CONSTANT, value=255)


def _band_of(box: Box, bands: tuple[Box, ...], candidates: list[int]) -> int:
    """The candidate band a text box (in bordered page coordinates) belongs to: the one its
    vertical centre lies in, else the nearest (a box reaching past its line's padding)."""
    centre = (box[1] + box[3]) / 2 - BORDER_PX
    return min(candidates, key=lambda i: 0.0 if bands[i][1] <= centre < bands[i][3] else min(abs(centre - bands[i][1]), abs(centre - bands[i][3])))
