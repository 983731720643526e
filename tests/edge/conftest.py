"""Fixtures shared by the edge tests: a systemd notify socket to listen on."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass
class NotifySocket:
    """Where a test plays systemd: the datagram socket a ``Notifier`` sends to."""

    path: str
    sock: socket.socket

    def received(self) -> list[str]:
        """Every notification waiting on the socket."""
        out = []
        self.sock.settimeout(0.05)
        while True:
            try:
                out.append(self.sock.recv(4096).decode())
            except TimeoutError:
                return out


@pytest.fixture
def notify_socket(tmp_path: Path) -> Iterator[NotifySocket]:
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(1.0)
    yield NotifySocket(str(path), sock)
    sock.close()
