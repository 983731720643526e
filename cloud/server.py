"""Run the service in a background thread on a free port (benchmarks, tests, ``darkread read``)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypedDict

import uvicorn
from fastapi import FastAPI

from .errors import ServiceStartError


class WebsocketOptions(TypedDict):
    ws_per_message_deflate: bool


# Masks and views arrive compressed (zlib, PNG: proto/codecs.py); permessage-deflate on top of them
# costs CPU on both ends for a few bytes, so the service never negotiates it.
WEBSOCKET_OPTIONS: WebsocketOptions = {"ws_per_message_deflate": False}

@dataclass(frozen=True)
class RunningServer:
    app: FastAPI
    host: str
    port: int

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://{self.host}:{self.port}/v1/stream"


@contextmanager
def serve_in_thread(
    app: FastAPI, *, host: str = "127.0.0.1", port: int = 0, ws_max_size: int = 16 * 1024 * 1024, timeout_s: float = 15
) -> Iterator[RunningServer]:
    """Start uvicorn with ``app`` (port 0 = a free one), yield once it listens, stop on exit."""
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", ws_max_size=ws_max_size, lifespan="on",
                            log_config=None,  # uvicorn logs through darkread's handler: one format for every line
                            **WEBSOCKET_OPTIONS)  # fmt: skip
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name="darkread-cloud", daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout_s
    while not server.started:
        if not thread.is_alive():
            raise ServiceStartError("the cloud service failed to start (see the log above)")
        if time.monotonic() > deadline:
            server.should_exit = True
            raise ServiceStartError(f"the cloud service did not start within {timeout_s:g} s")
        time.sleep(0.01)
    bound_port = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield RunningServer(app, host, bound_port)
    finally:
        server.should_exit = True
        thread.join(timeout=timeout_s)
