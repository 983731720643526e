"""sd_notify(3) without libsystemd: readiness, status lines and watchdog pings to systemd.

``READY=1`` is sent only once the sensor is open and the model is warm; ``WATCHDOG=1`` is sent from
the processing loop itself (the pipeline calls :meth:`Notifier.watchdog_tick`), so a stalled
pipeline misses pings and systemd restarts it.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Callable, Mapping

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
            sock.setblocking(False)  # never stall the processing loop on a full notify queue
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
