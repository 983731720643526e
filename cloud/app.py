"""The FastAPI application: ``create_app(settings)`` wires store, OCR engine, routes and metrics."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Send
from starlette.types import Scope as Scope_
from prometheus_client import make_asgi_app

from darkread import __version__

from . import datadir
from .auth import KeyRing, Scope, install_log_redaction
from .context import AppContext
from .prometheus import Metrics
from .ocr import OcrBackend, create_backend
from .pages import PageAssembler
from .routes import api, public
from .settings import Settings, get_settings
from .store import Store
from .stream import stream_endpoint
from .ui import mount_ui

log = logging.getLogger(__name__)

DESCRIPTION = """\
Ingest of reconstructed text frames from darkread glasses, page stitching and OCR.

* `WS /v1/stream` — the glasses stream msgpack messages (protocol: `proto/README.md`): `hello`,
  then `frame`s (or `page`s); the service answers `welcome` and cumulative `ack`s sent only after
  each message is committed to disk. Authenticate with `X-API-Key` (or `?key=`, or `hello.token`).
* `POST /v1/sessions/{id}/ask` — read the session's current page.
* `POST /v1/sessions/{id}/ask` with `Accept: audio/wav` (or `?format=wav`) — the answer spoken (RIFF WAV).
* `/` — the live session page (the key is typed in, or given as `/#key=...`).
* `/metrics` — Prometheus metrics (an admin key, unless `DARKREAD_METRICS_PUBLIC`).

Keys are per device with scopes `stream`, `read`, `admin` (`darkread cloud keys add`).
"""


def create_app(settings: Settings | None = None, *, ocr: OcrBackend | None = None) -> FastAPI:
    """A configured app. ``ocr`` overrides the engine chosen by ``settings`` (tests, benchmarks)."""
    settings = settings or get_settings()
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        install_log_redaction()
        datadir.check_data_dir(settings.data_dir)
        held = datadir.acquire(settings.data_dir)
        store = Store(settings.data_dir)
        engine = ocr or create_backend(settings)
        context = AppContext(
            settings=settings,
            store=store,
            metrics=metrics,
            ocr=engine,
            pages=PageAssembler(store, settings.max_frames_per_page),
            keys=KeyRing(settings.keys_path()),
        )
        if not context.auth_configured():
            log.warning("no API key configured: %s", "anyone may connect (--insecure)" if settings.insecure
                        else "serving loopback clients only (darkread cloud keys add, or DARKREAD_API_KEY)")
        app.state.context = context
        log.info("darkread cloud ready: data in %s, OCR engine %s", settings.data_dir, engine.name)
        try:
            yield
        finally:
            close = getattr(engine, "close", None)
            if callable(close):
                close()
            store.close(timeout_s=settings.shutdown_timeout_s)
            datadir.release(held)

    docs = settings.api_docs
    app = FastAPI(
        title="darkread cloud", version=__version__, description=DESCRIPTION, lifespan=lifespan,
        docs_url="/docs" if docs else None, redoc_url="/redoc" if docs else None,
        openapi_url="/openapi.json" if docs else None,
    )
    app.include_router(public)
    app.include_router(api)
    app.add_api_websocket_route("/v1/stream", stream_endpoint, name="stream")
    mount_ui(app)
    metrics_app = make_asgi_app(registry=metrics.registry)
    app.mount("/metrics", metrics_app if settings.metrics_public else _admin_only(metrics_app))
    return app


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
