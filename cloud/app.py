"""The FastAPI application: ``create_app(settings)`` wires store, OCR engine, routes and metrics."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from prometheus_client import make_asgi_app
from starlette.types import ASGIApp, Receive, Send
from starlette.types import Scope as Scope_

from darkread import __version__

from . import datadir
from .auth import KeyRing, Scope, install_log_redaction
from .context import AppContext
from .errors import StoreError
from .guard import RequestGuard
from .live import LiveConfig, LivePages, PagingConfig
from .ocr import OcrBackend, create_backend
from .prometheus import Metrics
from .routes import api, public
from .settings import Settings, get_settings
from .store import open_store
from .stream import stream_endpoint
from .ui import mount_ui

log = logging.getLogger(__name__)

DESCRIPTION = """\
Ingest of reconstructed text frames from darkread glasses, page stitching and OCR.

* `WS /v1/stream` — the glasses stream msgpack messages (protocol: `proto/README.md`): `hello`,
  then `frame`s (or `page`s); the service answers `welcome` and cumulative `ack`s sent only after
  each message is committed to disk. Authenticate with `X-API-Key` (or `?key=`, or `hello.token`).
* `POST /v1/sessions/{id}/ask` — read the session's current page (or `?page=N`); pages grow as
  frames arrive, and only lines that changed are read again.
* `GET /v1/sessions/{id}/pages`, `GET /v1/sessions/{id}/page.png` — the session's pages.
* `GET /v1/sessions/{id}/events` — Server-Sent Events: `page` updates while the wearer reads.
* `POST /v1/sessions/{id}/ask` with `Accept: audio/wav` (or `?format=wav`) — the answer spoken (RIFF WAV).
* `/` — the live session page (the key is typed in, or given as `/#key=...`).
* `/metrics` — Prometheus metrics (an admin key, unless `DARKREAD_METRICS_PUBLIC`).

Keys are per device with scopes `stream`, `read`, `admin` (`darkread cloud keys add`).
"""


def live_config(settings: Settings) -> LiveConfig:
    paging = PagingConfig(
        lost_after_s=settings.page_lost_after_s,
        max_page_pixels=settings.max_page_pixels,
        min_stitch_gap_us=round(settings.min_stitch_gap_ms * 1000),
    )
    return LiveConfig(
        paging=paging,
        stitch_threads=settings.stitch_threads,
        ocr_threads=settings.ocr_threads,
        catch_up_s=settings.ask_catch_up_s,
        live_idle_s=settings.live_idle_s,
        confidence_model=str(settings.line_confidence_model) if settings.line_confidence_model else None,
    )


async def expire_sessions(context: AppContext) -> list[str]:
    """Free idle sessions' pages from memory; delete sessions idle past ``session_expire_s``."""
    await context.pages.sweep()
    expire_s = context.settings.session_expire_s
    if expire_s <= 0:
        return []
    cutoff = time.time() - expire_s
    expired = [info.session_id for info in await context.store.sessions() if info.updated_s < cutoff]
    for session_id in expired:
        await context.pages.forget(session_id)
        await context.store.delete_session(session_id)
        log.info("session %s expired after %.0f s idle: deleted", session_id, expire_s)
    return expired


async def _sweep_forever(context: AppContext) -> None:
    interval = max(0.05, min(60.0, context.settings.live_idle_s / 4, context.settings.session_expire_s / 4 or 60.0))
    while True:
        await asyncio.sleep(interval)
        try:
            await expire_sessions(context)
        except Exception as exc:  # the sweep retries next time
            log.warning("session sweep failed: %s", exc)


def create_app(settings: Settings | None = None, *, ocr: OcrBackend | None = None) -> FastAPI:
    """A configured app. ``ocr`` overrides the engine chosen by ``settings`` (tests, benchmarks)."""
    settings = settings or get_settings()
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        install_log_redaction()
        datadir.check_data_dir(settings.data_dir)
        held = datadir.acquire(settings.data_dir)
        database_url = settings.database_url.get_secret_value() if settings.database_url else None
        store = await open_store(settings.data_dir, database_url, timeout_s=settings.store_timeout_s,
                                 read_threads=settings.store_read_threads)
        engine = ocr or create_backend(settings)
        context = AppContext(
            settings=settings,
            store=store,
            metrics=metrics,
            ocr=engine,
            pages=LivePages(store, engine, live_config(settings)),
            keys=KeyRing(settings.keys_path()),
        )
        if not context.auth_configured():
            log.warning("no API key configured: %s", "anyone may connect (--insecure)" if settings.insecure
                        else "serving loopback clients only (darkread cloud keys add, or DARKREAD_API_KEY)")
        app.state.context = context
        sweeper = asyncio.create_task(_sweep_forever(context))
        # load the OCR models now, off the event loop, so the first question does not wait for them
        warm = asyncio.create_task(asyncio.to_thread(engine.ready))
        # commits of other instances on a shared database wake the pages this instance keeps live
        unsubscribe = store.subscribe(lambda session_id, _last_seq: context.pages.wake(session_id))
        log.info("darkread cloud ready: sessions in %s, OCR engine %s", _where(settings), engine.name)
        try:
            yield
        finally:
            # every step is bounded: a systemd stop or a failover must not wait on a stuck part
            sweeper.cancel()
            await asyncio.wait({sweeper}, timeout=5.0)
            if not (await asyncio.wait({warm}, timeout=settings.shutdown_timeout_s))[0]:
                log.warning("OCR models still loading after %.0f s; shutdown goes on", settings.shutdown_timeout_s)
            elif not warm.cancelled() and warm.exception() is not None:  # said by /readyz and the questions
                log.debug("OCR warm-up failed: %s", warm.exception())
            unsubscribe()
            await context.pages.close(timeout_s=min(5.0, settings.shutdown_timeout_s))
            context.speech_pool.shutdown(wait=False, cancel_futures=True)
            close = getattr(engine, "close", None)
            if callable(close):
                close()
            await store.close(timeout_s=settings.shutdown_timeout_s)
            datadir.release(held)

    docs = settings.api_docs
    app = FastAPI(
        title="darkread cloud", version=__version__, description=DESCRIPTION, lifespan=lifespan,
        docs_url="/docs" if docs else None, redoc_url="/redoc" if docs else None,
        openapi_url="/openapi.json" if docs else None,
    )
    app.add_middleware(RequestGuard)
    app.add_exception_handler(StoreError, _store_unavailable)
    app.include_router(public)
    app.include_router(api)
    app.add_api_websocket_route("/v1/stream", stream_endpoint, name="stream")
    mount_ui(app)
    metrics_app = make_asgi_app(registry=metrics.registry)
    app.mount("/metrics", metrics_app if settings.metrics_public else _admin_only(metrics_app))
    return app


STORE_RETRY_AFTER_S = 5


async def _store_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """A store that fails (a database down, a pool without a connection in time): 503 with the
    reason in one line and when to retry, logged once without a traceback."""
    reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    log.warning("%s %s: 503, the store failed: %s", request.method, request.url.path, reason)
    return JSONResponse({"detail": f"the session store is unavailable: {reason}"}, 503,
                        headers={"Retry-After": str(STORE_RETRY_AFTER_S)})  # fmt: skip


def _where(settings: Settings) -> str:
    if settings.database_url is None:
        return str(settings.data_dir)
    from .store.postgres import describe  # lazy: psycopg only with a PostgreSQL store

    return describe(settings.database_url.get_secret_value())


def _admin_only(inner: ASGIApp) -> ASGIApp:
    """``/metrics`` behind an admin key (401 without a valid key, 403 with a weaker one)."""

    async def guarded(scope: Scope_, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            request = Request(scope)
            context: AppContext = request.app.state.context
            key = request.headers.get("x-api-key") or request.query_params.get("key")
            principal = context.authenticate(key, client_host=request.client.host if request.client else None)
            if principal is None or not principal.can(Scope.ADMIN):
                code = 401 if principal is None else 403
                await JSONResponse({"detail": "/metrics needs an admin API key (X-API-Key)"}, code)(scope, receive, send)
                return
        await inner(scope, receive, send)

    return guarded
