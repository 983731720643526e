"""The embedded default engine: rapidocr 3.x on onnxruntime with its bundled models (offline)."""

from __future__ import annotations

import logging
import threading
from typing import Any

import numpy as np

from ..errors import OcrError, OcrUnavailableError
from .base import OcrLine, OcrResult, check_image, join_lines, reading_order

log = logging.getLogger(__name__)

# Bundled PP-OCR det/rec models only (others download at run time). The angle classifier is
# off: on upright text it flips lines 180 degrees. One thread per session: on small CPUs ORT
# with two threads is bimodal, one is stable; scale with processes instead.
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
    name = "rapidocr"

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        self._params = {**RAPIDOCR_PARAMS, **(params or {})}
        self._engine: Any = None
        self._lock = threading.Lock()  # the engine is not safe to call from two threads at once

    def _load(self) -> Any:
        if self._engine is None:
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
            self._engine = engine
        return self._engine

    def ready(self) -> bool:
        try:
            with self._lock:
                self._load()
        except OcrError:
            return False
        return True

    def read(self, image: np.ndarray) -> OcrResult:
        array = check_image(image, self.name)
        with self._lock:
            output = self._load()(array)
        if output.txts is None or output.boxes is None:
            return OcrResult(text="", lines=[])
        lines = []
        for quad, text, score in zip(output.boxes, output.txts, output.scores, strict=True):
            xs, ys = np.asarray(quad)[:, 0], np.asarray(quad)[:, 1]
            box = (int(xs.min()), int(ys.min()), int(np.ceil(xs.max())), int(np.ceil(ys.max())))
            corners = tuple((float(x), float(y)) for x, y in np.asarray(quad, dtype=np.float64)[:4])
            lines.append(OcrLine(text=str(text), box=box, confidence=float(score), quad=corners))  # type: ignore[arg-type]
        ordered = reading_order(lines)
        return OcrResult(text=join_lines(ordered), lines=ordered)
