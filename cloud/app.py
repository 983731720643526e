"""The FastAPI application: ``create_app(settings)`` wires store, OCR engine, routes and metrics."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from prometheus_client import make_asgi_app

from darkread import __version__

from .context import AppContext
from .metrics import Metrics
from .ocr import OcrBackend, create_backend
from .pages import PageAssembler
from .routes import api, public
from .settings import Settings, get_settings
from .store import open_store
from .stream import stream_endpoint

log = logging.getLogger(__name__)

DESCRIPTION = """\
Ingest of reconstructed text frames from darkread glasses, page stitching and OCR.

* `WS /v1/stream` — the glasses stream msgpack messages (protocol: `proto/README.md`): `hello`,
  then `frame`s (or `page`s); the service answers `welcome` and cumulative `ack`s sent only after
  each message is committed to disk. Authenticate with `X-API-Key` (or `?key=`, or `hello.token`).
* `POST /v1/sessions/{id}/ask` — read the session's current page.
* `/metrics` — Prometheus metrics, including websocket ingest counters.
"""


def create_app(settings: Settings | None = None, *, ocr: OcrBackend | None = None) -> FastAPI:
    """A configured app. ``ocr`` overrides the engine chosen by ``settings`` (tests, benchmarks)."""
    settings = settings or get_settings()
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        database_url = settings.database_url.get_secret_value() if settings.database_url else None
        store = await open_store(settings.data_dir, database_url)
        engine = ocr or create_backend(settings)
        if settings.api_key is None:
            log.warning("no API key configured (DARKREAD_API_KEY): the service accepts anyone")
        app.state.context = AppContext(
            settings=settings,
            store=store,
            metrics=metrics,
            ocr=engine,
            pages=PageAssembler(store, settings.max_frames_per_page),
        )
        log.info("darkread cloud ready: sessions in %s, OCR engine %s", _where(settings), engine.name)
        try:
            yield
        finally:
            close = getattr(engine, "close", None)
            if callable(close):
                close()
            await store.close()

    app = FastAPI(title="darkread cloud", version=__version__, description=DESCRIPTION, lifespan=lifespan)
    app.include_router(public)
    app.include_router(api)
    app.add_api_websocket_route("/v1/stream", stream_endpoint, name="stream")
    app.mount("/metrics", make_asgi_app(registry=metrics.registry))
    return app


def _where(settings: Settings) -> str:
    if settings.database_url is None:
        return str(settings.data_dir)
    from .store.postgres import describe

    return describe(settings.database_url.get_secret_value())
