"""Lifecycle of the edge process: signals, readiness, a tick loop, graceful shutdown with a deadline.

Modelled on uvicorn's ``Server``/``Config`` split: the configuration is loaded and the application
wired elsewhere (``config.load_config``, ``builder.build_edge``); the :class:`Daemon` only owns
the lifecycle: startup, a 0.1 s tick loop for periodic duties (status line, metrics log, pages)
and a bounded graceful shutdown. systemd notifications go through :mod:`darkread.edge.notify`.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
from collections.abc import Iterator
from types import FrameType
from typing import Protocol

from darkread.edge.notify import Notifier

logger = logging.getLogger(__name__)


class Service(Protocol):
    """What the daemon runs: the wired edge application (:class:`darkread.edge.builder.Edge`)."""

    def startup(self) -> str: ...  # starts the threads (sensor open, model warm); returns a status line
    def tick(self) -> str | None: ...  # periodic duty; returns a status line or None
    def finished(self) -> bool: ...  # e.g. a replay reached its end
    def shutdown(self, timeout_s: float) -> bool: ...  # drain + flush; True when nothing was lost
    def verify(self) -> None: ...  # after a run that ended by itself: raise if it did not do its job


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
        handle_signals: bool = True,
    ) -> None:
        """``handle_signals`` False leaves SIGINT/SIGTERM to the caller (``darkread read`` keeps Ctrl-C a
        KeyboardInterrupt; the shutdown still drains)."""
        self.service = service
        self.handle_signals = handle_signals
        self.notifier = notifier or Notifier()
        self.tick_s = tick_s
        self.status_every_s = status_every_s
        self.shutdown_timeout_s = shutdown_timeout_s
        self.should_exit = threading.Event()
        self.force_exit = False

    def run(self) -> int:
        with self.capture_signals():
            try:
                status = self.service.startup()
                self.notifier.ready(status)
                logger.info("ready: %s", status)
                last_status = time.monotonic()
                while not self.should_exit.is_set():
                    line = self.service.tick()  # first: it raises what failed, also when that ended the run
                    if self.service.finished():
                        break
                    if line and time.monotonic() - last_status >= self.status_every_s:
                        self.notifier.status(line)
                        last_status = time.monotonic()
                    self.should_exit.wait(self.tick_s)
            finally:  # also on a failure: drain what can be drained, keep the rest spooled
                self.notifier.stopping()
                self.notifier.status("draining")
                clean = self.service.shutdown(0.0 if self.force_exit else self.shutdown_timeout_s)
        if not self.should_exit.is_set():
            self.service.verify()
        logger.info("stopped (%s)", "clean" if clean else "messages left in the spool")
        return 0 if clean else 3

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        if self.should_exit.is_set() and sig == signal.SIGINT:
            self.force_exit = True  # a second Ctrl-C skips the drain
        self.should_exit.set()

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        if not self.handle_signals or threading.current_thread() is not threading.main_thread():
            yield  # signals can only be handled in the main thread
            return
        original = {sig: signal.signal(sig, self.handle_exit) for sig in HANDLED_SIGNALS}
        try:
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)
