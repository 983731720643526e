"""What every request handler shares: settings, store, metrics, the OCR backend, the keys, live pages."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from fastapi import HTTPException, Request, Security, status
from fastapi.security import APIKeyHeader, APIKeyQuery

from .auth import ENVIRONMENT_ADMIN, LOOPBACK_DEVELOPER, UNAUTHORIZED, KeyRing, Principal, Scope, is_loopback, principal_of
from .limits import PerKeyCap, RateLimiter, SingleFlight
from .live import LivePages
from .prometheus import Metrics
from .settings import Settings
from .store import SessionStore

if TYPE_CHECKING:
    from .ocr.base import OcrBackend


@dataclass
class AppContext:
    settings: Settings
    store: SessionStore
    metrics: Metrics
    ocr: OcrBackend
    pages: LivePages  # every session's pages, stitched as frames arrive
    keys: KeyRing
    live: dict[str, Any] = field(default_factory=dict)  # session id -> its StreamConnection
    asks: SingleFlight = field(default_factory=SingleFlight)  # one reading per session page
    limiter: RateLimiter | None = None  # asks and page.png per key (from settings when None)
    event_streams: PerKeyCap = field(init=False)  # open GET .../events per key
    syntheses: PerKeyCap = field(init=False)  # spoken answers running or waiting per key
    speech_pool: ThreadPoolExecutor = field(init=False)  # speech only: store reads and OCR have their own

    def __post_init__(self) -> None:
        if self.limiter is None:
            self.limiter = RateLimiter(self.settings.ask_rate_per_min, self.settings.ask_burst)
        self.event_streams = PerKeyCap(self.settings.sse_per_key)
        self.syntheses = PerKeyCap(self.settings.speech_per_key)
        self.speech_pool = ThreadPoolExecutor(self.settings.speech_threads, thread_name_prefix="darkread-speech")

    def auth_configured(self) -> bool:
        return self.settings.api_key is not None or bool(self.keys)

    def authenticate(self, candidate: str | None, *, client_host: str | None) -> Principal | None:
        """The caller behind ``candidate``, or None (refuse). Without any key configured, only
        loopback clients are served (unless ``settings.insecure``)."""
        if not self.auth_configured():
            return LOOPBACK_DEVELOPER if self.settings.insecure or is_loopback(client_host) else None
        if candidate is None:
            return None
        expected = self.settings.api_key
        if expected is not None and secrets.compare_digest(candidate.encode(), expected.get_secret_value().encode()):
            return ENVIRONMENT_ADMIN
        return self.keys.authenticate(candidate)


def get_context(request: Request) -> AppContext:
    return request.app.state.context


_header_key = APIKeyHeader(name="X-API-Key", auto_error=False, description="a darkread API key")
_query_key = APIKeyQuery(name="key", auto_error=False, description="a darkread API key (clients without headers)")


def require(scope: Scope) -> Callable[..., Principal]:
    """REST dependency: the caller, 401 without a valid key, 403 without ``scope``."""

    def dependency(
        request: Request,
        header: str | None = Security(_header_key),
        query: str | None = Security(_query_key),
    ) -> Principal:
        principal = principal_of(request.scope)  # the guard authenticated it before the body was read
        if principal is None:
            client = request.client.host if request.client else None
            principal = get_context(request).authenticate(header if header is not None else query, client_host=client)
        if principal is None:
            raise HTTPException(
                status_code=status.HTTP_401_UNAUTHORIZED,
                detail=UNAUTHORIZED,
                headers={"WWW-Authenticate": "APIKey"},
            )
        if not principal.can(scope):
            raise HTTPException(status.HTTP_403_FORBIDDEN, detail=f"this key lacks the {scope.value!r} scope")
        return principal

    return dependency
