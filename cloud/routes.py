"""REST routes: ask about a session's page, fetch the page, list and delete sessions, health."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import asdict
from typing import Annotated, Literal

from darkread.image_codec import encode_png
from fastapi import APIRouter, Body, Depends, Header, HTTPException, Path, Query, Response, status
from pydantic import BaseModel, Field

from .auth import Principal, Scope
from .context import AppContext, get_context, require
from .errors import NoPageError, OcrError, OcrUnavailableError
from .ocr.base import OcrResult
from .pages import PageImage
from .speech import WAV_MEDIA_TYPE, wants_wav
from .speech_http import require_speech_engine, speak
from .store import SessionInfo

log = logging.getLogger(__name__)

SessionId = Annotated[str, Path(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$", description="the session id from hello")]


class SessionModel(BaseModel):
    session_id: str
    device_id: str
    mode: str = Field(description="'frames' (the cloud stitches) or 'pages' (the glasses stitch)")
    sensor: tuple[int, int] = Field(description="sensor (width, height) in pixels")
    fovea: tuple[int, int] = Field(description="foveal window (height, width) in pixels")
    created_s: float = Field(description="UNIX time of the first hello")
    updated_s: float = Field(description="UNIX time of the last hello or stored message")
    last_seq: int = Field(description="highest seq durably stored, -1 if none")
    frames: int
    pages: int

    @classmethod
    def of(cls, info: SessionInfo) -> SessionModel:
        return cls(**asdict(info))


class AskRequest(BaseModel):
    question: str = Field("what does this say", max_length=2000, description="what the wearer asked")


class LineModel(BaseModel):
    text: str
    box: tuple[int, int, int, int] | None = Field(None, description="x0, y0, x1, y1 in page pixels")
    confidence: float | None = None


class AskResponse(BaseModel):
    text: str = Field(description="the text read from the page, lines top to bottom")
    backend: str = Field(description="the OCR engine that read it")
    page_id: str = Field(description="which page: page-<id> (glasses) or frames-<first>-<last> (stitched)")
    latency_ms: float = Field(description="time to assemble the page and read it")
    lines: list[LineModel]
    question: str
    truncated: bool = Field(False, description="the engine stopped early (token limit); text is incomplete")


class Health(BaseModel):
    status: str
    checks: dict[str, bool] = {}


public = APIRouter(tags=["health"])
api = APIRouter(prefix="/v1", tags=["sessions"])
Context = Annotated[AppContext, Depends(get_context)]
Reader = Annotated[Principal, Depends(require(Scope.READ))]
Admin = Annotated[Principal, Depends(require(Scope.ADMIN))]


@public.get("/healthz", summary="Liveness: the process answers", response_model=Health)
async def healthz() -> Health:
    return Health(status="ok")


@public.get(
    "/readyz",
    summary="Readiness: storage and the OCR engine are usable",
    response_model=Health,
    responses={503: {"model": Health, "description": "a dependency is not ready"}},
)
async def readyz(context: Context, response: Response) -> Health:
    store_ok = await asyncio.to_thread(context.store.ping)
    ocr_ok = await asyncio.to_thread(context.ocr.ready)
    checks = {"store": store_ok, f"ocr:{context.ocr.name}": ocr_ok}
    if not all(checks.values()):
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
        return Health(status="unavailable", checks=checks)
    return Health(status="ready", checks=checks)


async def _session(context: AppContext, session_id: str, principal: Principal) -> SessionInfo:
    """The session, 404 also when it belongs to another device (its existence is not revealed)."""
    info = await asyncio.to_thread(context.store.session, session_id)
    if info is None or not principal.owns(info.device_id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no session {session_id!r}")
    return info


async def _page(context: AppContext, info: SessionInfo) -> PageImage:
    try:
        return await asyncio.to_thread(context.pages.current_page, info.session_id, info.mode, info.last_seq)
    except NoPageError as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, detail=str(exc)) from None


@api.get("/sessions", summary="List sessions, most recently active first", response_model=list[SessionModel])
async def list_sessions(context: Context, principal: Reader) -> list[SessionModel]:
    infos = await asyncio.to_thread(context.store.sessions)
    return [SessionModel.of(info) for info in infos if principal.owns(info.device_id)]


@api.get(
    "/sessions/{session_id}",
    summary="One session",
    response_model=SessionModel,
    responses={404: {"description": "unknown session"}},
)
async def get_session(session_id: SessionId, context: Context, principal: Reader) -> SessionModel:
    return SessionModel.of(await _session(context, session_id, principal))


@api.delete(
    "/sessions/{session_id}",
    summary="Delete a session with its frames and pages (admin keys)",
    status_code=status.HTTP_204_NO_CONTENT,
    responses={403: {"description": "not an admin key"}, 404: {"description": "unknown session"}},
)
async def delete_session(session_id: SessionId, context: Context, principal: Admin) -> Response:
    if not await asyncio.to_thread(context.store.delete_session, session_id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no session {session_id!r}")
    context.pages.forget(session_id)
    context.asks.forget(session_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@api.get(
    "/sessions/{session_id}/page.png",
    summary="The session's current page as a PNG (black text on white)",
    response_class=Response,
    responses={
        200: {"content": {"image/png": {}}, "description": "the page"},
        404: {"description": "unknown session"},
        409: {"description": "nothing stored yet"},
    },
)
async def page_png(session_id: SessionId, context: Context, principal: Reader) -> Response:
    info = await _session(context, session_id, principal)
    _rate_limit(context, principal)
    page = await _page(context, info)
    return Response(encode_png(page.image), media_type="image/png", headers={"X-Page-Id": page.page_id})


@api.post(
    "/sessions/{session_id}/ask",
    summary="Read the session's current page and answer (JSON, or spoken: Accept: audio/wav or ?format=wav)",
    response_model=AskResponse,
    responses={
        200: {"content": {WAV_MEDIA_TYPE: {}}, "description": "the answer (JSON), or spoken as a RIFF WAV"},
        404: {"description": "unknown session"},
        409: {"description": "nothing stored yet"},
        502: {"description": "the OCR engine failed"},
        503: {"description": "the OCR engine, stitcher or speech engine is unavailable"},
        504: {"description": "the OCR engine timed out"},
    },
)
async def ask(
    session_id: SessionId,
    context: Context,
    principal: Reader,
    request: Annotated[AskRequest | None, Body()] = None,
    format_: Annotated[Literal["json", "wav"] | None, Query(alias="format", description="wav: the answer spoken")] = None,
    accept: Annotated[str | None, Header()] = None,
) -> AskResponse | Response:
    question = (request or AskRequest()).question
    spoken = wants_wav(accept, format_)
    if spoken:
        require_speech_engine(context.settings)  # before the OCR work: a missing engine is known at once
    started = time.perf_counter()
    info = await _session(context, session_id, principal)
    _rate_limit(context, principal)
    reading = context.asks.run(session_id, (info.mode, info.last_seq), lambda: _read(context, info))
    limit = context.settings.ask_timeout_s
    try:
        page, result = await asyncio.wait_for(asyncio.shield(reading), limit)
    except TimeoutError:  # the reading goes on for the next ask of this page
        context.metrics.ask_errors.labels(reason="ask_timeout").inc()
        raise HTTPException(
            status.HTTP_503_SERVICE_UNAVAILABLE, headers={"Retry-After": str(max(1, round(limit)))},
            detail=f"reading the page takes longer than the {limit:g} s limit; it goes on: ask again shortly",
        ) from None
    latency_ms = (time.perf_counter() - started) * 1000
    log.info("session %s: read %s with %s in %.0f ms", session_id, page.page_id, context.ocr.name, latency_ms)
    answer = AskResponse(
        text=result.text,
        backend=context.ocr.name,
        page_id=page.page_id,
        latency_ms=round(latency_ms, 1),
        lines=[LineModel(text=line.text, box=line.box, confidence=line.confidence) for line in result.lines],
        question=question,
        truncated=result.truncated,
    )
    return await speak(context.settings, answer, session_id) if spoken else answer


def _rate_limit(context: AppContext, principal: Principal) -> None:
    assert context.limiter is not None  # noqa: S101 - set in AppContext.__post_init__
    wait_s = context.limiter.take(principal.key_id)
    if wait_s > 0:
        context.metrics.ask_errors.labels(reason="rate_limited").inc()
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS, headers={"Retry-After": str(max(1, math.ceil(wait_s)))},
            detail=f"too many requests for this key ({context.settings.ask_rate_per_min:g} per minute)",
        )


async def _read(context: AppContext, info: SessionInfo) -> tuple[PageImage, OcrResult]:
    """The session's page and what the OCR engine reads on it (shared by concurrent asks)."""
    page = await _page(context, info)
    backend = context.ocr
    try:
        with context.metrics.ocr_seconds.labels(backend=backend.name).time():
            result = await asyncio.wait_for(
                asyncio.to_thread(backend.read, page.image), context.settings.ocr_timeout_s
            )
    except TimeoutError:
        context.metrics.ask_errors.labels(reason="timeout").inc()
        raise HTTPException(status.HTTP_504_GATEWAY_TIMEOUT, detail=f"{backend.name}: OCR timed out") from None
    except OcrUnavailableError as exc:
        context.metrics.ask_errors.labels(reason="unavailable").inc()
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc)) from None
    except OcrError as exc:
        context.metrics.ask_errors.labels(reason="retryable" if exc.retryable else "failed").inc()
        code = status.HTTP_503_SERVICE_UNAVAILABLE if exc.retryable else status.HTTP_502_BAD_GATEWAY
        raise HTTPException(code, detail=str(exc)) from None
    return page, result
