"""Secrets out of log lines: the one redaction helper the edge and the cloud share."""

from __future__ import annotations

import logging

import pytest

from darkread.core.redact import RedactKeys, redact, redact_handlers

KEY = "drk_0123abcd_s3cretS3cretS3cretS3cret"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (f"ws://127.0.0.1:8000/v1/stream?key={KEY}", "ws://127.0.0.1:8000/v1/stream?key=REDACTED"),
        (f"wss://a/v1/stream?device=g1&api_key={KEY}&x=1", "wss://a/v1/stream?device=g1&api_key=REDACTED&x=1"),
        (f"GET /v1/stream?token={KEY} HTTP/1.1", "GET /v1/stream?token=REDACTED HTTP/1.1"),
        (f"ws://a/s?access_token={KEY}", "ws://a/s?access_token=REDACTED"),
        (f"ws://glasses:{KEY}@cloud.example.org/v1/stream", "ws://glasses:REDACTED@cloud.example.org/v1/stream"),
        (f"to ws://a/s?key={KEY}, ws://b/s?key={KEY}", "to ws://a/s?key=REDACTED, ws://b/s?key=REDACTED"),
        (f"> X-API-Key: {KEY}", "> X-API-Key: REDACTED"),
        (f"authorization: Bearer {KEY}", "authorization: REDACTED"),
        ("ws://127.0.0.1:8000/v1/stream?device=g1", "ws://127.0.0.1:8000/v1/stream?device=g1"),
        ("spool 13 (lost 0), 42 keys", "spool 13 (lost 0), 42 keys"),
    ],
)
def test_redact_hides_secrets_and_keeps_the_rest(text: str, expected: str) -> None:
    assert redact(text) == expected


def test_a_handler_filter_redacts_every_logger_and_keeps_argument_shapes() -> None:
    records: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(self.format(record))

    logger = logging.getLogger("test_redact_handler")
    logger.propagate = False
    logger.setLevel(logging.DEBUG)
    handler = Collect()
    logger.addHandler(handler)
    try:
        redact_handlers(logger)
        redact_handlers(logger)  # once is enough
        assert sum(isinstance(f, RedactKeys) for f in handler.filters) == 1
        logger.warning("uplink connected to %s, %d to send", f"ws://h/s?key={KEY}", 13)
        logger.warning("lost: %s", ValueError(f"bad URI ws://h/s?key={KEY}"))
        logger.warning(f"ready: sending to ws://h/s?key={KEY}")
        logger.debug("> %s: %s", "X-API-Key", KEY)  # as the websockets client logs a header
    finally:
        logger.removeHandler(handler)
    assert records == ["uplink connected to ws://h/s?key=REDACTED, 13 to send", "lost: bad URI ws://h/s?key=REDACTED",
                       "ready: sending to ws://h/s?key=REDACTED", "> X-API-Key: REDACTED"]
    assert not any(KEY in line for line in records)
