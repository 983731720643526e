"""Tesseract 5 (LSTM, ``--oem 1``, one text block ``--psm 6``) through tesserocr or pytesseract.

Optional: needs the Debian packages ``tesseract-ocr tesseract-ocr-eng`` and one of the Python
bindings. OpenMP is limited to one thread: on small CPUs Tesseract's default threading is
4-8 times slower; scale with processes instead.
"""

from __future__ import annotations

import os
import shutil
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OcrError, OcrUnavailableError
from .base import OcrLine, OcrResult, check_image, join_lines, reading_order

os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # read by libtesseract when it loads

TESSDATA_DIRS = ("/usr/share/tesseract-ocr/5/tessdata", "/usr/share/tesseract-ocr/4.00/tessdata", "/usr/share/tessdata")
INSTALL_HINT = (
    "Tesseract is not installed: apt-get install tesseract-ocr tesseract-ocr-eng, "
    "then pip install pytesseract (or tesserocr)"
)


def lines_from_words(data: Mapping[str, Sequence[Any]]) -> list[OcrLine]:
    """Tesseract's word table (``image_to_data`` as a dict) -> one OcrLine per text line."""
    grouped: dict[tuple[int, int, int, int], list[int]] = {}
    for i, text in enumerate(data["text"]):
        if int(data["level"][i]) == 5 and str(text).strip():
            key = (int(data["page_num"][i]), int(data["block_num"][i]), int(data["par_num"][i]), int(data["line_num"][i]))
            grouped.setdefault(key, []).append(i)
    lines = []
    for indices in grouped.values():
        left = [int(data["left"][i]) for i in indices]
        top = [int(data["top"][i]) for i in indices]
        right = [int(data["left"][i]) + int(data["width"][i]) for i in indices]
        bottom = [int(data["top"][i]) + int(data["height"][i]) for i in indices]
        confidences = [float(data["conf"][i]) for i in indices if float(data["conf"][i]) >= 0]
        lines.append(
            OcrLine(
                text=" ".join(str(data["text"][i]).strip() for i in indices),
                box=(min(left), min(top), max(right), max(bottom)),
                confidence=(sum(confidences) / len(confidences) / 100) if confidences else None,
            )
        )
    return reading_order(lines)


class TesseractBackend:
    name = "tesseract"

    def __init__(self, lang: str = "eng", psm: int = 6, timeout_s: float = 30) -> None:
        self.lang, self.psm, self.timeout_s = lang, psm, timeout_s
        self._local = threading.local()  # tesserocr: one API object per thread

    def _tesserocr_api(self) -> Any | None:
        try:
            import tesserocr
        except ImportError:
            return None
        api = getattr(self._local, "api", None)
        if api is None:
            path = os.environ.get("TESSDATA_PREFIX") or next((d for d in TESSDATA_DIRS if Path(d).is_dir()), None)
            kwargs = {"path": path} if path else {}
            try:
                api = tesserocr.PyTessBaseAPI(lang=self.lang, psm=self.psm, oem=tesserocr.OEM.LSTM_ONLY, **kwargs)
            except RuntimeError as exc:
                raise OcrUnavailableError(f"cannot load language data {self.lang!r}: {exc}", backend=self.name) from exc
            self._local.api = api
        return api

    def ready(self) -> bool:
        try:
            if self._tesserocr_api() is not None:
                return True
        except OcrError:
            return False
        try:
            import pytesseract  # noqa: F401  # imported only to learn whether it is installed
        except ImportError:
            return False
        return shutil.which("tesseract") is not None

    def read(self, image: np.ndarray) -> OcrResult:
        from PIL import Image

        array = check_image(image, self.name)
        picture = Image.fromarray(array)
        api = self._tesserocr_api()
        if api is not None:
            return self._read_tesserocr(api, picture)
        try:
            import pytesseract
        except ImportError as exc:
            raise OcrUnavailableError(INSTALL_HINT, backend=self.name) from exc
        try:
            data = pytesseract.image_to_data(
                picture,
                lang=self.lang,
                config=f"--oem 1 --psm {self.psm}",
                output_type=pytesseract.Output.DICT,
                timeout=self.timeout_s,
            )
        except pytesseract.TesseractNotFoundError as exc:
            raise OcrUnavailableError(INSTALL_HINT, backend=self.name) from exc
        except RuntimeError as exc:  # pytesseract reports its timeout as RuntimeError
            raise OcrError(str(exc), backend=self.name, retryable=True) from exc
        except pytesseract.TesseractError as exc:
            raise OcrError(str(exc), backend=self.name) from exc
        lines = lines_from_words(data)
        return OcrResult(text=join_lines(lines), lines=lines)

    def _read_tesserocr(self, api: Any, picture: Any) -> OcrResult:
        import tesserocr

        api.SetImage(picture)
        api.Recognize()
        level = tesserocr.RIL.TEXTLINE
        lines = []
        for item in tesserocr.iterate_level(api.GetIterator(), level):
            text = (item.GetUTF8Text(level) or "").strip()
            box = item.BoundingBox(level)
            if text and box is not None:
                x0, y0, x1, y1 = box
                lines.append(OcrLine(text=text, box=(int(x0), int(y0), int(x1), int(y1)), confidence=item.Confidence(level) / 100))
        ordered = reading_order(lines)
        return OcrResult(text=join_lines(ordered), lines=ordered)
