"""Lifecycle of the edge process: signals, systemd notify/watchdog, graceful shutdown.

Modelled on uvicorn's ``Server``: one object owns startup, a 0.1 s tick loop for periodic duties
(status line, metrics log) and a bounded graceful shutdown. ``READY=1`` is sent only once the
sensor is open and the model is warm; ``WATCHDOG=1`` is sent from the processing loop itself (the
pipeline calls :meth:`Notifier.watchdog_tick`), so a stalled pipeline misses pings and systemd
restarts it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from types import FrameType
from typing import Protocol

logger = logging.getLogger(__name__)


def sd_notify(state: str, environ: Mapping[str, str] | None = None) -> bool:
    """Send one sd_notify(3) datagram (``READY=1``, ``STATUS=...``); False when not under systemd."""
    address = (os.environ if environ is None else environ).get("NOTIFY_SOCKET", "")
    if not address or address[0] not in "/@":
        return False
    if address[0] == "@":  # abstract namespace socket
        address = "\0" + address[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
            sock.connect(address)
            sock.sendall(state.encode("utf-8"))
    except OSError as exc:
        logger.debug("sd_notify(%r) failed: %s", state, exc)
        return False
    return True


class Notifier:
    """systemd state notifications; watchdog pings at half of ``$WATCHDOG_USEC``."""

    def __init__(self, environ: Mapping[str, str] | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self._environ = dict(os.environ if environ is None else environ)
        self._clock = clock
        usec = self._environ.get("WATCHDOG_USEC", "")
        pid = self._environ.get("WATCHDOG_PID", "")
        enabled = usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid()))
        self.watchdog_interval_s: float | None = int(usec) / 2e6 if enabled else None
        self._last_ping = float("-inf")

    def notify(self, state: str) -> bool:
        return sd_notify(state, self._environ)

    def ready(self, status: str = "") -> None:
        self.notify("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def status(self, text: str) -> None:
        self.notify(f"STATUS={text}")

    def stopping(self) -> None:
        self.notify("STOPPING=1")

    def watchdog_tick(self) -> bool:
        """Ping the watchdog when due; call from the loop whose liveness matters."""
        if self.watchdog_interval_s is None:
            return False
        now = self._clock()
        if now - self._last_ping < self.watchdog_interval_s:
            return False
        self._last_ping = now
        return self.notify("WATCHDOG=1")


class Service(Protocol):
    """What the daemon runs: the wired edge application (see ``darkread.edge.cli``)."""

    def startup(self) -> str: ...  # opens the sensor, warms the model; returns a status line
    def tick(self) -> str | None: ...  # periodic duty; returns a status line or None
    def finished(self) -> bool: ...  # e.g. a replay reached its end
    def shutdown(self, timeout_s: float) -> bool: ...  # drain + flush; True when nothing was lost


HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Daemon:
    """Runs a :class:`Service` until it finishes or a signal asks it to stop."""

    def __init__(
        self,
        service: Service,
        notifier: Notifier | None = None,
        tick_s: float = 0.1,
        status_every_s: float = 5.0,
        shutdown_timeout_s: float = 10.0,
    ) -> None:
        self.service = service
        self.notifier = notifier or Notifier()
        self.tick_s = tick_s
        self.status_every_s = status_every_s
        self.shutdown_timeout_s = shutdown_timeout_s
        self.should_exit = threading.Event()
        self.force_exit = False

    def run(self) -> int:
        with self.capture_signals():
            status = self.service.startup()
            self.notifier.ready(status)
            logger.info("ready: %s", status)
            last_status = time.monotonic()
            while not self.should_exit.is_set() and not self.service.finished():
                line = self.service.tick()
                if line and time.monotonic() - last_status >= self.status_every_s:
                    self.notifier.status(line)
                    logger.info("%s", line)
                    last_status = time.monotonic()
                self.should_exit.wait(self.tick_s)
            self.notifier.stopping()
            self.notifier.status("draining")
            clean = self.service.shutdown(0.0 if self.force_exit else self.shutdown_timeout_s)
        logger.info("stopped (%s)", "clean" if clean else "messages left in the spool")
        return 0 if clean else 3

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        if self.should_exit.is_set() and sig == signal.SIGINT:
            self.force_exit = True  # a second Ctrl-C skips the drain
        self.should_exit.set()

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield  # signals can only be handled in the main thread
            return
        original = {sig: signal.signal(sig, self.handle_exit) for sig in HANDLED_SIGNALS}
        try:
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)
