"""Websocket uplink to the cloud: sequence numbers, resume, cumulative acks, zero-loss spool.

The pipeline thread calls :meth:`Uplink.submit`; it assigns the next ``seq``, encodes the message
and writes it to the :class:`~darkread.edge.spool.Spool` *before* anything is sent, then wakes the
uplink's asyncio loop (its own thread). The loop connects, says ``hello`` with the session id,
drops from the spool whatever ``welcome.last_acked_seq`` covers, sends the rest in seq order
(at most ``max_in_flight`` unacknowledged) and deletes messages as cumulative acks arrive. Any
failure reconnects with exponential backoff and jitter and resends from the spool; the cloud drops
duplicates by seq. Nothing is lost unless the bounded spool overflows (counted as drops).

``url`` may list several cloud instances (comma-separated) sharing one database: a failed
connect or a closed connection moves to the next one at once, and backoff starts only after
every instance failed in a row. The next instance's welcome says what the database holds, so
the resume point is the same whichever instance answers.

URLs reach the log only redacted (``darkread.core.redact``): a ``?key=`` in them never lands in journald.
A spool that cannot be written (a full disk) ends the connection loop with a :class:`SpoolError`
the daemon raises; the thread never dies with a traceback.
"""

from __future__ import annotations

import asyncio
import logging
import random
import socket
import threading
import time
import uuid
from collections.abc import Awaitable, Iterator

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI

from darkread.core.redact import redact
from darkread.edge.config import UplinkConfig
from darkread.edge.errors import CloudRefusedError, SpoolError
from darkread.edge.spool import Spool
from darkread.edge.telemetry import EdgeMetrics
from darkread.proto.errors import CloseCode, ProtocolError
from darkread.proto.messages import (
    DEFAULT_MAX_MESSAGE_BYTES,
    Ack,
    Error,
    Frame,
    Gaze,
    Heartbeat,
    Hello,
    Page,
    Welcome,
    decode,
    encode,
)

logger = logging.getLogger(__name__)

Sequenced = Frame | Page | Gaze
LATENCY_TRACKED = 8192
MESSAGE_REJECTED_CODES = frozenset({
    CloseCode.MESSAGE_TOO_BIG, CloseCode.MALFORMED, CloseCode.BAD_MASK,
})  # the close names one bad message, not a bad connection  # seqs whose submit time is remembered for the event-to-wire latency
# the cloud will never take this stream: retrying cannot help, frames stay in the spool
FATAL_CODES = frozenset({
    CloseCode.POLICY_VIOLATION, CloseCode.FORBIDDEN, CloseCode.TAKEN_OVER, CloseCode.SESSION_MISMATCH,
    CloseCode.SEQ_GAP, CloseCode.SESSION_BUSY, CloseCode.VERSION_MISMATCH,
})


def split_urls(urls: str) -> tuple[str, ...]:
    """``"ws://a/v1/stream, ws://b/v1/stream"`` -> both URLs, in order (blanks dropped)."""
    return tuple(part.strip() for part in urls.split(",") if part.strip())


def placeholder(seq: int) -> bytes:
    """An empty gaze batch under ``seq``: stands in for a message the spool dropped, so the
    cloud sees contiguous seqs (it refuses gaps)."""
    return encode(Gaze(seq=seq, t_us=(), px=()))


def _messages(n: int) -> str:
    return f"{n} message" if n == 1 else f"{n} messages"


def backoff_delays(initial_s: float, max_s: float, rng: random.Random) -> Iterator[float]:
    """Exponential backoff with full jitter: uniform in [d/2, d], d doubling up to ``max_s``."""
    delay = initial_s
    while True:
        yield rng.uniform(delay / 2, delay)
        delay = min(max_s, delay * 2)


def default_device_id() -> str:
    name = "".join(c if c.isalnum() or c in "._-" else "-" for c in socket.gethostname())
    return (name if name[:1].isalnum() else "edge-" + name)[:128] or "edge"


class Uplink:
    """Owns the websocket client thread; thread-safe :meth:`submit`, graceful :meth:`stop`."""

    def __init__(
        self,
        settings: UplinkConfig,
        spool: Spool,
        metrics: EdgeMetrics | None = None,
        *,
        sensor_wh: tuple[int, int],
        fovea_hw: tuple[int, int],
    ) -> None:
        """``sensor_wh`` (the source's size) and ``fovea_hw`` (the model's window) go into ``hello``."""
        self.settings = settings
        self.sensor_wh = (int(sensor_wh[0]), int(sensor_wh[1]))
        self.fovea_hw = (int(fovea_hw[0]), int(fovea_hw[1]))
        self.spool = spool
        self.metrics = metrics or EdgeMetrics()
        self.metrics.spool_depth = lambda: spool.depth
        self.metrics.spool_lost = lambda: spool.dropped
        self.device_id = settings.device_id or default_device_id()
        # frames waiting in the spool belong to the spool's session: resume it; otherwise start anew
        pending_session = spool.session_id() if spool.depth else None
        self.session_id = settings.session_id or pending_session or f"{self.device_id}-{uuid.uuid4().hex[:12]}"
        spool.set_session_id(self.session_id)
        self.stream_id = spool.stream_id()
        self.acked_seq = -1
        self.connected = threading.Event()
        self.last_error = ""
        self.fatal_error = ""  # set when the cloud refused the stream for good, or the spool failed (no more retries)
        self.failure: BaseException | None = None  # what ended the connection loop other than the cloud (a SpoolError)
        self._submit_lock = threading.Lock()
        self._latency_lock = threading.Lock()
        self._submitted_at: dict[int, float] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._acked: asyncio.Event | None = None
        self._stopping = False
        self._drained = threading.Event()
        self._thread: threading.Thread | None = None
        self._rng = random.Random()
        self._connected_since: float | None = None
        self._rejected: tuple[int, str] | None = None  # close code and reason naming a bad message
        self._cloud_error = ""  # the last error message the cloud sent (the close reason is cut short)
        self._ack_progress = (-1, time.monotonic())  # (acked seq, when it last advanced)
        self.urls = split_urls(settings.url)
        if not self.urls:
            raise ValueError("uplink: no cloud URL given")
        self._url_index = 0

    @property
    def url(self) -> str:
        """The cloud instance the uplink uses now (or tries next)."""
        return self.urls[self._url_index]

    @property
    def shown_url(self) -> str:
        """:attr:`url` as logs and errors show it: any key in it redacted."""
        return redact(self.url)

    def left_behind(self) -> str:
        """What the spool still holds, in words ("" when nothing): kept on disk for the next start,
        or lost with an in-memory spool. Call it before the spool is closed."""
        n, dropped = self.spool.depth, self.spool.dropped
        evicted = f"{_messages(dropped)} {'was' if dropped == 1 else 'were'} dropped from the full spool" if dropped else ""
        if n == 0:
            return evicted
        also = f" ({evicted})" if evicted else ""
        if self.spool.in_memory:
            return (f"{_messages(n)} {'is' if n == 1 else 'are'} lost: the spool was in memory (--spool :memory:; "
                    f"without it they stay on disk and are sent after the next start){also}")
        return (f"{_messages(n)} {'stays' if n == 1 else 'stay'} in the spool {self.spool.where} and "
                f"{'is' if n == 1 else 'are'} sent after the next start{also}")

    def undelivered(self, drain_timeout_s: float) -> str:
        """Why the run ended with messages the cloud never acknowledged, and where they are."""
        if self.connected.is_set() or self.acked_seq >= 0:
            why = f"did not acknowledge every message within the {drain_timeout_s:g} s drain"
        else:
            why = "was not reached"
        last = f" ({self.last_error})" if self.last_error else ""
        return f"the cloud at {self.shown_url} {why}{last}: {self.left_behind()}"

    # -- called from other threads ---------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("uplink already started")
        ready = threading.Event()
        self._thread = threading.Thread(target=self._thread_main, args=(ready,), name="edge-uplink", daemon=True)
        self._thread.start()
        ready.wait()

    def submit(self, message: Sequenced, submitted_at: float | None = None) -> int:
        """Spool ``message`` under the next seq and schedule it for sending; returns the seq.

        ``submitted_at`` (``time.monotonic()``) is when the data behind the message arrived; the
        time from it until the message is handed to the socket is the event-to-wire latency.
        """
        with self._submit_lock:
            seq = self.spool.allocate_seq()
            payload = encode(message.numbered(seq))
            if submitted_at is not None:
                with self._latency_lock:
                    if len(self._submitted_at) >= LATENCY_TRACKED:
                        self._submitted_at.pop(next(iter(self._submitted_at)))
                    self._submitted_at[seq] = submitted_at
            self.spool.append(seq, payload)
        self._drained.clear()
        self._notify()
        return seq

    def wait_drained(self, timeout_s: float) -> bool:
        """Block until every spooled message is acknowledged (or the timeout)."""
        deadline = time.monotonic() + timeout_s
        while self.spool.depth > 0 and not self.fatal_error:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self._drained.wait(min(remaining, 0.05))
        return self.spool.depth == 0

    def stop(self, drain_timeout_s: float = 10.0) -> bool:
        """Flush (wait for acks up to the timeout), then close; True when the spool is empty."""
        drained = self.wait_drained(drain_timeout_s) if self._thread else self.spool.depth == 0
        self._stopping = True
        self._notify()
        if self._thread is not None:
            self._thread.join(timeout=max(2.0, self.settings.open_timeout_s + 1))
        if not drained:
            logger.warning("uplink stopped: %s", self.left_behind())
        return drained

    # -- the asyncio thread ------------------------------------------------------------------
    def _notify(self) -> None:
        loop, wake = self._loop, self._wake
        if loop is not None and wake is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(wake.set)
            except RuntimeError:  # loop closed between the check and the call
                pass

    def _thread_main(self, ready: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main(ready))
        except Exception as exc:  # a bug: end the run with it (the daemon raises it) instead of a dead thread
            logger.exception("uplink failed")
            self.failure = exc
            self._fail(f"uplink failed: {type(exc).__name__}: {exc}")
        finally:
            ready.set()
            loop.close()

    async def _main(self, ready: threading.Event) -> None:
        self._wake, self._acked = asyncio.Event(), asyncio.Event()
        ready.set()
        delays = backoff_delays(self.settings.backoff_initial_s, self.settings.backoff_max_s, self._rng)
        first = True
        failed_in_a_row = 0  # connections that ended without a welcome, across instances
        while not self._stopping and not self.fatal_error:
            if not first:
                self.metrics.add("reconnects")
            first = False
            self._connected_since = None
            url = self.url
            try:
                await self._connection(url)
            except InvalidStatus as exc:
                self.last_error = f"cloud refused the connection: HTTP {exc.response.status_code}"
                if exc.response.status_code in (401, 403):
                    self._fail(f"{self.last_error}: the API key is missing, wrong or lacks the stream scope")
                else:
                    logger.error("%s at %s (check the URL)", self.last_error, redact(url))
            except CloudRefusedError as exc:
                self.last_error = str(exc)
                if exc.code in FATAL_CODES:
                    self._fail(f"cloud refused session {self.session_id}: {exc.message}")
                else:
                    logger.warning("uplink to %s lost: %s", redact(url), self.last_error)
            except ConnectionClosed as exc:
                self.last_error = f"{type(exc).__name__}: {exc}"
                code, reason = (exc.rcvd.code, exc.rcvd.reason) if exc.rcvd is not None else (None, "")
                if code in FATAL_CODES:
                    self._fail(f"cloud refused session {self.session_id}: {self._cloud_error or reason}")
                else:
                    logger.warning("uplink to %s lost: %s", redact(url), self.last_error)
                if code in MESSAGE_REJECTED_CODES:
                    self._rejected = (code, exc.rcvd.reason)  # type: ignore[union-attr]  # dropped after the next welcome
            except (OSError, InvalidHandshake, TimeoutError, ProtocolError) as exc:
                why = str(exc) or (f"no welcome within {self.settings.open_timeout_s:g} s (the cloud is busy or unreachable)"
                                   if isinstance(exc, TimeoutError) else "")  # fmt: skip
                self.last_error = redact(f"{type(exc).__name__}: {why}")
                logger.warning("uplink to %s lost: %s", redact(url), self.last_error)
            except InvalidURI as exc:
                self.last_error = redact(str(exc))
                logger.error("uplink URL is not valid: %s", self.last_error)
            except SpoolError as exc:  # a full disk: acks cannot be recorded, retrying would resend for ever
                self.failure = exc
                self._fail(str(exc))
            finally:
                self.connected.clear()
            if self._stopping or self.fatal_error:
                break
            connected = self._connected_since is not None
            lasted = self._connected_since is not None and time.monotonic() - self._connected_since >= self.settings.stable_connection_s
            if lasted:
                # a connection that worked for a while: the next outage starts from a short delay again
                delays = backoff_delays(self.settings.backoff_initial_s, self.settings.backoff_max_s, self._rng)
            failed_in_a_row = 0 if connected else failed_in_a_row + 1
            if self._rejected is None:  # a rejected message is no reason to leave a working instance
                self._fail_over()
            if len(self.urls) > 1 and (lasted or (not connected and failed_in_a_row % len(self.urls) != 0)):
                continue  # the next instance may answer at once; back off only after a whole round failed
            await self._sleep_or_stop(next(delays))

    def _fail_over(self) -> None:
        """Move to the next cloud instance (a no-op with one URL)."""
        if len(self.urls) > 1:
            previous = self.url
            self._url_index = (self._url_index + 1) % len(self.urls)
            self.metrics.add("failovers")
            logger.warning("uplink fails over from %s to %s", redact(previous), self.shown_url)

    def _fail(self, reason: str) -> None:
        """Stop retrying: the cloud will not take this stream, or the spool cannot be written.
        Frames stay in the spool; how many is said once, when the run ends."""
        self.fatal_error = reason
        logger.error("%s; the uplink stops", reason)
        self._drained.set()

    async def _sleep_or_stop(self, delay_s: float) -> None:
        assert self._wake is not None
        deadline = time.monotonic() + delay_s
        while not self._stopping and (remaining := deadline - time.monotonic()) > 0:
            self._wake.clear()
            try:
                await asyncio.wait_for(self._wake.wait(), remaining)
            except TimeoutError:
                return

    async def _connection(self, url: str) -> None:
        s = self.settings
        headers = {"X-API-Key": s.api_key} if s.api_key else None
        async with connect(
            url, additional_headers=headers, open_timeout=s.open_timeout_s, max_size=DEFAULT_MAX_MESSAGE_BYTES,
            compression=None,  # messages are compressed already (proto/codecs.py): deflate again costs CPU, saves ~nothing
        ) as ws:
            hello = Hello(
                device_id=self.device_id,
                session_id=self.session_id,
                mode=s.mode,
                sensor=self.sensor_wh,
                fovea=self.fovea_hw,
                resume_from_seq=self.acked_seq if self.acked_seq >= 0 else None,
                stream_id=self.stream_id,
            )
            await ws.send(encode(hello))
            welcome = decode(await asyncio.wait_for(ws.recv(), s.open_timeout_s), max_bytes=DEFAULT_MAX_MESSAGE_BYTES)
            if isinstance(welcome, Error):
                raise CloudRefusedError(welcome.code, welcome.message)
            if not isinstance(welcome, Welcome):
                raise ConnectionError(f"expected welcome, got {welcome.TYPE}")
            if welcome.last_acked_seq > self.spool.last_allocated_seq:
                raise CloudRefusedError(CloseCode.FORBIDDEN, (
                    f"the cloud holds seqs up to {welcome.last_acked_seq} of session {self.session_id}, more than this "
                    f"spool ever numbered ({self.spool.last_allocated_seq}): another device streams to it"))
            self._on_ack(welcome.last_acked_seq)
            self._drop_rejected(welcome.last_acked_seq)
            self._connected_since = time.monotonic()
            self.connected.set()
            self.last_error = ""
            logger.info(
                "uplink connected to %s, session %s, cloud has up to seq %d, %d to send",
                redact(url), self.session_id, welcome.last_acked_seq, self.spool.depth,
            )
            try:
                await self._stream(ws, welcome)
            except SpoolError:
                # nothing reads the cloud's acks any more: a closing handshake would wait behind them
                # for the close timeout; the connection is given up anyway
                ws.transport.abort()
                raise

    async def _stream(self, ws: ClientConnection, welcome: Welcome) -> None:
        assert self._wake is not None and self._acked is not None
        receiver = asyncio.create_task(self._receive(ws))
        cursor = max(welcome.last_acked_seq, self.acked_seq)
        last_heartbeat = time.monotonic()
        self._ack_progress = (self.acked_seq, time.monotonic())
        try:
            while True:
                if receiver.done():
                    receiver.result()  # re-raises the connection error
                    return
                if self._stopping:
                    await ws.close()
                    return
                self._check_ack_progress(cursor)
                if cursor - self.acked_seq >= self.settings.max_in_flight:
                    self._acked.clear()
                    await self._wait_any(receiver, self._acked.wait(), 1.0)
                    continue
                self._wake.clear()
                limit = min(64, self.settings.max_in_flight - (cursor - self.acked_seq))
                batch = self.spool.pending(after_seq=cursor, limit=limit)
                for seq, payload in batch:
                    while cursor + 1 < seq:  # dropped from the spool (full, or rejected): keep seqs contiguous
                        await ws.send(placeholder(cursor + 1))
                        cursor += 1
                    if len(payload) > welcome.max_message_bytes:
                        logger.error("message seq %d (%d bytes) exceeds the cloud's limit; dropped", seq, len(payload))
                        self.spool.discard(seq)
                        payload = placeholder(seq)
                    await ws.send(payload)
                    cursor = seq
                    self._sent(seq, len(payload))
                if not batch:
                    if time.monotonic() - last_heartbeat >= self.settings.heartbeat_s:
                        await ws.send(encode(self._heartbeat()))
                        last_heartbeat = time.monotonic()
                    await self._wait_any(receiver, self._wake.wait(), min(self.settings.heartbeat_s, self.settings.ack_timeout_s / 2))
        finally:
            receiver.cancel()

    def _check_ack_progress(self, cursor: int) -> None:
        """Messages in flight and the ack not advancing for ``ack_timeout_s``: the connection is
        stuck (a cloud that stopped committing, a half-open socket), so reconnect and resend."""
        now = time.monotonic()
        if self.acked_seq != self._ack_progress[0] or cursor <= self.acked_seq:
            self._ack_progress = (self.acked_seq, now)
        elif now - self._ack_progress[1] > self.settings.ack_timeout_s:
            self.metrics.add("ack_timeouts")
            raise TimeoutError(f"no ack for {self.settings.ack_timeout_s:g} s with {cursor - self.acked_seq} "
                               "messages in flight")

    async def _wait_any(self, receiver: asyncio.Task[None], awaitable: Awaitable[object], timeout_s: float) -> None:
        waiter = asyncio.ensure_future(awaitable)
        try:
            await asyncio.wait({receiver, waiter}, timeout=timeout_s, return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiter.cancel()

    async def _receive(self, ws: ClientConnection) -> None:
        async for data in ws:
            if isinstance(data, str):
                raise ConnectionError("cloud sent a text message; expected binary msgpack")
            message = decode(data, max_bytes=DEFAULT_MAX_MESSAGE_BYTES)
            if isinstance(message, Ack):
                self._on_ack(message.seq)
            elif isinstance(message, Error):
                log = logger.error if message.fatal else logger.warning
                log("cloud error %d: %s", message.code, message.message)
                self.last_error = f"cloud error {message.code}: {message.message}"
                self._cloud_error = message.message
        raise ConnectionError("cloud closed the connection")

    def _drop_rejected(self, last_stored_seq: int) -> None:
        """The cloud closed because of one message (malformed, bad mask, too big). It stores in seq
        order, so that is the first one after what the next welcome says it has; resending it would
        fail forever."""
        if self._rejected is None:
            return
        code, reason = self._rejected
        self._rejected = None
        pending = self.spool.pending(after_seq=last_stored_seq, limit=1)
        if pending:
            seq = pending[0][0]
            self.spool.discard(seq)
            self.metrics.add("messages_rejected")
            logger.error("cloud rejected message seq %d (close %d: %s); dropped from the spool", seq, code, reason)

    def _on_ack(self, seq: int) -> None:
        if seq > self.spool.last_allocated_seq:
            raise CloudRefusedError(CloseCode.FORBIDDEN, f"the cloud acknowledged seq {seq}, which this edge never sent")
        if seq > self.acked_seq:
            removed = self.spool.ack(seq)
            self.metrics.add("messages_acked", removed)
            self.acked_seq = seq
        if self._acked is not None:
            self._acked.set()
        if self.spool.depth == 0:
            self._drained.set()

    def _sent(self, seq: int, n_bytes: int) -> None:
        self.metrics.add("messages_sent")
        self.metrics.add("bytes_sent", n_bytes)
        with self._latency_lock:
            submitted = self._submitted_at.pop(seq, None)
        if submitted is not None:
            self.metrics.observe_latency((time.monotonic() - submitted) * 1e3)

    def _heartbeat(self) -> Heartbeat:
        snap = self.metrics.totals
        return Heartbeat(
            t_us=time.time_ns() // 1000,
            stats={"spool_depth": float(self.spool.depth), "frames": float(snap["frames"]), "acked_seq": float(self.acked_seq)},
        )


__all__ = ["Uplink", "backoff_delays", "split_urls"]
