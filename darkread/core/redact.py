"""Secrets out of log lines: API keys in URL queries, passwords in URL user parts, key headers.

The edge logs the cloud URL it streams to (which may carry ``?key=``, e.g. in a systemd unit) and
the cloud's web server logs request paths with their query string; both go through here, so no key
reaches a log, a journal or a status line. Pure: the standard library only.
"""

from __future__ import annotations

import contextlib
import logging
import re

REDACTED = "REDACTED"

# ``?key=...``, ``&api_key=...``, ``?token=...``, ``?access_token=...``: any query parameter whose
# name says it is a secret, up to the next parameter, blank or quote
_SECRET_IN_QUERY = re.compile(
    r"((?:^|[?&;])[\w.-]*(?:key|token|secret|password|passwd|auth)[\w.-]*=)[^&;#,\s\"']+", re.IGNORECASE
)
# ``ws://user:password@host``: the password of a URL's user part
_PASSWORD_IN_URL = re.compile(r"(://[^/\s:@]*:)[^/\s@]+@")
# ``X-API-Key: ...`` and its kin, as a websocket library logs the headers it sends at debug level
_SECRET_HEADER = re.compile(r"\b((?:x-api-key|authorization|proxy-authorization|cookie|set-cookie):[ \t]*)[^\r\n]+",
                            re.IGNORECASE)


def redact(text: str) -> str:
    """``text`` with every secret a URL or a logged header in it carries replaced by ``REDACTED``."""
    text = _SECRET_IN_QUERY.sub(rf"\1{REDACTED}", text)
    text = _PASSWORD_IN_URL.sub(rf"\1{REDACTED}@", text)
    return _SECRET_HEADER.sub(rf"\1{REDACTED}", text)


class RedactKeys(logging.Filter):
    """Logger or handler filter: no key from a URL ever reaches a log line."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):  # the tuple keeps its shape: uvicorn's access formatter unpacks it
            record.args = tuple(_redacted_arg(a) for a in record.args)
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        with contextlib.suppress(TypeError, ValueError):  # a malformed record is logging's to report
            message = record.getMessage()
            clean = redact(message)
            if clean != message:  # a secret spread over several arguments ("> %s: %s", header, value)
                record.msg, record.args = clean, ()
        return True


def _redacted_arg(arg: object) -> object:
    """A string argument redacted; any other (an exception naming a URL) as its redacted text
    when it carries a secret, else unchanged (``%d`` still gets its number)."""
    if isinstance(arg, str):
        return redact(arg)
    if isinstance(arg, int | float):
        return arg
    text = str(arg)
    clean = redact(text)
    return arg if clean == text else clean


def redact_handlers(logger: logging.Logger | None = None) -> None:
    """Put :class:`RedactKeys` on every handler of ``logger`` (the root logger by default), so the
    records of every library that logs through them (websockets, uvicorn) are redacted too."""
    for handler in (logger or logging.getLogger()).handlers:
        if not any(isinstance(f, RedactKeys) for f in handler.filters):
            handler.addFilter(RedactKeys())


__all__ = ["REDACTED", "RedactKeys", "redact", "redact_handlers"]
