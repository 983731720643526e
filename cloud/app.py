"""The FastAPI application: ``create_app(settings)`` wires store, OCR engine, routes and metrics."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from prometheus_client import make_asgi_app

from darkread import __version__

from .context import AppContext
from .prometheus import Metrics
from .ocr import OcrBackend, create_backend
from .live import LiveConfig, LivePages, PagingConfig
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
* `POST /v1/sessions/{id}/ask` — read the session's current page (or `?page=N`); pages grow as
  frames arrive, and only lines that changed are read again.
* `GET /v1/sessions/{id}/pages`, `GET /v1/sessions/{id}/page.png` — the session's pages.
* `GET /v1/sessions/{id}/events` — Server-Sent Events: `page` updates while the wearer reads.
* `/metrics` — Prometheus metrics, including websocket ingest counters.
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
    )


async def expire_sessions(context: AppContext) -> list[str]:
    """Free idle sessions' pages from memory; delete sessions idle past ``session_expire_s``."""
    await context.live.sweep()
    expire_s = context.settings.session_expire_s
    if expire_s <= 0:
        return []
    cutoff = time.time() - expire_s
    expired = [info.session_id for info in await context.store.sessions() if info.updated_s < cutoff]
    for session_id in expired:
        await context.live.forget(session_id)
        await context.store.delete_session(session_id)
        log.info("session %s expired after %.0f s idle: deleted", session_id, expire_s)
    return expired


async def _sweep_forever(context: AppContext) -> None:
    interval = max(0.05, min(60.0, context.settings.live_idle_s / 4, context.settings.session_expire_s / 4 or 60.0))
    while True:
        await asyncio.sleep(interval)
        try:
            await expire_sessions(context)
        except Exception as exc:  # noqa: BLE001 - the sweep retries next time
            log.warning("session sweep failed: %s", exc)


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
        live = LivePages(store, engine, live_config(settings))
        context = AppContext(settings=settings, store=store, metrics=metrics, ocr=engine, live=live)
        app.state.context = context
        sweeper = asyncio.create_task(_sweep_forever(context))
        # load the OCR models now, off the event loop, so the first question does not wait for them
        warm = asyncio.create_task(asyncio.to_thread(engine.ready))
        # commits of other instances on a shared database wake the pages this instance keeps live
        unsubscribe = store.subscribe(lambda session_id, _last_seq: live.wake(session_id))
        log.info("darkread cloud ready: sessions in %s, OCR engine %s", _where(settings), engine.name)
        try:
            yield
        finally:
            sweeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sweeper
            with contextlib.suppress(Exception):
                await warm
            unsubscribe()
            await live.close()
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
