from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import pytest

from darkread.edge.daemon import Daemon, Notifier, sd_notify


@pytest.fixture
def notify_socket(tmp_path: Path):
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(1.0)
    yield str(path), sock
    sock.close()


def received(sock: socket.socket) -> list[str]:
    out = []
    sock.settimeout(0.05)
    while True:
        try:
            out.append(sock.recv(4096).decode())
        except (TimeoutError, socket.timeout):
            return out


def test_sd_notify_sends_one_datagram(notify_socket) -> None:
    path, sock = notify_socket
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
    path, sock = notify_socket
    now = [100.0]
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"}, clock=lambda: now[0])
    assert notifier.watchdog_interval_s == 1.0
    assert notifier.watchdog_tick()
    now[0] += 0.5
    assert not notifier.watchdog_tick()
    now[0] += 0.6
    assert notifier.watchdog_tick()
    assert received(sock) == ["WATCHDOG=1", "WATCHDOG=1"]


def test_watchdog_for_another_pid_is_ignored(notify_socket) -> None:
    path, _ = notify_socket
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"})
    assert notifier.watchdog_interval_s is None
    assert not notifier.watchdog_tick()


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


def test_daemon_runs_until_service_finishes_and_notifies(notify_socket) -> None:
    path, sock = notify_socket
    service = FakeService(ticks_until_finished=3)
    daemon = Daemon(service, Notifier({"NOTIFY_SOCKET": path}), tick_s=0.001, status_every_s=0.0)
    assert daemon.run() == 0
    assert service.calls == ["startup", "shutdown 10.0"]
    messages = received(sock)
    assert messages[0] == "READY=1\nSTATUS=sensor open, model warm"
    assert "STATUS=tick 1" in messages
    assert messages[-2:] == ["STOPPING=1", "STATUS=draining"]


def test_daemon_should_exit_from_another_thread_drains() -> None:
    service = FakeService()
    daemon = Daemon(service, Notifier({}), tick_s=0.001)
    threading.Timer(0.05, daemon.should_exit.set).start()
    assert daemon.run() == 0
    assert service.calls[-1] == "shutdown 10.0"


def test_sigterm_stops_the_daemon_gracefully() -> None:
    service = FakeService()
    daemon = Daemon(service, Notifier({}), tick_s=0.001)
    threading.Timer(0.05, os.kill, args=(os.getpid(), 15)).start()
    assert daemon.run() == 0
    assert service.calls == ["startup", "shutdown 10.0"]


# -- configuration (TOML + environment), loaded by the daemon ----------------------------------
from darkread.edge.config import EdgeConfig, load_config  # noqa: E402


def test_config_toml_env_and_overrides(tmp_path: Path) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text('[uplink]\nurl = "ws://cloud:1/v1/stream"\nmode = "pages"\n[pipeline]\nn_events = 800\n')
    env = {"DARKREAD_EDGE_UPLINK_API_KEY": "secret", "DARKREAD_EDGE_PIPELINE_LOSSLESS": "yes", "HOME": "/x"}
    config = load_config(toml, environ=env, overrides={"source": {"speed": 0.0}})
    assert config.uplink.url == "ws://cloud:1/v1/stream"
    assert config.uplink.mode == "pages"
    assert config.uplink.api_key == "secret"
    assert config.pipeline.n_events == 800 and config.pipeline.lossless is True
    assert config.source.speed == 0.0
    assert config.metrics == EdgeConfig().metrics


def test_config_env_beats_file_and_types_are_checked(tmp_path: Path) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text("[pipeline]\nn_events = 800\n")
    assert load_config(toml, environ={"DARKREAD_EDGE_PIPELINE_N_EVENTS": "1200"}).pipeline.n_events == 1200
    with pytest.raises(ValueError, match="n_events"):
        load_config(toml, environ={"DARKREAD_EDGE_PIPELINE_N_EVENTS": "many"})


@pytest.mark.parametrize(
    "text",
    ["[uplink]\nmode = 'video'\n", "[nosuch]\nx = 1\n", "[uplink]\nnosuch = 1\n", "not toml ["],
)
def test_config_rejects_bad_files(tmp_path: Path, text: str) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text(text)
    with pytest.raises(ValueError):
        load_config(toml, environ={})


def test_shipped_example_config_loads() -> None:
    import darkread.edge

    example = Path(darkread.edge.__file__).parent / "systemd" / "edge.toml"
    config = load_config(example, environ={})
    assert config.uplink.spool_dir.startswith("/var/lib/darkread")


def test_unit_file_is_notify_with_watchdog_and_hardening() -> None:
    import darkread.edge

    unit = (Path(darkread.edge.__file__).parent / "systemd" / "darkread-edge.service").read_text()
    directives = {}
    for line in unit.splitlines():
        if "=" in line and not line.startswith("#"):
            key, _, value = line.partition("=")
            directives.setdefault(key.strip(), value.strip())
    assert directives["Type"] == "notify"
    assert directives["WatchdogSec"].endswith("s")
    assert directives["ProtectSystem"] == "strict"
    assert directives["NoNewPrivileges"] == "yes"
    assert directives["StateDirectory"] == "darkread-edge"
    assert "edge run" in directives["ExecStart"]
    rules = Path(darkread.edge.__file__).parent / "systemd" / "99-darkread-evk4.rules"
    if rules.is_file():  # the camera's group is the one the udev rule assigns
        import re

        groups = set(re.findall(r'GROUP="([^"]+)"', rules.read_text()))
        assert groups == {directives["SupplementaryGroups"]}
    else:
        assert directives["SupplementaryGroups"]


def test_edge_run_options_become_config_overrides(tmp_path: Path) -> None:
    import argparse

    from darkread.edge.cli import overrides_from_args, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        ["edge", "run", "--replay", "rec", "--cloud", "ws://h:1/v1/stream", "--api-key", "K",
         "--speed", "max", "--mode", "pages", "--spool", str(tmp_path), "--metrics-port", "9100"]
    )
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert config.source.kind == "replay" and config.source.path == "rec" and config.source.speed == 0.0
    assert config.gaze.kind == "recording"
    assert config.uplink.url == "ws://h:1/v1/stream" and config.uplink.api_key == "K"
    assert config.uplink.mode == "pages" and config.uplink.spool_dir == str(tmp_path)
    assert config.metrics.port == 9100
    args = parser.parse_args(["edge", "run", "--speed", "2", "--gaze", "udp", "--gaze-port", "7100"])
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert config.source.speed == 2.0 and config.gaze.kind == "udp" and config.gaze.udp_port == 7100


def test_journal_format_carries_syslog_priorities() -> None:
    import logging

    from darkread.edge.daemon import JournalFormatter, use_journal_format_if_under_systemd

    formatter = JournalFormatter()
    warning = logging.LogRecord("darkread.edge", logging.WARNING, __file__, 1, "spool at %d", (5,), None)
    assert formatter.format(warning) == "<4>darkread.edge: spool at 5"
    debug = logging.LogRecord("x", logging.DEBUG, __file__, 1, "a\nb", None, None)
    assert formatter.format(debug) == "<7>x: a\n<7>b"
    assert not use_journal_format_if_under_systemd({})


def test_sd_notify_never_blocks_on_a_full_queue(notify_socket) -> None:
    path, _ = notify_socket  # nobody reads: the kernel queue fills up
    results = [sd_notify("WATCHDOG=1", {"NOTIFY_SOCKET": path}) for _ in range(500)]
    assert results[0] is True
    assert results[-1] is False  # dropped, not stuck
