"""REST routes: ask about a session's page, fetch the page, list and delete sessions, health."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import asdict, dataclass
from typing import Annotated, Any, Literal, TypeVar

import numpy as np
from fastapi import APIRouter, Body, Depends, Header, HTTPException, Path, Query, Response, status
from fastapi.responses import StreamingResponse

from darkread.core.image_codec import encode_png
from darkread.stitch.stitched_page import ink_mask_to_paper

from .auth import Principal, Scope
from .confidence import REASONS, LineJudgement, LineRead, judge_lines, page_reasons, spoken_answer
from .context import AppContext, get_context, require
from .errors import NoPageError, OcrError, OcrUnavailableError
from .schemas import AskRequest, AskResponse, Health, LineModel, PageModel, SessionModel
from .speech import WAV_MEDIA_TYPE, wants_wav
from .speech_http import require_speech_engine, speak
from .store import SessionInfo

_T = TypeVar("_T")
KEEPALIVE_S = 15.0

log = logging.getLogger(__name__)

SessionId = Annotated[str, Path(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$", description="the session id from hello")]


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
    limit = context.settings.ready_timeout_s  # a probe that waits longer counts a slow answer as down
    store_ok, ocr_ok = await asyncio.gather(
        _within(context.store.ping(), limit), _within(asyncio.to_thread(context.ocr.ready), limit)
    )
    checks = {"store": store_ok, f"ocr:{context.ocr.name}": ocr_ok}
    if not all(checks.values()):
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
        return Health(status="unavailable", checks=checks)
    return Health(status="ready", checks=checks)


async def _within(check: Awaitable[bool], limit_s: float) -> bool:
    """A readiness check's answer, False when it takes longer than ``limit_s`` (it is left to finish)."""
    task = asyncio.ensure_future(check)
    done, _ = await asyncio.wait({task}, timeout=limit_s)
    if not done:
        task.add_done_callback(lambda t: t.cancelled() or t.exception())  # its late failure is not "never retrieved"
        return False
    return not task.cancelled() and task.exception() is None and bool(task.result())


async def _session(context: AppContext, session_id: str, principal: Principal) -> SessionInfo:
    """The session, 404 also when it belongs to another device (its existence is not revealed)."""
    info = await context.store.session(session_id)
    if info is None or not principal.owns(info.device_id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no session {session_id!r}")
    return info


PageQuery = Annotated[int | None, Query(ge=0, description="page number (0 = the first); default: the current page")]


@dataclass(frozen=True)
class _GlassesPage:
    """A page the glasses stitched (mode "pages"): read whole, as sent."""

    page_id: str
    image: np.ndarray


async def _glasses_page(context: AppContext, info: SessionInfo) -> _GlassesPage:
    stored = await context.store.latest_page(info.session_id)
    if stored is None:
        raise HTTPException(status.HTTP_409_CONFLICT, detail=f"session {info.session_id!r} has not sent a page yet")
    return _GlassesPage(f"page-{stored.page_id}", ink_mask_to_paper(stored.mask))


def _no_page(exc: NoPageError) -> HTTPException:
    return HTTPException(status.HTTP_409_CONFLICT, detail=str(exc))


async def _ocr(context: AppContext, call: Callable[[], Awaitable[_T]]) -> _T:
    """Run an OCR call off the event loop with the ask timeout; engine errors as HTTP errors."""
    backend = context.ocr
    try:
        with context.metrics.ocr_seconds.labels(backend=backend.name).time():
            return await asyncio.wait_for(call(), context.settings.ocr_timeout_s)
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


@api.get("/sessions", summary="List sessions, most recently active first", response_model=list[SessionModel])
async def list_sessions(context: Context, principal: Reader) -> list[SessionModel]:
    return [SessionModel.of(info) for info in await context.store.sessions() if principal.owns(info.device_id)]


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
    summary="Delete a session with everything kept for it: frames, pages, readings (admin keys)",
    status_code=status.HTTP_204_NO_CONTENT,
    responses={403: {"description": "not an admin key"}, 404: {"description": "unknown session"}},
)
async def delete_session(session_id: SessionId, context: Context, principal: Admin) -> Response:
    await context.pages.forget(session_id)
    context.asks.forget(session_id)
    if not await context.store.delete_session(session_id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no session {session_id!r}")
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@api.get(
    "/sessions/{session_id}/pages",
    summary="The session's pages: a new one starts when the wearer moves to other text",
    response_model=list[PageModel],
    responses={404: {"description": "unknown session"}},
)
async def list_pages(session_id: SessionId, context: Context, principal: Reader) -> list[PageModel]:
    info = await _session(context, session_id, principal)
    if info.mode == "pages":
        return []
    pages = context.pages.get(session_id)
    await pages.caught_up(context.settings.ask_catch_up_s)
    return [PageModel(**asdict(summary)) for summary in pages.summaries()]


@api.get(
    "/sessions/{session_id}/page.png",
    summary="A page of the session as a PNG (black text on white); default the current one",
    response_class=Response,
    responses={
        200: {"content": {"image/png": {}}, "description": "the page"},
        404: {"description": "unknown session"},
        409: {"description": "nothing stored yet, or no such page"},
    },
)
async def page_png(session_id: SessionId, context: Context, principal: Reader, page: PageQuery = None) -> Response:
    info = await _session(context, session_id, principal)
    _rate_limit(context, principal)
    if info.mode == "pages":
        glasses = await _glasses_page(context, info)
        return Response(encode_png(glasses.image), media_type="image/png", headers={"X-Page-Id": glasses.page_id})
    try:
        rendered = await context.pages.get(session_id).render(page)
    except NoPageError as exc:
        raise _no_page(exc) from None
    headers = {"X-Page-Id": _page_id(rendered.index, rendered.version), "X-Page": str(rendered.index),
               "X-Page-Version": str(rendered.version)}  # fmt: skip
    return Response(encode_png(rendered.grey), media_type="image/png", headers=headers)


def _page_id(index: int, version: int) -> str:
    return f"stitched-{index}-v{version}"


@api.post(
    "/sessions/{session_id}/ask",
    summary="Read a page of the session (default the current one) and answer (JSON, or spoken: Accept: audio/wav or ?format=wav)",
    response_model=AskResponse,
    responses={
        200: {"content": {WAV_MEDIA_TYPE: {}}, "description": "the answer (JSON), or spoken as a RIFF WAV"},
        404: {"description": "unknown session"},
        409: {"description": "nothing stored yet, or no such page"},
        502: {"description": "the OCR engine failed"},
        503: {"description": "the OCR engine or the speech engine is unavailable"},
        504: {"description": "the OCR engine timed out"},
    },
)
async def ask(
    session_id: SessionId,
    context: Context,
    principal: Reader,
    request: Annotated[AskRequest | None, Body()] = None,
    page: PageQuery = None,
    format_: Annotated[Literal["json", "wav"] | None, Query(alias="format", description="wav: the answer spoken")] = None,
    part: Annotated[int, Query(ge=0, le=100_000, description="spoken answers: which part (X-Speech-Parts says how many)")] = 0,
    accept: Annotated[str | None, Header()] = None,
) -> AskResponse | Response:
    question = (request or AskRequest()).question
    spoken = wants_wav(accept, format_)
    if spoken:
        require_speech_engine(context.settings)  # before the OCR work: a missing engine is known at once
    started = time.perf_counter()
    info = await _session(context, session_id, principal)
    _rate_limit(context, principal)
    answer = await _answer(context, info, page)
    answer = answer.model_copy(update={"question": question, "latency_ms": round((time.perf_counter() - started) * 1000, 1)})
    log.info("session %s: read %s with %s in %.0f ms", session_id, answer.page_id, answer.backend, answer.latency_ms)
    return await speak(context, principal, answer, session_id, part) if spoken else answer


@api.get(
    "/sessions/{session_id}/lines/{line}/speech",
    summary="One line of a page spoken (RIFF WAV): an app speaks each line as it is read, following the live push",
    response_class=Response,
    responses={
        200: {"content": {WAV_MEDIA_TYPE: {}}, "description": "the line spoken; X-Line-Count says how many the page has"},
        404: {"description": "unknown session, or the page has no such line (yet)"},
        409: {"description": "nothing stored yet, or no such page"},
        503: {"description": "the OCR engine or the speech engine is unavailable"},
    },
)
async def speak_line(
    session_id: SessionId,
    line: Annotated[int, Path(ge=0, le=10_000, description="the line, 0 = the top one (as in the answer's lines)")],
    context: Context,
    principal: Reader,
    page: PageQuery = None,
) -> Response:
    require_speech_engine(context.settings)
    info = await _session(context, session_id, principal)
    # a budget of its own: a reader following the push asks for every line, beside the page polls
    _rate_limit(context, principal, bucket="lines")
    answer = await _answer(context, info, page)
    if line >= len(answer.lines):
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            detail=f"{answer.page_id} has {len(answer.lines)} lines read so far, no line {line}")  # fmt: skip
    chosen = answer.lines[line]
    said = chosen.text if chosen.status == "read" else " ".join(["One line unclear.", *(REASONS[r] for r in chosen.reasons[:1])])
    one = answer.model_copy(update={"text": chosen.text, "lines": [chosen], "spoken": said})
    response = await speak(context, principal, one, session_id)
    response.headers["X-Line"] = str(line)
    response.headers["X-Line-Count"] = str(len(answer.lines))
    return response


async def _answer(context: AppContext, info: SessionInfo, page: int | None) -> AskResponse:
    """The page read, once per page version however many ask at once; past the time limit the
    reading goes on and the caller gets a 503 to retry."""
    session_id = info.session_id
    progress = context.pages.get(session_id).stitched_seq if info.mode == "frames" else None  # a newer page: a new reading
    version = (info.mode, info.last_seq, page, progress)
    reading = context.asks.run(session_id, version, lambda: _read(context, info, page))
    limit = context.settings.ask_timeout_s
    try:
        return await asyncio.wait_for(asyncio.shield(reading), limit)
    except TimeoutError:
        context.metrics.ask_errors.labels(reason="ask_timeout").inc()
        raise HTTPException(
            status.HTTP_503_SERVICE_UNAVAILABLE, headers={"Retry-After": str(max(1, round(limit)))},
            detail=f"reading the page takes longer than the {limit:g} s limit; it goes on: ask again shortly",
        ) from None


async def _read(context: AppContext, info: SessionInfo, page: int | None) -> AskResponse:
    """What the OCR engine reads on the page (shared by concurrent asks of it)."""
    if info.mode == "pages":
        glasses = await _glasses_page(context, info)
        loop = asyncio.get_running_loop()  # on the OCR threads, never the default executor
        result = await _ocr(context, lambda: loop.run_in_executor(context.pages.ocr_pool, context.ocr.read, glasses.image))
        read = [LineRead(line.text, line.text, line.box, line.char_scores) for line in result.lines]
        corrector = getattr(context.ocr, "corrector", None)
        judgements = judge_lines(read, glasses.image, context.pages.confidence, known=corrector.known if corrector else None)
        return AskResponse(text=result.text, backend=context.ocr.name, page_id=glasses.page_id, latency_ms=0.0,
                           question="", truncated=result.truncated,
                           **_answer_lines([(ln.text, ln.box, ln.confidence, j) for ln, j in zip(result.lines, judgements)]))  # fmt: skip
    try:
        live = await _ocr(context, lambda: context.pages.ask(info.session_id, page, upto_seq=info.last_seq))
    except NoPageError as exc:
        raise _no_page(exc) from None
    reading = live.reading
    return AskResponse(
        text=reading.text, backend=context.ocr.name, page_id=_page_id(reading.index, reading.version),
        page=reading.index, version=reading.version, lines_read=reading.lines_read,
        frames_pending=live.frames_pending, latency_ms=0.0, question="", truncated=reading.truncated,
        **_answer_lines([(line.text, line.box, line.confidence, line.judgement) for line in reading.lines]),
    )  # fmt: skip


def _answer_lines(lines: list[tuple[str, Any, float | None, LineJudgement | None]]) -> dict[str, Any]:
    """The lines with their calibrated confidence and status, how many are unclear and why, and what to say."""
    models = [
        LineModel(text=text, box=box, confidence=score) if j is None else
        LineModel(text=text, box=box, confidence=j.confidence, status=j.status, reasons=list(j.reasons),
                  evidence={k: round(v, 4) for k, v in j.evidence.items()})
        for text, box, score, j in lines
    ]
    unclear = [j for *_, j in lines if j is not None and j.status == "unclear"]
    return {"lines": models, "unclear_lines": len(unclear), "reasons": list(page_reasons(unclear)),
            "spoken": spoken_answer([(text, j) for text, _, _, j in lines])}


def _rate_limit(context: AppContext, principal: Principal, bucket: str = "") -> None:
    assert context.limiter is not None  # set in AppContext.__post_init__
    wait_s = context.limiter.take(f"{principal.key_id}/{bucket}" if bucket else principal.key_id)
    if wait_s > 0:
        context.metrics.ask_errors.labels(reason="rate_limited").inc()
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS, headers={"Retry-After": str(max(1, math.ceil(wait_s)))},
            detail=f"too many requests for this key ({context.settings.ask_rate_per_min:g} per minute)",
        )


@api.get(
    "/sessions/{session_id}/events",
    summary="Server-Sent Events: `page` updates (page, version, the lines read so far) while the wearer reads",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}}, 404: {"description": "unknown session"}},
)
async def events(session_id: SessionId, context: Context, principal: Reader) -> StreamingResponse:
    info = await _session(context, session_id, principal)
    if info.mode == "pages":
        raise HTTPException(status.HTTP_409_CONFLICT, detail="live pages are for sessions that stream frames")
    streams = context.event_streams
    if not streams.try_acquire(principal.key_id):
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS, headers={"Retry-After": str(round(KEEPALIVE_S))},
            detail=f"this key has {streams.limit} event streams open, the most it may (DARKREAD_SSE_PER_KEY); "
            "close one first",
        )  # fmt: skip
    return _HeldStream(lambda: streams.release(principal.key_id), _event_stream(context, session_id),
                       media_type="text/event-stream", headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})  # fmt: skip


class _HeldStream(StreamingResponse):
    """A streamed answer that gives back what it holds (a per-key slot) however it ends: finished,
    client gone, or cancelled before its first byte."""

    def __init__(self, release: Callable[[], None], *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._release = release

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self._release()


async def _event_stream(context: AppContext, session_id: str) -> AsyncIterator[str]:
    updates = context.pages.events(session_id)
    next_update = asyncio.ensure_future(anext(updates))
    try:
        while True:
            done, _ = await asyncio.wait({next_update}, timeout=KEEPALIVE_S)
            if not done:
                yield ": keep-alive\n\n"
                continue
            event = next_update.result()
            yield f"event: page\nid: {event['page']}-{event['version']}\ndata: {json.dumps(event)}\n\n"
            next_update = asyncio.ensure_future(anext(updates))
    finally:
        next_update.cancel()
        with contextlib.suppress(asyncio.CancelledError, StopAsyncIteration):
            await next_update  # the generator must be at rest before it is closed
        await updates.aclose()
