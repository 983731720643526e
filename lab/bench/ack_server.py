"""A loopback websocket endpoint that speaks just enough of the protocol to acknowledge every message.

It stands in for the cloud where only the edge is measured (the edge benchmark) or checked (the
edge tests): it answers ``hello`` with ``welcome`` (resuming after what it already stored for the
session), acknowledges each sequenced message, and remembers the hellos and the stored seqs.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from darkread.proto.messages import Ack, Hello, Welcome, decode, encode

MAX_BYTES = 1 << 22


class AckServer:
    """Runs on its own event loop thread; ``url`` is where the uplink connects."""

    def __init__(self) -> None:
        self.stored: dict[str, list[int]] = {}  # session id -> seqs acknowledged, in arrival order
        self.hellos: list[Any] = []
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="ack-server", daemon=True)
        self.thread.start()
        self.port = asyncio.run_coroutine_threadsafe(self._start(), self.loop).result(10)
        self.url = f"ws://127.0.0.1:{self.port}/v1/stream"

    async def _start(self) -> int:
        from websockets.asyncio.server import serve

        self.server = await serve(self._handle, "127.0.0.1", 0)
        return int(self.server.sockets[0].getsockname()[1])

    async def _handle(self, ws) -> None:

        hello = decode(await ws.recv(), max_bytes=MAX_BYTES)
        assert isinstance(hello, Hello)  # the uplink opens with hello
        self.hellos.append(hello)
        seqs = self.stored.setdefault(hello.session_id, [])
        last = seqs[-1] if seqs else -1
        await ws.send(encode(Welcome(session_id=hello.session_id, last_acked_seq=last, max_message_bytes=MAX_BYTES)))
        async for data in ws:
            seq = getattr(decode(data, max_bytes=MAX_BYTES), "seq", None)
            if seq is not None:
                seqs.append(seq)
                await ws.send(encode(Ack(seq=seq)))

    def close(self) -> None:
        async def stop() -> None:
            self.server.close()
            await self.server.wait_closed()

        asyncio.run_coroutine_threadsafe(stop(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()
