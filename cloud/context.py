"""What every request handler shares: settings, store, metrics, the OCR backend, live pages."""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fastapi import HTTPException, Request, Security, status
from fastapi.security import APIKeyHeader, APIKeyQuery

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
    live: LivePages

    def key_matches(self, candidate: str | None) -> bool:
        """True when no key is configured, or ``candidate`` equals it (constant-time)."""
        expected = self.settings.api_key
        if expected is None:
            return True
        if candidate is None:
            return False
        return secrets.compare_digest(candidate.encode(), expected.get_secret_value().encode())


def get_context(request: Request) -> AppContext:
    return request.app.state.context  # type: ignore[no-any-return]


_header_key = APIKeyHeader(name="X-API-Key", auto_error=False, description="the service API key")
_query_key = APIKeyQuery(name="key", auto_error=False, description="the service API key (for clients without headers)")


def require_api_key(
    request: Request,
    header: str | None = Security(_header_key),
    query: str | None = Security(_query_key),
) -> None:
    """REST dependency: 401 unless the API key is given in ``X-API-Key`` or ``?key=``."""
    if not get_context(request).key_matches(header if header is not None else query):
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="missing or wrong API key (send it in the X-API-Key header)",
            headers={"WWW-Authenticate": "APIKey"},
        )
