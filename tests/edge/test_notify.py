"""sd_notify datagrams and the watchdog cadence, against a real AF_UNIX socket."""

from __future__ import annotations

import os
import socket
from pathlib import Path

from darkread.edge.notify import Notifier, sd_notify


def test_sd_notify_sends_one_datagram(notify_socket) -> None:
    path, sock = notify_socket.path, notify_socket.sock
    assert sd_notify("READY=1\nSTATUS=hello", {"NOTIFY_SOCKET": path})
    assert sock.recv(4096) == b"READY=1\nSTATUS=hello"


def test_sd_notify_abstract_socket() -> None:
    name = f"darkread-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind("\0" + name)
        sock.settimeout(1.0)
        assert sd_notify("WATCHDOG=1", {"NOTIFY_SOCKET": "@" + name})
        assert sock.recv(4096) == b"WATCHDOG=1"


def test_sd_notify_without_systemd_is_a_noop(tmp_path: Path) -> None:
    assert not sd_notify("READY=1", {})
    assert not sd_notify("READY=1", {"NOTIFY_SOCKET": "relative/path"})
    assert not sd_notify("READY=1", {"NOTIFY_SOCKET": str(tmp_path / "missing.sock")})


def test_watchdog_pings_at_half_the_interval(notify_socket) -> None:
    path = notify_socket.path
    now = [100.0]
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"}, clock=lambda: now[0])
    assert notifier.watchdog_interval_s == 1.0
    assert notifier.watchdog_tick()
    now[0] += 0.5
    assert not notifier.watchdog_tick()
    now[0] += 0.6
    assert notifier.watchdog_tick()
    assert notify_socket.received() == ["WATCHDOG=1", "WATCHDOG=1"]


def test_watchdog_for_another_pid_is_ignored(notify_socket) -> None:
    path = notify_socket.path
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"})
    assert notifier.watchdog_interval_s is None
    assert not notifier.watchdog_tick()


def test_sd_notify_never_blocks_on_a_full_queue(notify_socket) -> None:
    path = notify_socket.path  # nobody reads: the kernel queue fills up
    results = [sd_notify("WATCHDOG=1", {"NOTIFY_SOCKET": path}) for _ in range(500)]
    assert results[0] is True
    assert results[-1] is False  # dropped, not stuck
