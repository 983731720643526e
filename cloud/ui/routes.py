"""Routes of the live page: the HTML shells, the session-list fragment and the static files."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates

from darkread import __version__

from ..context import AppContext, get_context
from ..routes import Reader, SessionId

HERE = Path(__file__).parent
templates = Jinja2Templates(directory=HERE / "templates")
templates.env.filters["clock"] = lambda unix_s: datetime.fromtimestamp(unix_s, UTC).strftime("%H:%M:%S UTC")

# The page loads only its own script and styles; images and audio come from blob: URLs the script
# makes from authenticated fetches; forms never submit (the key must not travel in a URL).
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob:; media-src blob:; "
        "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "Referrer-Policy": "no-referrer",
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-store",
}

pages = APIRouter(tags=["live page"], include_in_schema=False)
fragments = APIRouter(prefix="/ui", tags=["live page"], include_in_schema=False)
Context = Annotated[AppContext, Depends(get_context)]


def _page(request: Request, template: str, **values: object) -> HTMLResponse:
    api_docs = get_context(request).settings.api_docs
    response = templates.TemplateResponse(request, template, {"version": __version__, "api_docs": api_docs, **values})
    response.headers.update(SECURITY_HEADERS)
    return response


@pages.get("/", response_class=HTMLResponse)
async def index(request: Request) -> HTMLResponse:
    return _page(request, "index.html")


@pages.get("/sessions/{session_id}", response_class=HTMLResponse)
async def session_page(request: Request, session_id: SessionId) -> HTMLResponse:
    return _page(request, "session.html", session_id=session_id)


@fragments.get("/sessions", response_class=HTMLResponse)
async def session_list(request: Request, context: Context, principal: Reader) -> HTMLResponse:
    """The sessions the key may read, most recently active first, as the list the index page shows."""
    sessions = [info for info in await asyncio.to_thread(context.store.sessions) if principal.owns(info.device_id)]
    return _page(request, "fragments/sessions.html", sessions=sessions)


def mount_ui(app: FastAPI) -> None:
    app.include_router(pages)
    app.include_router(fragments)
    app.mount("/ui/static", StaticFiles(directory=HERE / "static"), name="ui-static")
