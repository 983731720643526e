"""Which Host names and web Origins may reach the service: pure rules, no I/O.

Without any key the service trusts its caller by address (loopback), so a web page the developer
opens must not reach it: by DNS rebinding (a foreign name resolving to 127.0.0.1, seen in
``Host``) or by a cross-origin request or websocket (seen in ``Origin``). With keys, a page may
call the API from the service's own origin or from an origin of ``DARKREAD_ALLOWED_ORIGINS``.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from .auth import is_loopback


def host_name(authority: str | None) -> str | None:
    """The name in a ``Host`` header or an origin's authority: ``[::1]:8000`` -> ``::1``."""
    if not authority:
        return None
    text = authority.strip().lower()
    if text.startswith("["):
        end = text.find("]")
        return text[1:end] if end > 0 else None
    return text.rsplit(":", 1)[0] if text.count(":") == 1 else text


def normalise_origin(origin: str) -> str:
    """``HTTPS://Reader.example/`` -> ``https://reader.example``; ValueError when it is no origin."""
    text = origin.strip().rstrip("/").lower()
    parts = urlsplit(text)
    if parts.scheme not in ("http", "https") or not parts.netloc or parts.path or parts.query:
        raise ValueError(f"{origin!r} is not a web origin (scheme://host[:port])")
    return text


def host_refusal(host: str | None, *, loopback_only: bool) -> str | None:
    """Why a request with this ``Host`` is refused, or None."""
    if loopback_only and not is_loopback(host_name(host)):
        return (f"Host {host!r} is not a loopback name: without an API key only localhost, 127.0.0.1 and [::1] "
                "are served")  # fmt: skip
    return None


def origin_refusal(origin: str | None, host: str | None, *, allowed: list[str], loopback_ok: bool) -> str | None:
    """Why a request from the web page at ``origin`` is refused, or None (no Origin: not a browser
    page's request, or a same-origin GET)."""
    if origin is None:
        return None
    try:
        normal = normalise_origin(origin)
    except ValueError:
        normal = None
    if normal is not None:
        authority = urlsplit(normal).netloc
        if normal in allowed or (host is not None and authority == host.strip().lower()):
            return None
        if loopback_ok and is_loopback(host_name(authority)):
            return None
    return f"Origin {origin!r} may not call this service (DARKREAD_ALLOWED_ORIGINS lists the web origins that may)"
