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
from darkread.edge.uplink import split_urls  # noqa: E402


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


def test_several_cloud_urls_from_repeated_options_toml_lists_and_the_environment(tmp_path: Path) -> None:
    import argparse

    from darkread.edge.cli import overrides_from_args, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["edge", "run", "--cloud", "ws://a:1/v1/stream", "--cloud", "ws://b:1/v1/stream,ws://c:1/v1/stream"])
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert split_urls(config.uplink.url) == ("ws://a:1/v1/stream", "ws://b:1/v1/stream", "ws://c:1/v1/stream")
    toml = tmp_path / "edge.toml"
    toml.write_text('[uplink]\nurl = ["ws://a:1/v1/stream", "wss://b/v1/stream"]\n')
    assert split_urls(load_config(toml, environ={}).uplink.url) == ("ws://a:1/v1/stream", "wss://b/v1/stream")
    environ = {"DARKREAD_EDGE_UPLINK_URL": "ws://x:1/v1/stream, ws://y:1/v1/stream"}
    assert split_urls(load_config(None, environ=environ).uplink.url) == ("ws://x:1/v1/stream", "ws://y:1/v1/stream")
    with pytest.raises(ValueError, match="not a ws:// or wss:// URL"):
        load_config(None, environ={"DARKREAD_EDGE_UPLINK_URL": "ws://x:1/v1/stream,http://y"})


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


# -- the wired service, end to end on a synthetic recording (no ../shared needed) --------------


def synthetic_recording(root: Path) -> Path:
    import numpy as np
    from factories import random_events

    from darkread.edge.io.calibration import Calibration, save_calibration
    from darkread.edge.io.gaze_csv import write_gaze_csv
    from darkread.edge.io.raw import write_raw

    root.mkdir()
    ev = random_events(30_000, width=200, height=100, t0=1_000, rate_hz=100_000, seed=7)
    ev["x"] += 540
    ev["y"] += 310
    _, keep = np.unique(np.stack([ev["t"], ev["y"].astype(np.int64), ev["x"].astype(np.int64)]), axis=1, return_index=True)
    write_raw(root / "events.raw", ev[np.sort(keep)])
    t = np.arange(0, 400_000, 16_667)
    zeros = np.zeros(t.shape[0])
    write_gaze_csv(root / "general_eye_gaze.csv", t, zeros, zeros, zeros, np.full(t.shape[0], 0.45))
    save_calibration(root / "calibration.json", Calibration(
        width=1280, height=720, fx=600.0, fy=600.0, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
        T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=0,
    ))
    (root / "text.txt").write_text("synthetic")
    (root / "meta.json").write_text("{}")
    return root


def stand_in_model(path: Path) -> Path:
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("voxel", TensorProto.FLOAT, ["batch", 4, 100, 200])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["batch", 1, 100, 200])
    axes = helper.make_tensor("axes", TensorProto.INT64, [1], [1])
    node = helper.make_node("ReduceSum", ["voxel", "axes"], ["logits"], keepdims=1)
    model = helper.make_model(helper.make_graph([node], "g", [x], [y], initializer=[axes]),
                              opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


class AckingCloud:
    """Acks every message and remembers the seqs it stored, per session."""

    def __init__(self) -> None:
        import asyncio

        from websockets.asyncio.server import serve

        from darkread.proto.messages import Ack, Welcome, decode, encode

        self.stored: dict[str, list[int]] = {}

        async def handler(ws) -> None:  # noqa: ANN001
            hello = decode(await ws.recv(), max_bytes=1 << 22)
            seqs = self.stored.setdefault(hello.session_id, [])
            await ws.send(encode(Welcome(session_id=hello.session_id, last_acked_seq=seqs[-1] if seqs else -1,
                                         max_message_bytes=1 << 22)))
            async for data in ws:
                message = decode(data, max_bytes=1 << 22)
                if hasattr(message, "seq"):
                    seqs.append(message.seq)
                    await ws.send(encode(Ack(seq=message.seq)))

        async def start():  # noqa: ANN202
            return await serve(handler, "127.0.0.1", 0)

        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server = asyncio.run_coroutine_threadsafe(start(), self.loop).result(5)
        self.url = f"ws://127.0.0.1:{self.server.sockets[0].getsockname()[1]}/v1/stream"

    def close(self) -> None:
        import asyncio

        async def stop() -> None:
            self.server.close()
            await self.server.wait_closed()

        asyncio.run_coroutine_threadsafe(stop(), self.loop).result(5)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


@pytest.mark.slow  # a whole edge: decoder start-up, model load, websocket
def test_edge_service_replays_a_recording_into_the_cloud(tmp_path: Path, notify_socket) -> None:
    from darkread.edge.daemon import EdgeService

    path, sock = notify_socket
    cloud = AckingCloud()
    try:
        config = load_config(None, environ={}, overrides={
            "source": {"kind": "replay", "path": str(synthetic_recording(tmp_path / "rec")), "speed": 0.0},
            "pipeline": {"model": str(stand_in_model(tmp_path / "m.onnx"))},
            "uplink": {"url": cloud.url, "spool_dir": str(tmp_path / "spool"), "session_id": "synthetic-1"},
            "metrics": {"log_every_s": 0.0},
        })
        service = EdgeService(config, Notifier({"NOTIFY_SOCKET": path}))
        assert Daemon(service, service.notifier, tick_s=0.005).run() == 0
    finally:
        cloud.close()
    sent = list(service.sent_seqs)
    assert len(sent) >= 15  # 30k events in the window: one frame per 1600 (lossless at max speed)
    assert cloud.stored["synthetic-1"] == sent
    assert service.metrics.totals["frames_skipped"] == 0
    assert received(sock)[0].startswith("READY=1\nSTATUS=replay 1280x720 open, model m.onnx warm")
