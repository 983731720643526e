"""The HTTP side of spoken answers: an ask's text becomes an ``audio/wav`` response.

Every synthesis runs on the speech threads (``DARKREAD_SPEECH_THREADS``, apart from store reads and
OCR), one key may have at most ``DARKREAD_SPEECH_PER_KEY`` running or waiting (429 beyond), and an
answer is spoken one part at a time (``?part=N``, ``X-Speech-Parts``), each at most
``DARKREAD_SPEECH_PART_WORDS`` words and ``DARKREAD_SPEECH_MAX_SECONDS`` of audio.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from typing import TYPE_CHECKING

from fastapi import HTTPException, Response, status

from .errors import SpeechError, SpeechUnavailableError
from .speech import WAV_MEDIA_TYPE, engine_path, speech_parts, synthesize_wav

if TYPE_CHECKING:
    from .auth import Principal
    from .context import AppContext
    from .schemas import AskResponse
    from .settings import Settings

log = logging.getLogger(__name__)


def require_speech_engine(settings: Settings) -> None:
    """503 with the one-line reason when the engine is missing."""
    try:
        engine_path(settings.speech_engine)
    except SpeechUnavailableError as exc:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc)) from None


async def speak(context: AppContext, principal: Principal, answer: AskResponse, session_id: str, part: int = 0) -> Response:
    """Part ``part`` of the answer's text spoken as a RIFF WAV; what was read travels in headers."""
    settings = context.settings
    started = time.perf_counter()
    parts = speech_parts(answer.spoken or answer.text, settings.speech_part_words)
    if part >= len(parts):
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"the answer is spoken in {len(parts)} parts, no part {part}")
    if not context.syntheses.try_acquire(principal.key_id):
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS, headers={"Retry-After": "1"},
            detail=f"this key has {settings.speech_per_key} spoken answers being made, the most it may at once "
            "(DARKREAD_SPEECH_PER_KEY)",
        )  # fmt: skip
    make = functools.partial(synthesize_wav, parts[part], settings.voice(), executable=settings.speech_engine,
                             timeout_s=settings.speech_timeout_s, max_seconds=settings.speech_max_seconds)  # fmt: skip
    try:
        wav = await asyncio.get_running_loop().run_in_executor(context.speech_pool, make)
    except SpeechUnavailableError as exc:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc)) from None
    except SpeechError as exc:
        raise HTTPException(status.HTTP_502_BAD_GATEWAY, detail=str(exc)) from None
    finally:
        context.syntheses.release(principal.key_id)
    log.info(
        "session %s: spoke part %d/%d (%d words) of %s in %.1f s of audio (%d bytes, synthesised in %.0f ms)",
        session_id, part + 1, len(parts), len(parts[part].split()), answer.page_id, wav.info.seconds, len(wav.riff),
        (time.perf_counter() - started) * 1000,
    )  # fmt: skip
    headers = {
        "X-Page-Id": answer.page_id,
        "X-OCR-Backend": answer.backend,
        "X-Speech-Seconds": f"{wav.info.seconds:.3f}",
        "X-Speech-Part": str(part),
        "X-Speech-Parts": str(len(parts)),
        "Cache-Control": "no-store",
    }
    if wav.truncated:
        headers["X-Speech-Truncated"] = "true"
    return Response(memoryview(wav.riff), media_type=WAV_MEDIA_TYPE, headers=headers)
