"""``WS /v1/stream``: authenticated ingest of frames and pages, acknowledged after commit.

Each connection is an explicit state machine::

    AWAIT_HELLO --hello--> STREAMING --frame/page/gaze/heartbeat--> STREAMING
         |                     |
         +--- bad input -------+--> CLOSED (error message, then close code with reason)

Two tasks per connection: the receiver decodes, validates and hands messages to the store
(which commits in groups); the sender awaits each commit in arrival order and sends its
cumulative ack. Every message to the client goes through the sender, so acks, errors and the
close never interleave. A failure closes only its own connection.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from enum import Enum, auto
from typing import Any

from starlette.websockets import WebSocket, WebSocketDisconnect

from darkread.proto.errors import (
    AuthenticationError,
    BadMaskError,
    CloseCode,
    MalformedMessageError,
    ProtocolError,
    UnexpectedMessageError,
)
from darkread.proto.messages import (
    Ack,
    Error,
    Frame,
    Gaze,
    Heartbeat,
    Hello,
    Message,
    NewPage,
    Page,
    Welcome,
    decode,
    encode,
)

from .context import AppContext
from .errors import StoreError
from .store import GazeRecord, PageBreak, PageRecord, SessionSpec, StoredFrame, WriteResult

log = logging.getLogger(__name__)


class StreamState(Enum):
    AWAIT_HELLO = auto()
    STREAMING = auto()
    CLOSED = auto()


@dataclass(frozen=True)
class _Pending:
    """A message handed to the store; the sender acks it once ``result`` resolves."""

    result: asyncio.Future[WriteResult]  # a task started on arrival, so writes queue in order
    kind: str
    session_id: str


@dataclass(frozen=True)
class _Close:
    code: int
    message: str


_Outgoing = Message | _Pending | _Close


def close_reason(message: str) -> str:
    """A websocket close reason must fit in 123 bytes of UTF-8."""
    return message.encode()[:120].decode(errors="ignore")


class StreamConnection:
    """Protocol state of one websocket: bytes in, things to send out. No socket I/O here."""

    def __init__(self, context: AppContext, *, authenticated: bool) -> None:
        self.context = context
        self.authenticated = authenticated
        self.state = StreamState.AWAIT_HELLO
        self.hello: Hello | None = None

    async def handle(self, data: bytes) -> _Outgoing | None:
        metrics = self.context.metrics
        metrics.bytes_received.inc(len(data))
        message = decode(data, max_bytes=self.context.settings.max_message_bytes)
        metrics.messages.labels(type=message.TYPE).inc()
        if self.state is StreamState.AWAIT_HELLO:
            return await self._on_hello(message)
        return self._on_streaming(message)

    async def _on_hello(self, message: Message) -> Welcome:
        if not isinstance(message, Hello):
            raise UnexpectedMessageError(f"expected hello as the first message, got {message.TYPE}")
        if not self.authenticated and not self.context.key_matches(message.token):
            raise AuthenticationError("missing or wrong API key (X-API-Key header, ?key= or hello.token)")
        spec = SessionSpec(message.session_id, message.device_id, message.mode, message.sensor, message.fovea)
        last_seq = await self.context.store.open_session(spec)
        self.hello = message
        self.state = StreamState.STREAMING
        log.info("session %s from %s: %s mode, resuming after seq %d", message.session_id, message.device_id,
                 message.mode, last_seq)  # fmt: skip
        return Welcome(
            session_id=message.session_id,
            last_acked_seq=last_seq,
            max_message_bytes=self.context.settings.max_message_bytes,
            features=("new_page",),
        )

    def _on_streaming(self, message: Message) -> _Pending | None:
        assert self.hello is not None  # noqa: S101 - state invariant, not input validation
        store, session_id = self.context.store, self.hello.session_id
        if isinstance(message, Frame):
            if self.hello.mode != "frames":
                raise UnexpectedMessageError("frame received but hello.mode is 'pages'")
            if message.shape != self.hello.fovea:
                raise BadMaskError(f"frame shape {message.shape} differs from hello.fovea {self.hello.fovea}")
            return _Pending(asyncio.ensure_future(store.add_frame(session_id, stored_frame(message))), "frame", session_id)
        if isinstance(message, Page):
            if self.hello.mode != "pages":
                raise UnexpectedMessageError("page received but hello.mode is 'frames'")
            record = PageRecord(message.seq, message.page_id, message.t_us, message.mask(), message.lines)
            return _Pending(asyncio.ensure_future(store.add_page(session_id, record)), "page", session_id)
        if isinstance(message, Gaze):
            record = GazeRecord(message.seq, message.t_us, message.px)
            return _Pending(asyncio.ensure_future(store.add_gaze(session_id, record)), "gaze", session_id)
        if isinstance(message, NewPage):
            if self.hello.mode != "frames":
                raise UnexpectedMessageError("new_page received but hello.mode is 'pages'")
            mark = PageBreak(message.seq, message.t_us)
            return _Pending(asyncio.ensure_future(store.add_page_break(session_id, mark)), "new_page", session_id)
        if isinstance(message, Heartbeat):
            log.debug("session %s heartbeat t_us=%d %s", session_id, message.t_us, message.stats)
            return None
        raise UnexpectedMessageError(f"{message.TYPE} is not allowed after hello")


def stored_frame(frame: Frame) -> StoredFrame:
    """The wire frame as the store keeps it: its frame record, seq, gaze angles and event count."""
    record = frame.record()
    return StoredFrame(
        record.frame_id, record.t_us, record.mask, record.origin, record.gaze_px,
        seq=frame.seq, gaze_rad=frame.gaze_rad, events_used=frame.events_used,
    )  # fmt: skip


async def stream_endpoint(websocket: WebSocket) -> None:
    context: AppContext = websocket.app.state.context
    metrics = context.metrics
    supplied = websocket.headers.get("x-api-key") or websocket.query_params.get("key")
    if supplied is not None and not context.key_matches(supplied):
        metrics.denied.inc()
        metrics.errors.labels(code=str(int(CloseCode.POLICY_VIOLATION))).inc()
        await websocket.close(code=CloseCode.POLICY_VIOLATION, reason="wrong API key")  # before accept: HTTP 403
        return
    await websocket.accept()
    metrics.connections.inc()
    metrics.active.inc()
    connection = StreamConnection(context, authenticated=supplied is not None or context.settings.api_key is None)
    outbox: asyncio.Queue[_Outgoing | None] = asyncio.Queue(maxsize=context.settings.max_in_flight)
    sender = asyncio.create_task(_send_loop(websocket, outbox, context))
    try:
        await _receive_loop(websocket, connection, outbox)
    finally:
        connection.state = StreamState.CLOSED
        if not sender.done():  # a sender that died cannot drain a full outbox
            await outbox.put(None)
        await sender
        metrics.active.dec()


async def _receive_loop(
    websocket: WebSocket, connection: StreamConnection, outbox: asyncio.Queue[_Outgoing | None]
) -> None:
    hello_timeout = connection.context.settings.hello_timeout_s
    while connection.state is not StreamState.CLOSED:
        try:
            if connection.state is StreamState.AWAIT_HELLO:
                event = await asyncio.wait_for(websocket.receive(), hello_timeout)
            else:
                event = await websocket.receive()
        except TimeoutError:
            await outbox.put(_Close(CloseCode.UNEXPECTED, f"no hello within {hello_timeout:g} s"))
            return
        except (WebSocketDisconnect, RuntimeError):
            return
        if event["type"] == "websocket.disconnect":
            return
        data = event.get("bytes")
        try:
            if data is None:
                raise MalformedMessageError("text messages are not part of the protocol; send binary msgpack")
            outgoing = await connection.handle(data)
        except ProtocolError as exc:
            log.info("closing stream (%d): %s", exc.close_code, exc)
            await outbox.put(_Close(int(exc.close_code), str(exc)))
            return
        except StoreError as exc:
            await outbox.put(_Close(CloseCode.INTERNAL_ERROR, f"could not open the session: {exc}"))
            return
        if outgoing is not None:
            await outbox.put(outgoing)


async def _send_loop(websocket: WebSocket, outbox: asyncio.Queue[_Outgoing | None], context: AppContext) -> None:
    """Send welcome/acks in arrival order; after a close, keep draining so commits are awaited."""
    metrics = context.metrics
    open_ = True
    while (item := await outbox.get()) is not None:
        reply: Any = item
        if isinstance(item, _Pending):
            try:
                result = await item.result
            except StoreError as exc:
                reply = _Close(CloseCode.INTERNAL_ERROR, f"could not store {item.kind}: {exc}")
            else:
                if result.stored:
                    if item.kind in ("frame", "new_page"):
                        context.live.notify(item.session_id)  # the session's pages take it up
                    if item.kind == "frame":
                        metrics.frames_stored.inc()
                    elif item.kind == "page":
                        metrics.pages_stored.inc()
                else:
                    metrics.duplicates.inc()
                reply = Ack(seq=result.last_seq)
        if not open_:
            continue
        try:
            if isinstance(reply, _Close):
                code = int(reply.code)
                metrics.errors.labels(code=str(code)).inc()
                await websocket.send_bytes(encode(Error(code=code, message=reply.message[:4096], fatal=True)))
                await websocket.close(code=code, reason=close_reason(reply.message))
                open_ = False
            else:
                await websocket.send_bytes(encode(reply))
        except (WebSocketDisconnect, RuntimeError, OSError):
            open_ = False  # the client left; remaining commits still finish
