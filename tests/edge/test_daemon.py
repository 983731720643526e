"""The daemon's lifecycle: startup, ticks, notifications, signals and a graceful shutdown."""

from __future__ import annotations

import os
import threading

import pytest

from darkread.edge.daemon import Daemon
from darkread.edge.errors import RunError
from darkread.edge.notify import Notifier


class FakeService:
    def __init__(self, ticks_until_finished: int | None = None) -> None:
        self.calls: list[str] = []
        self.ticks = 0
        self.ticks_until_finished = ticks_until_finished

    def startup(self) -> str:
        self.calls.append("startup")
        return "sensor open, model warm"

    def tick(self) -> str | None:
        self.ticks += 1
        return f"tick {self.ticks}"

    def finished(self) -> bool:
        return self.ticks_until_finished is not None and self.ticks >= self.ticks_until_finished

    def shutdown(self, timeout_s: float) -> bool:
        self.calls.append(f"shutdown {timeout_s}")
        return True

    def verify(self) -> None:
        self.calls.append("verify")


class CrashedReplay(FakeService):
    """The replay thread died: the source reports finished, and the failure waits in tick()."""

    def tick(self) -> str | None:
        raise RunError("event source failed: CorruptRawError at byte 42")

    def finished(self) -> bool:
        return True


def test_a_replay_that_crashed_is_not_reported_as_finished() -> None:
    service = CrashedReplay()
    with pytest.raises(RunError, match="byte 42"):
        Daemon(service, Notifier({}), tick_s=0.001).run()
    assert service.calls == ["startup", "shutdown 10.0"]  # still drained what it could


def test_daemon_runs_until_service_finishes_and_notifies(notify_socket) -> None:
    path = notify_socket.path
    service = FakeService(ticks_until_finished=3)
    daemon = Daemon(service, Notifier({"NOTIFY_SOCKET": path}), tick_s=0.001, status_every_s=0.0)
    assert daemon.run() == 0
    assert service.calls == ["startup", "shutdown 10.0", "verify"]
    messages = notify_socket.received()
    assert messages[0] == "READY=1\nSTATUS=sensor open, model warm"
    assert "STATUS=tick 1" in messages
    assert messages[-2:] == ["STOPPING=1", "STATUS=draining"]


def test_daemon_should_exit_from_another_thread_drains() -> None:
    service = FakeService()
    daemon = Daemon(service, Notifier({}), tick_s=0.001)
    threading.Timer(0.05, daemon.should_exit.set).start()
    assert daemon.run() == 0
    assert service.calls[-1] == "shutdown 10.0"


class SignalledAtStartup(FakeService):
    """Sends SIGTERM to this process once the daemon runs (its handler is installed by then: a timer
    started before ``run()`` could fire first on a busy host and end the test process)."""

    def startup(self) -> str:
        threading.Timer(0.05, os.kill, args=(os.getpid(), 15)).start()
        return super().startup()


def test_sigterm_stops_the_daemon_gracefully() -> None:
    service = SignalledAtStartup()
    daemon = Daemon(service, Notifier({}), tick_s=0.001)
    assert daemon.run() == 0
    assert service.calls == ["startup", "shutdown 10.0"]


def test_signals_can_stay_with_the_caller() -> None:
    """``darkread read`` keeps Ctrl-C a KeyboardInterrupt: the daemon installs no handler, yet drains."""
    import signal

    seen = []

    class Recording(FakeService):
        def tick(self) -> str | None:
            seen.append(signal.getsignal(signal.SIGINT))
            return super().tick()

    service = Recording(ticks_until_finished=2)
    before = signal.getsignal(signal.SIGINT)
    assert Daemon(service, Notifier({}), tick_s=0.001, handle_signals=False).run() == 0
    assert seen and all(handler is before for handler in seen)
    assert service.calls == ["startup", "shutdown 10.0", "verify"]
    handled = Recording(ticks_until_finished=1)
    Daemon(handled, Notifier({}), tick_s=0.001).run()
    assert seen[-1] is not before  # by default the daemon handles SIGINT itself
