"""OCR engines behind one interface (``OcrBackend``); ``create_backend`` picks one from settings."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .base import OcrBackend, OcrError, OcrLine, OcrResult, OcrUnavailableError

if TYPE_CHECKING:
    from darkread.cloud.settings import Settings

__all__ = ["OcrBackend", "OcrError", "OcrLine", "OcrResult", "OcrUnavailableError", "create_backend"]


def create_backend(settings: Settings) -> OcrBackend:
    """The configured engine. Engines import their libraries lazily, so unused ones cost nothing."""
    name = settings.ocr_backend
    if name in ("local", "rapidocr"):
        from .rapid import RapidOcrBackend

        return RapidOcrBackend()
    if name == "tesseract":
        from .tesseract import TesseractBackend

        return TesseractBackend()
    if name == "google":
        from .google_vision import GoogleVisionBackend

        return GoogleVisionBackend.from_settings(settings)
    if name == "openai":
        from .openai_compatible import OpenAiCompatibleBackend

        return OpenAiCompatibleBackend.from_settings(settings)
    raise ValueError(f"unknown OCR backend {name!r}; choose local, tesseract, google or openai")
