"""The door every request passes first (pure ASGI, before any route reads a byte of the body).

In order: the Host name and the Origin (``origins.py``), then the API key for the routes that need
one (a caller without a valid key is answered 401 before its body is read), then the body's size
against its route's limit (413 without reading the rest; a chunked body is read at most up to the
limit). Refusals close the connection, so an announced body is never drained. Every HTTP answer
also carries ``X-Content-Type-Options: nosniff``.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from starlette.datastructures import Headers, QueryParams
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from darkread.proto.errors import CloseCode

from .auth import UNAUTHORIZED
from .origins import host_refusal, origin_refusal

if TYPE_CHECKING:
    from .context import AppContext

NOSNIFF = (b"x-content-type-options", b"nosniff")
# A question is at most 2,000 characters; as JSON with every character escaped (a non-BMP one is two
# \uXXXX escapes) that is under 24 kB.
ASK_BODY_BYTES = 32 * 1024
OTHER_BODY_BYTES = 1024  # routes that take no body
_ASK = re.compile(r"^/v1/sessions/[^/]+/ask$")
_KEYED = ("/v1/", "/ui/sessions", "/metrics")


def body_limit(method: str, path: str) -> int:
    """The largest body a route accepts, in bytes."""
    return ASK_BODY_BYTES if method == "POST" and _ASK.match(path) else OTHER_BODY_BYTES


def needs_key(scope: Scope, *, metrics_public: bool = False) -> bool:
    """HTTP routes holding data (the websocket may send its key in ``hello.token`` instead)."""
    path = scope["path"]
    return scope["type"] == "http" and path.startswith(_KEYED) and not (metrics_public and path.startswith("/metrics"))


class RequestGuard:
    """ASGI middleware; the app's ``state.context`` (set by the lifespan) holds keys and settings."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        context: AppContext = scope["app"].state.context
        headers = Headers(scope=scope)
        reason = self._origin_refusal(context, headers)
        if reason is not None:
            await _refuse(scope, receive, send, 403, reason, headers)
            return
        if scope["type"] == "websocket":
            await self.app(scope, receive, send)
            return
        if needs_key(scope, metrics_public=context.settings.metrics_public):
            key = headers.get("x-api-key") or QueryParams(scope.get("query_string", b"")).get("key")
            client = scope.get("client")
            principal = context.authenticate(key, client_host=client[0] if client else None)
            if principal is None:
                await _refuse(scope, receive, send, 401, UNAUTHORIZED, headers, {"WWW-Authenticate": "APIKey"})
                return
            scope.setdefault("state", {})["principal"] = principal
        limit = body_limit(scope["method"], scope["path"])
        declared = headers.get("content-length")
        too_big = f"a request body to {scope['path']} may be at most {limit} bytes"
        if declared is not None and (not declared.isdigit() or int(declared) > limit):
            await _refuse(scope, receive, send, 413, too_big, headers)
            return
        if "chunked" in headers.get("transfer-encoding", "").lower():
            body = await _read_at_most(receive, limit)
            if body is None:
                await _refuse(scope, receive, send, 413, too_big, headers)
                return
            receive = _replay(body, receive)
        await self.app(scope, receive, _with_nosniff(send))

    @staticmethod
    def _origin_refusal(context: AppContext, headers: Headers) -> str | None:
        settings = context.settings
        keyed = context.auth_configured()
        host = headers.get("host")
        return host_refusal(host, loopback_only=not keyed and not settings.insecure) or origin_refusal(
            headers.get("origin"), host, allowed=settings.allowed_origins, loopback_ok=not keyed
        )


def _with_nosniff(send: Send) -> Send:
    async def sending(message: Message) -> None:
        if message["type"] == "http.response.start":
            headers = list(message.get("headers", []))
            if not any(name.lower() == NOSNIFF[0] for name, _ in headers):
                headers.append(NOSNIFF)
            message = {**message, "headers": headers}
        await send(message)

    return sending


async def _read_at_most(receive: Receive, limit: int) -> bytes | None:
    """The whole body when it is at most ``limit`` bytes; None as soon as it is longer."""
    parts: list[bytes] = []
    size = 0
    while True:
        message = await receive()
        if message["type"] != "http.request":
            break
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > limit:
            return None
        parts.append(chunk)
        if not message.get("more_body", False):
            break
    return b"".join(parts)


def _replay(body: bytes, receive: Receive) -> Receive:
    sent = False

    async def replaying() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replaying


async def _refuse(scope: Scope, receive: Receive, send: Send, status: int, reason: str, headers: Headers,
                  extra: dict[str, str] | None = None) -> None:  # fmt: skip
    """One-line refusal; the connection closes when a body may follow (it is never read)."""
    if scope["type"] == "websocket":  # before accept: the client sees HTTP 403
        await send({"type": "websocket.close", "code": int(CloseCode.POLICY_VIOLATION), "reason": reason[:120]})
        return
    answer = dict(extra or {})
    if headers.get("content-length", "0") != "0" or "transfer-encoding" in headers:
        answer["Connection"] = "close"
    response = JSONResponse({"detail": reason}, status, headers=answer)
    await response(scope, receive, _with_nosniff(send))
