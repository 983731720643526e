"""``WS /v1/stream``: authenticated ingest of frames and pages, acknowledged after commit.

A session belongs to the stream that opened it (device id, and the ``hello.stream_id`` naming
its spool, i.e. its seq space). While a connection streams a session, a hello from another
stream is refused (4423 SESSION_BUSY); a hello from the same stream (a reconnect after a
half-open drop) takes the session over and the old connection is closed with 4408 TAKEN_OVER.
After the owner left, another device or stream is refused (4403), and no hello may change the
session's mode or geometry (4412). Seqs continue contiguously from ``welcome.last_acked_seq``:
a gap or a wild value closes with 4416 and is never stored.

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
    CloseCode,
    ForbiddenError,
    MalformedMessageError,
    ProtocolError,
    SeqGapError,
    SessionBusyError,
    SessionMismatchError,
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
    View,
    Welcome,
    check_view_shape,
    content_version,
    decode,
    encode,
)

from .auth import Principal, Scope
from .context import AppContext
from .errors import SessionOwnedError, SessionShapeError
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
    shed_level: int = 0  # a view the glasses made while shedding work (counted once stored)


@dataclass(frozen=True)
class _Close:
    code: int
    message: str


_Outgoing = Message | _Pending | _Close


def store_failure(context: AppContext, kind: str, exc: BaseException) -> str:
    """Count and log (once) a failed store path; the close reason naming it."""
    name = type(exc).__name__
    context.metrics.store_failures.labels(error=name).inc()
    log.error("closing stream (%d): could not store %s: %s: %s", CloseCode.INTERNAL_ERROR, kind, name, exc)
    return f"could not store {kind}: {name}: {exc}"


def close_reason(message: str) -> str:
    """A websocket close reason must fit in 123 bytes of UTF-8."""
    return message.encode()[:120].decode(errors="ignore")


class StreamConnection:
    """Protocol state of one websocket: bytes in, things to send out. No socket I/O here."""

    def __init__(self, context: AppContext, *, principal: Principal | None, client_host: str | None = None) -> None:
        self.context = context
        self.principal = principal  # None: not yet authenticated (the key may come in hello.token)
        self.client_host = client_host
        self.state = StreamState.AWAIT_HELLO
        self.hello: Hello | None = None
        self.high_water = -1  # highest seq handed to the store on this connection (contiguity)
        self.receiver: asyncio.Task[None] | None = None  # cancelled when another connection takes over
        self.taken_over = False

    def release(self) -> None:
        """The connection ended: the session is free for its next connection."""
        if self.hello is not None and self.context.live.get(self.hello.session_id) is self:
            del self.context.live[self.hello.session_id]

    def _claim(self, hello: Hello) -> None:
        """Become the session's live connection: refuse another stream, take over from our own."""
        live = self.context.live.get(hello.session_id)
        if live is not None and live is not self:
            assert live.hello is not None  # only connections past hello are live
            if (live.hello.device_id, live.hello.stream_id) != (hello.device_id, hello.stream_id):
                raise SessionBusyError(f"session {hello.session_id!r} is being streamed by another connection")
            live.taken_over = True
            if live.receiver is not None:
                live.receiver.cancel()
            log.info("session %s: a newer connection of stream %s takes over", hello.session_id, hello.stream_id)
        self.context.live[hello.session_id] = self

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
        if self.principal is None:
            self.principal = self.context.authenticate(message.token, client_host=self.client_host)
        if self.principal is None:
            raise AuthenticationError("missing or wrong API key (X-API-Key header, ?key= or hello.token)")
        if not self.principal.can(Scope.STREAM):
            raise ForbiddenError("this key lacks the 'stream' scope")
        if self.principal.device is not None and self.principal.device != message.device_id:
            raise ForbiddenError(f"this key belongs to device {self.principal.device!r}, not {message.device_id!r}")
        self._claim(message)
        self.hello = message
        try:
            last_seq = await self.context.store.open_session(session_spec(message))
        except SessionOwnedError as exc:
            self.release()
            raise ForbiddenError(str(exc)) from None
        except SessionShapeError as exc:
            self.release()
            raise SessionMismatchError(str(exc)) from None
        except BaseException:
            self.release()
            raise
        self.high_water = last_seq
        self.state = StreamState.STREAMING
        log.info("session %s from %s: %s mode, resuming after seq %d", message.session_id, message.device_id,
                 message.mode, last_seq)  # fmt: skip
        return Welcome(
            session_id=message.session_id,
            last_acked_seq=last_seq,
            max_message_bytes=self.context.settings.max_message_bytes,
            v=message.v,  # a version 1 client gets a version 1 answer
            features=("new_page",),
        )

    def _contiguous(self, seq: int) -> None:
        """A seq after the high-water mark must be the next one; at or below it is a duplicate."""
        expected = self.high_water + 1
        if seq > expected:
            raise SeqGapError(f"seq {seq} does not follow seq {self.high_water}: expected {expected} "
                              "(seqs continue contiguously from welcome.last_acked_seq)")
        self.high_water = max(self.high_water, seq)

    def _on_streaming(self, message: Message) -> _Pending | None:
        assert self.hello is not None  # state invariant, not input validation
        store, session_id = self.context.store, self.hello.session_id
        needs = content_version(message)
        if self.hello.v < needs:
            raise UnexpectedMessageError(f"{message.TYPE} with version {needs} content in a version {self.hello.v} session")
        if isinstance(message, Frame | View | Page | Gaze | NewPage):
            self._contiguous(message.seq)
        if isinstance(message, Frame | View):  # a fixation's fused view: stored with its levels and frame count
            if self.hello.mode != "frames":
                raise UnexpectedMessageError(f"{message.TYPE} received but hello.mode is 'pages'")
            check_view_shape(message, self.hello.fovea, self.hello.v)
            stored = stored_frame(message)
            return _Pending(asyncio.ensure_future(store.add_frame(session_id, stored)), "frame", session_id, stored.shed_level)
        if isinstance(message, Page):
            if self.hello.mode != "pages":
                raise UnexpectedMessageError("page received but hello.mode is 'frames'")
            record = PageRecord(message.seq, message.page_id, message.t_us, message.mask(), message.lines)
            return _Pending(asyncio.ensure_future(store.add_page(session_id, record)), "page", session_id)
        if isinstance(message, Gaze):
            gaze = GazeRecord(message.seq, message.t_us, message.px)
            return _Pending(asyncio.ensure_future(store.add_gaze(session_id, gaze)), "gaze", session_id)
        if isinstance(message, NewPage):
            if self.hello.mode != "frames":
                raise UnexpectedMessageError("new_page received but hello.mode is 'pages'")
            mark = PageBreak(message.seq, message.t_us)
            return _Pending(asyncio.ensure_future(store.add_page_break(session_id, mark)), "new_page", session_id)
        if isinstance(message, Heartbeat):
            log.debug("session %s heartbeat t_us=%d %s", session_id, message.t_us, message.stats)
            return None
        raise UnexpectedMessageError(f"{message.TYPE} is not allowed after hello")


def session_spec(hello: Hello) -> SessionSpec:
    """What the store keeps of a hello: the session, its owner (device and stream) and geometry."""
    return SessionSpec(hello.session_id, hello.device_id, hello.mode, (hello.sensor[0], hello.sensor[1]), (hello.fovea[0], hello.fovea[1]),
                       stream_id=hello.stream_id or "")  # fmt: skip


def stored_frame(frame: Frame | View) -> StoredFrame:
    """The wire frame (or fused view) as the store keeps it: its frame record (a view's with its
    grey levels and frame count), seq, gaze angles and event count."""
    record = frame.record()
    return StoredFrame(
        record.frame_id, record.t_us, record.mask, record.origin, record.gaze_px,
        seq=frame.seq, gaze_rad=frame.gaze_rad, events_used=frame.events_used,
        levels=record.levels, n_levels=record.n_levels, frames=record.frames, scene_px=record.scene_px,
        shed_level=record.shed_level, light_lux=record.light_lux,
    )  # fmt: skip


async def stream_endpoint(websocket: WebSocket) -> None:
    context: AppContext = websocket.app.state.context
    metrics = context.metrics
    supplied = websocket.headers.get("x-api-key") or websocket.query_params.get("key")
    client_host = websocket.client.host if websocket.client else None
    principal = context.authenticate(supplied, client_host=client_host) if supplied is not None else None
    if supplied is not None and principal is None:
        metrics.denied.inc()
        metrics.errors.labels(code=str(int(CloseCode.POLICY_VIOLATION))).inc()
        await websocket.close(code=CloseCode.POLICY_VIOLATION, reason="wrong API key")  # before accept: HTTP 403
        return
    await websocket.accept()
    metrics.connections.inc()
    metrics.active.inc()
    if principal is None and not context.auth_configured():
        principal = context.authenticate(None, client_host=client_host)  # loopback without keys
    connection = StreamConnection(context, principal=principal, client_host=client_host)
    outbox: asyncio.Queue[_Outgoing | None] = asyncio.Queue(maxsize=context.settings.max_in_flight)
    sender = asyncio.create_task(_send_loop(websocket, outbox, connection))
    connection.receiver = asyncio.create_task(_receive_loop(websocket, connection, outbox))
    try:
        try:
            await connection.receiver
        except asyncio.CancelledError:
            task = asyncio.current_task()  # (this coroutine's: never None here)
            if not connection.taken_over or (task is not None and task.cancelling()):
                raise
            await outbox.put(_Close(CloseCode.TAKEN_OVER, "a newer connection of this stream took the session over"))
    finally:
        connection.release()
        connection.state = StreamState.CLOSED
        try:
            if not sender.done():  # a sender that died cannot drain a full outbox
                await outbox.put(None)
            await sender
        finally:
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
        if event["type"] == "websocket.disconnect" or connection.state is StreamState.CLOSED:
            return  # the client left, or a store failure closed the connection meanwhile
        data = event.get("bytes")
        try:
            if data is None:
                raise MalformedMessageError("text messages are not part of the protocol; send binary msgpack")
            outgoing = await connection.handle(data)
        except ProtocolError as exc:
            log.info("closing stream (%d): %s", exc.close_code, exc)
            await outbox.put(_Close(int(exc.close_code), str(exc)))
            return
        except Exception as exc:  # any failure of the store path ends this connection
            await outbox.put(_Close(CloseCode.INTERNAL_ERROR, store_failure(connection.context, "message", exc)))
            return
        if outgoing is not None:
            await outbox.put(outgoing)


async def _send_loop(websocket: WebSocket, outbox: asyncio.Queue[_Outgoing | None], connection: StreamConnection) -> None:
    """Send welcome/acks in arrival order; after a close, keep draining so commits are awaited."""
    context = connection.context
    metrics = context.metrics
    open_ = True
    while (item := await outbox.get()) is not None:
        reply: Any = item
        if isinstance(item, _Pending):
            try:
                result = await item.result
            except Exception as exc:  # not only StoreError: IntegrityError, OSError, ...
                if connection.state is not StreamState.CLOSED:
                    connection.state = StreamState.CLOSED  # the receiver hands nothing more to the store
                    reply = _Close(CloseCode.INTERNAL_ERROR, store_failure(context, item.kind, exc))
                else:
                    continue  # a later message of a connection that already failed
            else:
                if result.stored:
                    if item.kind in ("frame", "new_page"):
                        context.pages.notify(item.session_id)  # the session's pages take it up
                    if item.kind == "frame":
                        metrics.frames_stored.inc()
                        if item.shed_level:
                            metrics.views_shed.labels(level=str(item.shed_level)).inc()
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
