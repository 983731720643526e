"""``build_edge``: the one wiring of the edge, run by the daemon on synthetic recordings (no ../shared needed)."""

from __future__ import annotations

import dataclasses
import math
import socket
from pathlib import Path

import numpy as np
import pytest
from factories import sum_bins_model, synthetic_recording

from darkread.edge.builder import build_edge
from darkread.edge.config import load_config
from darkread.edge.daemon import Daemon
from darkread.edge.errors import ModelError
from darkread.edge.imu_motion import ImuHeadMotion
from darkread.edge.io.imu_csv import IMU_NAME, write_imu_csv
from darkread.edge.notify import Notifier
from darkread.edge.spool import Spool
from darkread.lab.bench.ack_server import AckServer
from darkread.proto.messages import PROTOCOL_VERSION


def replay_config(recording: Path, model: Path, url: str, spool: Path, infer: str = "every-window", **uplink: object):
    return load_config(None, environ={}, overrides={
        "source": {"kind": "replay", "path": str(recording), "speed": 0.0},
        "pipeline": {"model": str(model), "infer": infer},
        "uplink": {"url": url, "spool_dir": str(spool), "session_id": "synthetic-1", **uplink},
        "metrics": {"log_every_s": 0.0},
    })


@pytest.mark.slow  # a whole edge: decoder start-up, model load, websocket
def test_the_daemon_replays_a_recording_into_the_cloud(tmp_path: Path, notify_socket) -> None:
    cloud = AckServer()
    try:
        config = replay_config(synthetic_recording(tmp_path / "rec"), sum_bins_model(tmp_path / "m.onnx"),
                               cloud.url, tmp_path / "spool")
        notifier = Notifier({"NOTIFY_SOCKET": notify_socket.path})
        edge = build_edge(config, watchdog=notifier.watchdog_tick)
        assert Daemon(edge, notifier, tick_s=0.005).run() == 0
    finally:
        cloud.close()
    frames = edge.metrics.totals["frames"]
    assert frames >= 15  # 30k events in the window: one frame per 1600 (lossless at max speed)
    assert cloud.stored["synthetic-1"] == list(range(frames))  # every frame stored once, in order
    spool = Spool(tmp_path / "spool")  # and the spool agrees: all of them sent, none left
    assert spool.depth == 0 and spool.last_allocated_seq == frames - 1
    spool.close()
    assert edge.metrics.totals["frames_skipped"] == 0
    assert notify_socket.received()[0].startswith("READY=1\nSTATUS=replay 1280x720 open, model m.onnx warm")
    assert cloud.hellos[0].fovea == (100, 200)


@pytest.mark.slow
def test_on_change_sends_one_view_per_fixation_stretch(tmp_path: Path) -> None:
    """The default mode: the synthetic gaze rests on the text, so the views come every view_every_ms,
    each fusing the frames inferred at most every min_interval_ms."""
    cloud = AckServer()
    try:
        config = replay_config(synthetic_recording(tmp_path / "rec"), sum_bins_model(tmp_path / "m.onnx"),
                               cloud.url, tmp_path / "spool", infer="on-change")
        edge = build_edge(config)
        assert Daemon(edge, Notifier(environ={}), tick_s=0.005).run() == 0
    finally:
        cloud.close()
    views, frames = edge.metrics.totals["views"], edge.metrics.totals["frames"]
    assert 1 <= views <= frames
    assert cloud.stored["synthetic-1"] == list(range(views))  # one message per view, every one stored
    assert cloud.hellos[0].v == PROTOCOL_VERSION


@pytest.mark.slow
def test_a_model_with_another_window_size_sets_the_fovea_everywhere(tmp_path: Path) -> None:
    """The window and the bins come from the model: frames, their origin and the hello follow it."""
    cloud = AckServer()
    try:
        recording = synthetic_recording(tmp_path / "rec", box_xywh=(640 - 48, 360 - 32, 96, 64))
        config = replay_config(recording, sum_bins_model(tmp_path / "small.onnx", (2, 64, 96)), cloud.url, tmp_path / "spool")
        edge = build_edge(config)
        assert edge.pipeline.windows.voxel.shape == (2, 64, 96)
        assert Daemon(edge, Notifier({}), tick_s=0.005).run() == 0
    finally:
        cloud.close()
    assert cloud.hellos[0].fovea == (64, 96)
    frames = edge.metrics.totals["frames"]
    assert frames >= 15 and cloud.stored["synthetic-1"] == list(range(frames))


def test_frames_can_go_to_the_caller_instead_of_an_uplink(tmp_path: Path) -> None:
    config = replay_config(synthetic_recording(tmp_path / "rec", n_events=8_000), sum_bins_model(tmp_path / "m.onnx"),
                           "ws://127.0.0.1:1/v1/stream", tmp_path / "spool")
    frames = []
    edge = build_edge(config, on_frame=lambda frame, arrival: frames.append(frame))
    assert edge.uplink is None
    assert edge.startup().endswith("frames to the caller")
    assert edge.source.wait(10)
    assert edge.shutdown(1.0)
    assert len(frames) == edge.metrics.totals["frames"] >= 4
    assert all(f.mask.shape == (100, 200) and f.origin == (540, 310) for f in frames)
    assert not (tmp_path / "spool").exists()  # no uplink, no spool


def test_a_failed_build_closes_what_it_opened(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    config = load_config(None, environ={}, overrides={
        "source": {"kind": "replay", "path": str(synthetic_recording(tmp_path / "rec", n_events=1_000)), "speed": 0.0},
        "gaze": {"kind": "udp", "udp_port": port},
        "pipeline": {"model": str(tmp_path / "absent.onnx")},
    })
    with pytest.raises(ModelError, match="not found"):
        build_edge(config)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:  # the gaze feed's port was released
        again.bind(("127.0.0.1", port))


def test_pages_are_built_from_frames_and_sent_when_due() -> None:
    from darkread.edge.frame import FrameResult
    from darkread.edge.pages import PageBuilder

    now = [0.0]
    pages = PageBuilder(every_s=5.0, clock=lambda: now[0])
    assert not pages.due() and pages.message(t_us=1) is None  # nothing stitched yet: nothing to send
    rng = np.random.default_rng(0)
    text = (rng.random((100, 2000)) < 0.2).astype(np.uint8)  # a line of "ink" the gaze sweeps along
    for i in range(40):
        x = 40 * i
        pages.add(FrameResult(frame_id=i, t_us=1_000 * i, mask=text[:, x : x + 200], origin=(300 + x, 300),
                              gaze_px=(400.0 + x, 350.0), gaze_rad=(0.0, 0.0), events_used=1600, inference_ms=1.0))
    now[0] = 5.0
    assert pages.due()
    message = pages.message(t_us=99, final=True)
    assert message is not None and message.t_us == 99 and message.mask().any()
    assert not pages.due()  # the clock restarts with every page


def test_a_recording_with_an_imu_stream_gives_the_edge_the_gyroscopes_head_motion(tmp_path: Path) -> None:
    recording = synthetic_recording(tmp_path / "rec", n_events=8_000)
    t = np.arange(0, 400_000, 1000, dtype=np.int64)
    write_imu_csv(recording / IMU_NAME, t, np.zeros((t.shape[0], 3)), np.tile([0.0, 0.0, 0.0, 1.0], (t.shape[0], 1)),
                  graph_uid="g", utc_offset_ns=0)
    config = replay_config(recording, sum_bins_model(tmp_path / "m.onnx"), "ws://127.0.0.1:1/v1/stream", tmp_path / "spool")
    frames: list = []
    edge = build_edge(config, on_frame=lambda frame, arrival: frames.append(frame))
    windows = edge.pipeline.windows
    assert isinstance(windows.known_motion, ImuHeadMotion) and windows.imu is windows.known_motion
    assert windows.scene is not None  # the event tracker runs beside it: the fallback and the check
    edge.startup()
    assert edge.source.wait(10)
    assert edge.shutdown(1.0)
    totals = edge.metrics.totals
    assert frames and totals["frames_imu_motion"] + totals["frames_imu_fallback"] >= len(frames)
    # [imu] kind "none": the edge as without the stream
    plain = build_edge(dataclasses.replace(config, imu=dataclasses.replace(config.imu, kind="none")),
                       on_frame=lambda frame, arrival: None)
    try:
        assert plain.pipeline.windows.known_motion is None
    finally:
        plain.shutdown(1.0)


def test_the_edge_asks_the_gyroscope_how_far_the_scene_moved_between_two_frames(tmp_path: Path) -> None:
    """``Windows.gyro_moved``: the scene's shift between two times by the gyroscope (what a view's dim
    frames are placed by), None where it is not healthy at both (its first half second)."""
    recording = synthetic_recording(tmp_path / "rec", n_events=8_000)
    t = np.arange(0, 2_000_000, 1000, dtype=np.int64)
    write_imu_csv(recording / IMU_NAME, t, np.tile([0.0, 0.01, 0.0], (t.shape[0], 1)),
                  np.tile([0.0, 0.0, 0.0, 1.0], (t.shape[0], 1)), graph_uid="g", utc_offset_ns=0)
    config = replay_config(recording, sum_bins_model(tmp_path / "m.onnx"), "ws://127.0.0.1:1/v1/stream", tmp_path / "spool")
    edge = build_edge(config, on_frame=lambda frame, arrival: None)
    try:
        windows = edge.pipeline.windows
        offset = windows.known_motion.clock_offset_us
        a, b = 1_000_000 + offset, 1_500_000 + offset
        moved = windows.gyro_moved(a, b)
        before, after = windows.known_motion.scene_px(a), windows.known_motion.scene_px(b)
        assert moved is not None and before is not None and after is not None
        assert moved == pytest.approx((after[0] - before[0], after[1] - before[1]))
        assert math.hypot(*moved) > 1.0  # 0.29 deg turned in half a second
        assert windows.gyro_moved(100_000 + offset, b) is None  # its first half second: not trusted yet
    finally:
        edge.shutdown(1.0)


@pytest.mark.slow  # a whole edge: decoder start-up, model load
def test_a_replay_knows_its_biases_and_only_advises_a_switch(tmp_path: Path) -> None:
    """A recording states the biases it was made with; a replay cannot change them, so the controller
    reads the light on that profile and says (and counts) what it would do."""
    import json

    from darkread.edge.sources.evk4.bias_profiles import profile_offsets

    recording = synthetic_recording(tmp_path / "rec", n_events=8_000)
    (recording / "meta.json").write_text(json.dumps({"biases": {"profile": "dark", "offsets": profile_offsets("dark")}}))
    config = load_config(None, environ={}, overrides={
        "source": {"kind": "replay", "path": str(recording), "speed": 0.0},
        "pipeline": {"model": str(sum_bins_model(tmp_path / "m.onnx")), "infer": "every-window"},
        "sensor": {"lux": 40.0},
    })
    edge = build_edge(config, on_frame=lambda frame, arrival: None)
    light = edge.pipeline.light
    assert light is not None and light.advisory and light.active == "dark" and light.state.profile == "factory"
    assert edge.metrics.totals["bias_switches"] == 1
    snap = edge.metrics.snapshot()
    assert snap.light_lux == 40.0 and "biases factory (advisory)" in snap.log_line()
    edge.startup()
    assert edge.source.wait(10)
    assert edge.shutdown(1.0)
