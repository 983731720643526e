"""Errors of the cloud service: storage, pages, start-up, OCR engines.

They sit under ``DarkreadError``; the whole tree is drawn in ``darkread/core/errors.py``.
"""

from __future__ import annotations

from darkread.core.errors import DarkreadError


class CloudError(DarkreadError):
    """The cloud service could not do what was asked."""


class StoreError(CloudError):
    """The store could not persist or read something (disk full, database locked, closed)."""


class UnknownSessionError(StoreError):
    """A write named a session that was never opened (or was deleted)."""


class SessionOwnedError(StoreError):
    """The session exists and belongs to another device or stream (seq space)."""


class SessionShapeError(StoreError):
    """A hello names an existing session with another mode or geometry."""


class NoPageError(CloudError):
    """The session has nothing to read yet (no frames or pages stored)."""


class DataDirError(CloudError):
    """The data directory cannot be used: a file, not writable, a corrupt database, or held by
    another service process."""


class ConfidenceModelError(CloudError):
    """The line-confidence model file cannot be read, or is not one (``darkread eval calibrate`` writes them)."""


class ServiceStartError(CloudError):
    """The service did not come up (it exited during start-up, or did not listen in time)."""


class OcrError(CloudError):
    """OCR failed; ``retryable`` says whether trying again later may help (timeouts, 429, 5xx)."""

    def __init__(self, message: str, *, backend: str, retryable: bool = False) -> None:
        super().__init__(f"{backend}: {message}")
        self.backend = backend
        self.retryable = retryable


class OcrUnavailableError(OcrError):
    """The engine is not installed or not configured (missing binary, package or API key)."""


class SpeechError(CloudError):
    """The speech engine ran but failed, timed out or wrote no valid WAV."""


class SpeechUnavailableError(SpeechError):
    """The speech engine (espeak-ng) is not installed or cannot run."""
