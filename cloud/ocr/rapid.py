"""The embedded default engine: rapidocr 3.x on onnxruntime with its bundled models (offline)."""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ..errors import OcrError, OcrUnavailableError
from .base import OcrLine, OcrResult, check_image, join_lines, reading_order
from .charset import LANGUAGES, restrict_engine

log = logging.getLogger(__name__)

# Bundled PP-OCR det/rec models only (others download at run time). The angle classifier is
# off: on upright text it flips lines 180 degrees. One thread per session: on small CPUs ORT
# with two threads is bimodal, one is stable; scale with engines, one per OCR thread, instead.
RAPIDOCR_PARAMS: dict[str, Any] = {
    "Global.use_cls": False,
    "Global.log_level": "warning",
    # Detect at native resolution (up to 2000 px): the default upscales short images to 736 px
    # on the short side, which splits single lines into fragments and costs seconds.
    "Det.limit_type": "max",
    "Det.limit_side_len": 2000,
    "EngineConfig.onnxruntime.intra_op_num_threads": 1,
    "EngineConfig.onnxruntime.inter_op_num_threads": 1,
}


class RapidOcrBackend:
    """``engines`` independent engines, one per thread reading at once (an engine is not safe to
    call from two threads at once, and one engine would read one page at a time however many
    cores the service has); each has its own models in memory (tens of MB)."""

    name = "rapidocr"

    def __init__(self, params: dict[str, Any] | None = None, engines: int = 1, *, language: str | None = "en",
                 known: Callable[[str], bool] | None = None) -> None:
        """``language``: decode within its alphabet (``charset.LANGUAGES``; None: every class of the
        model); ``known``: whether a word is a dictionary word (decides between the masked and the
        ASCII-folded read)."""
        if engines < 1:
            raise ValueError(f"engines must be at least 1, not {engines}")
        if language is not None and language not in LANGUAGES:
            raise ValueError(f"no alphabet for language {language!r}; choose one of {sorted(LANGUAGES)}")
        self.language = language
        self.known = known
        self._params = {**RAPIDOCR_PARAMS, **(params or {})}
        self.engines = engines
        self._idle: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._made = 0
        self._making = threading.Lock()

    def _new_engine(self) -> Any:
        try:
            from rapidocr import RapidOCR
        except ImportError as exc:
            raise OcrUnavailableError(
                "rapidocr is not installed (pip install 'rapidocr>=3' onnxruntime)", backend=self.name
            ) from exc
        engine = RapidOCR(params=self._params)
        # rapidocr 3 loads its models on first use: a second and more on the first question
        # (and its CPU counted against it); ``ready`` loads them now
        for load in ("_load_det_model", "_load_rec_model"):
            getattr(engine, load, lambda: None)()
        if self.language is not None:
            restrict_engine(engine, self.language, self.known)
        return engine

    def _make_one(self) -> Any | None:
        """A new engine if fewer than ``engines`` exist, else None."""
        with self._making:
            if self._made >= self.engines:
                return None
            engine = self._new_engine()
            self._made += 1
            return engine

    def ready(self) -> bool:
        """Loads every engine now, so no question pays for it."""
        try:
            while (engine := self._make_one()) is not None:
                self._idle.put(engine)
        except OcrError:
            return False
        return True

    @contextlib.contextmanager
    def _engine(self) -> Iterator[Any]:
        """An idle engine (made if there are fewer than ``engines``, else waited for), for one call."""
        try:
            engine = self._idle.get_nowait()
        except queue.Empty:
            engine = self._make_one() or self._idle.get()
        try:
            yield engine
        finally:
            self._idle.put(engine)

    def read(self, image: np.ndarray) -> OcrResult:
        array = check_image(image, self.name)
        with self._engine() as engine:
            output = engine(array)
        if output.txts is None or output.boxes is None:
            return OcrResult(text="", lines=[])
        lines = []
        for quad, text, score in zip(output.boxes, output.txts, output.scores, strict=True):
            xs, ys = np.asarray(quad)[:, 0], np.asarray(quad)[:, 1]
            box = (int(xs.min()), int(ys.min()), int(np.ceil(xs.max())), int(np.ceil(ys.max())))
            corners = tuple((float(x), float(y)) for x, y in np.asarray(quad, dtype=np.float64)[:4])
            chars = getattr(score, "chars", None)
            lines.append(OcrLine(text=str(text), box=box, confidence=float(score), quad=corners,  # type: ignore[arg-type]
                                 char_scores=tuple(chars) if chars is not None else None))
        ordered = reading_order(lines)
        return OcrResult(text=join_lines(ordered), lines=ordered)
