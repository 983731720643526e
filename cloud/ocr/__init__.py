"""OCR engines behind one interface (``OcrBackend``); ``create_backend`` picks one from settings."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..errors import OcrError, OcrUnavailableError
from .base import OCR_BACKENDS, OcrBackend, OcrLine, OcrResult

if TYPE_CHECKING:
    from darkread.cloud.settings import Settings

__all__ = ["OcrBackend", "OcrError", "OcrLine", "OcrResult", "OcrUnavailableError", "create_backend"]


def create_backend(settings: Settings) -> OcrBackend:
    """The configured engine. Engines import their libraries lazily, so unused ones cost nothing.

    Offline engines read without a language model; unless ``ocr_lexicon`` is off, their text goes
    through the dictionary correction (``lexicon.LexiconCorrected``). Remote engines have their own.
    """
    name = settings.ocr_backend
    if name in ("local", "rapidocr", "tesseract"):
        from .lexicon import LexiconCorrected, LexiconCorrector  # lazy: only the configured engine (and its model) loads

        corrector = LexiconCorrector(language=settings.ocr_language) if settings.ocr_lexicon else None
        engine: OcrBackend
        if name == "tesseract":
            from .tesseract import TesseractBackend  # lazy: only the configured engine (and its model) loads

            engine = TesseractBackend()
        else:
            from .rapid import RapidOcrBackend  # lazy: only the configured engine (and its model) loads

            # one engine per thread reading pages, decoding within the language's alphabet
            engine = RapidOcrBackend(engines=settings.ocr_threads, language=None if settings.ocr_language == "any" else settings.ocr_language,
                                     known=corrector.known if corrector is not None else None)
        return engine if corrector is None else LexiconCorrected(engine, corrector)
    if name == "google":
        from .google_vision import GoogleVisionBackend  # lazy: only the configured engine (and its model) loads

        return GoogleVisionBackend.from_settings(settings)
    if name == "openai":
        from .openai_compatible import OpenAiCompatibleBackend  # lazy: only the configured engine (and its model) loads

        return OpenAiCompatibleBackend.from_settings(settings)
    raise ValueError(f"unknown OCR backend {name!r}; choose {', '.join(OCR_BACKENDS)}")
