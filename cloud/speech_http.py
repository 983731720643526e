"""The HTTP side of spoken answers: an ask's text becomes an ``audio/wav`` response."""

from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING

from fastapi import HTTPException, Response, status

from .errors import SpeechError, SpeechUnavailableError
from .speech import WAV_MEDIA_TYPE, engine_path, spoken_text, synthesize, wav_info

if TYPE_CHECKING:
    from .routes import AskResponse
    from .settings import Settings

log = logging.getLogger(__name__)


def require_speech_engine(settings: Settings) -> None:
    """503 with the one-line reason when the engine is missing."""
    try:
        engine_path(settings.speech_engine)
    except SpeechUnavailableError as exc:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc)) from None


async def speak(settings: Settings, answer: AskResponse, session_id: str) -> Response:
    """The answer's text spoken as a RIFF WAV; what was read travels in headers (page, engine)."""
    started = time.perf_counter()
    text = spoken_text(answer.spoken or answer.text)
    try:
        riff = await asyncio.to_thread(
            synthesize, text, settings.voice(), executable=settings.speech_engine, timeout_s=settings.speech_timeout_s
        )
    except SpeechUnavailableError as exc:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc)) from None
    except SpeechError as exc:
        raise HTTPException(status.HTTP_502_BAD_GATEWAY, detail=str(exc)) from None
    info = wav_info(riff)
    log.info(
        "session %s: spoke %d words of %s in %.1f s of audio (%d bytes, synthesised in %.0f ms)",
        session_id, len(text.split()), answer.page_id, info.seconds, len(riff), (time.perf_counter() - started) * 1000,
    )
    headers = {
        "X-Page-Id": answer.page_id,
        "X-OCR-Backend": answer.backend,
        "X-Speech-Seconds": f"{info.seconds:.3f}",
        "Cache-Control": "no-store",
    }
    return Response(riff, media_type=WAV_MEDIA_TYPE, headers=headers)
