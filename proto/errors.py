"""Errors of the wire protocol and the websocket close codes they map to.

Every error carries ``close_code`` so the server can close the websocket with the right code and
the error's message as the reason. They sit under ``DarkreadError``; the whole tree, with each
error's close code, is drawn in ``darkread/core/errors.py``.
"""

from __future__ import annotations

from enum import IntEnum

from darkread.core.errors import DarkreadError


class CloseCode(IntEnum):
    """Websocket close codes used by ``/v1/stream`` (RFC 6455 range plus 4000-4999 private)."""

    NORMAL = 1000  # the client said goodbye, or the server shuts down
    GOING_AWAY = 1001  # server shutting down; reconnect later and resume
    POLICY_VIOLATION = 1008  # missing or wrong API key
    MESSAGE_TOO_BIG = 1009  # a message larger than welcome.max_message_bytes
    INTERNAL_ERROR = 1011  # the server could not store a message; reconnect and resume
    MALFORMED = 4400  # undecodable or invalid message
    UNEXPECTED = 4401  # a valid message that is not allowed now (e.g. frame before hello)
    VERSION_MISMATCH = 4409  # hello.v differs from the server's protocol version
    BAD_MASK = 4422  # mask shape/bit length wrong, or frame shape differs from hello.fovea
    FORBIDDEN = 4403  # the key may not do this: scope, another device's id or session
    TAKEN_OVER = 4408  # a newer connection of the same stream took the session over
    SESSION_MISMATCH = 4412  # hello's mode or geometry differs from the existing session's
    SEQ_GAP = 4416  # a seq that does not follow the last one (a gap, or a wild value)
    SESSION_BUSY = 4423  # another stream is connected to this session


class ProtocolError(DarkreadError):
    """A message that cannot be accepted; ``close_code`` tells the server how to close."""

    close_code: CloseCode = CloseCode.MALFORMED


class MessageTooLargeError(ProtocolError):
    close_code = CloseCode.MESSAGE_TOO_BIG


class MalformedMessageError(ProtocolError):
    close_code = CloseCode.MALFORMED


class UnknownMessageTypeError(ProtocolError):
    close_code = CloseCode.MALFORMED


class InvalidFieldError(ProtocolError):
    close_code = CloseCode.MALFORMED


class BadMaskError(InvalidFieldError):
    close_code = CloseCode.BAD_MASK


class VersionMismatchError(ProtocolError):
    close_code = CloseCode.VERSION_MISMATCH


class UnexpectedMessageError(ProtocolError):
    close_code = CloseCode.UNEXPECTED


class AuthenticationError(ProtocolError):
    close_code = CloseCode.POLICY_VIOLATION


class ForbiddenError(ProtocolError):
    close_code = CloseCode.FORBIDDEN


class SessionMismatchError(ProtocolError):
    close_code = CloseCode.SESSION_MISMATCH


class SeqGapError(ProtocolError):
    close_code = CloseCode.SEQ_GAP


class SessionBusyError(ProtocolError):
    close_code = CloseCode.SESSION_BUSY
