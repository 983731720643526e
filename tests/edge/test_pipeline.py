from __future__ import annotations

import dataclasses
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from factories import moving_strokes, random_events, sum_bins_model

from darkread.edge.builder import build_pipeline
from darkread.edge.config import PipelineConfig
from darkread.edge.events import EVENT_CD_DTYPE, Events, empty_events
from darkread.edge.fovea import FoveaConfig, window_events, window_origin
from darkread.edge.frame import FrameResult, count_in_window, make_frame
from darkread.edge.gaze import GazeSample
from darkread.edge.roi import ROI_FOLLOW_MARGIN_PX
from darkread.edge.sources.base import EventSource
from darkread.edge.telemetry import EdgeMetrics, MetricsServer
from darkread.edge.voxel import VoxelConfig
from darkread.proto.messages import decode, encode

SENSOR = (1280, 720)


def ink_where_events(voxel: np.ndarray) -> np.ndarray:
    """A stand-in model: ink wherever the voxel grid is non-zero."""
    return (np.abs(voxel).sum(axis=0) > 0).astype(np.uint8)


def every_window(**settings: Any) -> PipelineConfig:
    """This module tests the every-window loop (a frame per n_events); on-change: test_view_trigger.py."""
    return PipelineConfig(infer="every-window", **settings)


class FixedGaze:
    def __init__(self, px: tuple[float, float] | None = (640.0, 360.0)) -> None:
        self.px = px
        self.asked: list[int] = []  # the event times the pipeline looked the gaze up at

    def at(self, t_event_us: int) -> GazeSample | None:
        self.asked.append(t_event_us)
        return None if self.px is None else GazeSample(self.px, (0.01, -0.02))


class ListSource:
    """Delivers prepared chunks from a reader thread, like a replay at maximum speed."""

    width, height = SENSOR

    def __init__(self, chunks: list[Events], pause_s: float = 0.0) -> None:
        self.chunks = chunks
        self.pause_s = pause_s
        self.done = threading.Event()
        self.rois: list[tuple[int, int, int, int]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, sink) -> None:
        def run() -> None:
            for chunk in self.chunks:
                if self._stop.is_set():
                    break
                sink(chunk)
                if self.pause_s:
                    time.sleep(self.pause_s)
            self.done.set()

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def set_roi(self, x0: int, y0: int, width: int, height: int) -> None:
        self.rois.append((x0, y0, width, height))

    @property
    def stats(self) -> dict[str, float]:
        return {}


def events_in_box(n: int, x0: int, y0: int, w: int, h: int, t0: int = 0, seed: int = 0) -> Events:
    ev = random_events(n, width=w, height=h, t0=t0, rate_hz=1e6, seed=seed)
    ev["x"] += x0
    ev["y"] += y0
    return ev


# -- the pure core ---------------------------------------------------------------------------


def test_count_in_window_matches_bounds() -> None:
    ev = random_events(5000, seed=1)
    cfg = FoveaConfig()
    expected = np.count_nonzero((ev["x"] >= 100) & (ev["x"] < 300) & (ev["y"] >= 50) & (ev["y"] < 150))
    assert count_in_window(ev, (100, 50), cfg) == expected
    assert count_in_window(ev, None, cfg) == 0
    assert count_in_window(empty_events(), (0, 0), cfg) == 0


def test_window_events_are_the_newest_inside() -> None:
    ev = random_events(20000, seed=2)
    window = window_events(ev, (500, 300), FoveaConfig(), 100)
    assert window.shape[0] == 100
    assert np.all((window["x"] >= 500) & (window["x"] < 700) & (window["y"] >= 300) & (window["y"] < 400))
    inside_all = ev[(ev["x"] >= 500) & (ev["x"] < 700) & (ev["y"] >= 300) & (ev["y"] < 400)]
    assert np.array_equal(window, inside_all[-100:])


def window_at(events: Events, gaze_px: tuple[float, float], n_events: int = 1600) -> tuple[Events, tuple[int, int]]:
    """What the loop bins for a gaze: the window placed at the gaze, its newest events."""
    origin = window_origin(gaze_px, SENSOR)
    return window_events(events, origin, FoveaConfig(), n_events), origin


def test_make_frame_carries_window_gaze_and_mask() -> None:
    ev = np.concatenate([random_events(3000, seed=3), events_in_box(2000, 540, 310, 200, 100, t0=10_000, seed=4)])
    ev.sort(order="t", kind="stable")
    window, origin = window_at(ev, (640.2, 359.6))
    t_frame = int(ev["t"][-1])
    gaze = GazeSample((640.2, 359.6), (0.1, -0.2))
    frame = make_frame(window, origin, gaze, t_frame, VoxelConfig(), ink_where_events, frame_id=7)
    assert isinstance(frame, FrameResult)
    assert frame.frame_id == 7
    assert frame.origin == (540, 310)
    assert frame.events_used == 1600
    assert frame.mask.shape == (100, 200) and frame.mask.dtype == np.uint8
    assert frame.t_us == t_frame  # the frame's one timestamp: where its gaze was looked up
    assert frame.gaze_px == (640.2, 359.6) and frame.gaze_rad == (0.1, -0.2)
    message = decode(encode(frame.to_message()), max_bytes=1 << 20)
    assert np.array_equal(message.mask(), frame.mask)
    assert message.origin == (540, 310) and message.events_used == 1600


def test_make_frame_clamps_at_the_border_and_skips_empty_windows() -> None:
    ev = events_in_box(500, 0, 0, 50, 50)
    window, origin = window_at(ev, (3.0, 2.0))
    frame = make_frame(window, origin, GazeSample((3.0, 2.0), (0.0, 0.0)), 0, VoxelConfig(), ink_where_events, 0)
    assert frame is not None and frame.origin == (0, 0) and frame.events_used == 500
    window, origin = window_at(ev, (1000.0, 600.0))
    assert make_frame(window, origin, GazeSample((1000.0, 600.0), (0.0, 0.0)), 0, VoxelConfig(), ink_where_events, 0) is None


def test_make_frame_with_an_onnx_reconstructor(tmp_path: Path) -> None:
    from darkread.edge.reconstruct import Reconstructor

    reconstructor = Reconstructor(sum_bins_model(tmp_path / "tiny.onnx"), warmup=1)
    ev = events_in_box(2000, 540, 310, 200, 100)
    ev["p"] = 1
    window, origin = window_at(ev, (640.0, 360.0))
    frame = make_frame(window, origin, GazeSample((640.0, 360.0), (0.0, 0.0)), 0, reconstructor.voxel, reconstructor, 0)
    assert frame is not None and frame.mask.shape == (100, 200)
    assert frame.mask.sum() > 0 and frame.inference_ms >= 0


def test_a_model_with_another_window_size_just_works(tmp_path: Path) -> None:
    """Window and bins come from the model's input shape: a 2x64x96 model makes 64x96 frames."""
    from darkread.edge.reconstruct import Reconstructor

    reconstructor = Reconstructor(sum_bins_model(tmp_path / "small.onnx", (2, 64, 96)), warmup=1)
    assert reconstructor.voxel == VoxelConfig(bins=2, height=64, width=96)
    ev = events_in_box(16_000, 640 - 48, 360 - 32, 96, 64)  # all inside the small window at the gaze
    ev["p"] = 1
    frames: list[FrameResult] = []
    source = ListSource(chunked(ev, 200))
    pipeline = build_pipeline(source, FixedGaze(), reconstructor, lambda f, t: frames.append(f),
                              every_window(lossless=True, denoise=False), reconstructor.voxel)  # (uniform events: all isolated)
    pipeline.start()
    assert source.done.wait(5)
    pipeline.stop()
    assert pipeline.error is None and frames
    assert all(f.mask.shape == (64, 96) and f.mask.any() for f in frames)
    assert {f.origin for f in frames} == {(640 - 48, 360 - 32)}  # centred on the gaze
    assert len(frames) >= 9 and all(f.events_used == 1600 for f in frames[:-1])


# -- the threaded loop -----------------------------------------------------------------------


def chunked(events: Events, size: int) -> list[Events]:
    return [events[i : i + size] for i in range(0, events.shape[0], size)]


def run_pipeline(source: ListSource, gaze: FixedGaze, settings: PipelineConfig, infer=ink_where_events, known_motion=None,
                 light=None):
    frames: list[tuple[FrameResult, float]] = []
    metrics = EdgeMetrics()
    pings = []
    pipeline = build_pipeline(
        source, gaze, infer, lambda f, t: frames.append((f, t)), dataclasses.replace(settings, ring_capacity=1 << 16),
        metrics=metrics, watchdog=lambda: pings.append(1), known_motion=known_motion, light=light,
    )
    assert isinstance(source, EventSource)
    pipeline.start()
    assert source.done.wait(5)
    pipeline.stop()
    assert pipeline.error is None
    return frames, metrics, pings


def test_lossless_pipeline_makes_one_frame_per_window() -> None:
    ev = events_in_box(16_000, 540, 310, 200, 100)  # all inside the window at the gaze
    source = ListSource(chunked(ev, 200))
    settings = every_window(n_events=1600, period_ms=1000.0, lossless=True, denoise=False)  # (uniform events: all noise)
    gaze = FixedGaze()
    frames, metrics, pings = run_pipeline(source, gaze, settings)
    # every 1600 new foveated events make a frame (the first places the window), plus the remainder
    assert 9 <= len(frames) <= 11
    assert [f.frame_id for f, _ in frames] == list(range(len(frames)))
    assert all(f.events_used == 1600 for f, _ in frames)
    assert metrics.totals["frames_skipped"] == 0
    assert metrics.totals["events_in"] == 16_000
    assert frames[-1][0].t_us == int(ev["t"][-1])  # the last frame reaches the end of the stream
    assert pings and len(metrics.inference_ms) == len(frames)
    # one timestamp per frame: its stamp is where its gaze was looked up, and no newer event is in it
    assert {f.t_us for f, _ in frames} <= set(gaze.asked)


def test_slow_inference_skips_to_the_newest_window_and_counts() -> None:
    ev = events_in_box(40_000, 540, 310, 200, 100)

    def slow(voxel: np.ndarray) -> np.ndarray:
        time.sleep(0.02)
        return ink_where_events(voxel)

    source = ListSource(chunked(ev, 1000), pause_s=0.002)
    frames, metrics, _ = run_pipeline(source, FixedGaze(), every_window(period_ms=5.0), infer=slow)
    windows = 40_000 // 1600
    assert len(frames) < windows
    assert metrics.totals["frames_skipped"] > 0
    assert len(frames) + metrics.totals["frames_skipped"] <= windows + 2
    assert frames[-1][0].t_us == int(ev["t"][-1])


def test_no_gaze_means_no_frames_counted() -> None:
    ev = events_in_box(5000, 540, 310, 200, 100)
    source = ListSource(chunked(ev, 500), pause_s=0.002)
    frames, metrics, _ = run_pipeline(source, FixedGaze(None), every_window(period_ms=2.0))
    assert frames == []
    assert metrics.totals["frames_no_gaze"] > 0


def test_ring_bounds_memory_and_counts_what_it_overwrote() -> None:
    ev = random_events(100_000, seed=5)
    source = ListSource(chunked(ev, 50_000))
    settings = every_window(period_ms=1.0, ring_capacity=1 << 15)
    frames: list = []
    metrics = EdgeMetrics()
    pipeline = build_pipeline(source, FixedGaze(), ink_where_events, lambda f, t: frames.append(f), settings, metrics=metrics)
    pipeline.start()
    source.done.wait(5)
    pipeline.stop()
    assert len(pipeline.ring) == 1 << 15
    assert metrics.totals["events_overwritten"] == 100_000 - (1 << 15)


# -- metrics ---------------------------------------------------------------------------------


def test_metrics_snapshot_rates_and_percentiles() -> None:
    now = [0.0]
    metrics = EdgeMetrics(clock=lambda: now[0])
    metrics.add("events_in", 1000)
    metrics.add("bytes_sent", 100)
    for ms in range(1, 101):
        metrics.observe_inference(float(ms))
        metrics.observe_latency(float(ms) / 10)
    now[0] = 2.0
    snap = metrics.snapshot()
    assert snap.rates["events_in"] == 500.0
    assert snap.inference_ms_p50 == pytest.approx(50.5)
    assert snap.latency_ms_p99 == pytest.approx(9.901)
    assert snap.bandwidth_vs_raw() == pytest.approx(50 / (500 * 2.0))
    assert "inferences" in snap.log_line() and "views" in snap.log_line()
    assert "drops" not in snap.log_line()  # ring history overwritten is no loss; the spool's evictions are
    metrics.spool_lost = lambda: 7
    now[0] = 2.5
    assert "(lost 7)" in metrics.snapshot().log_line() and "darkread_edge_spool_lost 7" in metrics.prometheus_text()
    now[0] = 3.0
    assert metrics.snapshot().rates["events_in"] == 0.0  # rates cover the last interval only


def test_status_line_reports_views_inferences_cpu_and_bytes() -> None:
    now = [0.0]
    metrics = EdgeMetrics(clock=lambda: now[0])
    metrics.add("views", 8)
    metrics.add("frames", 20)
    metrics.add("event_us", 2_000_000)  # two seconds of reading
    metrics.add("bytes_sent", 12_000)
    now[0] = 2.0
    snap = dataclasses.replace(metrics.snapshot(), cpu_s=0.1)
    assert snap.cpu_per_reading_s == pytest.approx(0.05)
    assert snap.status_line() == "4.0 views/s, 10.0 inferences/s, CPU 0.050 s per reading s, 6.0 kB/s"


def test_metrics_http_endpoint_serves_prometheus_text() -> None:
    metrics = EdgeMetrics()
    metrics.add("frames", 3)
    metrics.observe_latency(4.0)
    server = MetricsServer(metrics, port=0)
    server.start()
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{server.port}/metrics", timeout=2) as response:
            body = response.read().decode()
            assert response.headers["Content-Type"].startswith("text/plain; version=0.0.4")
    finally:
        server.stop()
    assert "# TYPE darkread_edge_frames_total counter" in body
    assert "darkread_edge_frames_total 3" in body
    assert 'darkread_edge_event_to_wire_ms{quantile="0.99"} 4' in body
    for line in body.splitlines():
        assert line.startswith("#") or len(line.split(" ")) == 2


def test_event_dtype_is_the_shared_one() -> None:
    assert ListSource([]).width == 1280 and EVENT_CD_DTYPE.itemsize == 16


def test_watchdog_is_no_longer_fed_when_the_source_stalls() -> None:
    ev = events_in_box(2000, 540, 310, 200, 100)
    source = ListSource(chunked(ev, 500))
    pings: list[float] = []
    settings = every_window(period_ms=5.0, stall_s=0.1)
    pipeline = build_pipeline(source, FixedGaze(), ink_where_events, lambda f, t: None, settings,
                              watchdog=lambda: pings.append(time.monotonic()))
    pipeline.start()
    assert source.done.wait(5)  # then silence, as from a hung sensor
    last_event = time.monotonic()
    time.sleep(0.3)
    pipeline.stop()
    assert pings and pings[0] < last_event + 0.1
    assert max(pings) < last_event + 0.15  # no pings once stalled


def test_sensor_roi_follows_the_window() -> None:
    ev = events_in_box(8000, 540, 310, 200, 100)
    source = ListSource(chunked(ev, 200))
    gaze = FixedGaze((640.0, 360.0))
    frames, metrics, _ = run_pipeline(source, gaze, every_window(lossless=True, sensor_roi="on"))
    m = ROI_FOLLOW_MARGIN_PX  # the window and its margin, programmed once: the gaze did not move
    assert frames and source.rois == [(540 - m, 310 - m, 200 + 2 * m, 100 + 2 * m)]
    assert metrics.totals["roi_writes"] == 1
    plain = ListSource(chunked(ev, 200))
    _, metrics, _ = run_pipeline(plain, FixedGaze(), every_window(lossless=True))  # "auto", no known motion
    assert plain.rois == [] and metrics.totals["roi_writes"] == 0


def test_lossless_replay_is_reproducible() -> None:
    """Frames depend on the events only, never on wall-clock timing: a slow and a fast delivery of
    the same chunks give the same frames (period_ms counts on the event clock here)."""
    ev = events_in_box(12_000, 540, 310, 200, 100)  # 12 ms of events at 1 Mev/s
    runs = []
    for pause_s in (0.0, 0.004):
        settings = every_window(n_events=1600, period_ms=2.0, lossless=True)
        frames, _, _ = run_pipeline(ListSource(chunked(ev, 300), pause_s=pause_s), FixedGaze(), settings)
        runs.append([(f.t_us, f.events_used) for f, _ in frames])
    assert len(runs[0]) > 12 // 2 and runs[0][-1][0] == int(ev["t"][-1])  # the event-clock period adds frames
    assert runs[0] == runs[1]


@pytest.mark.parametrize("deblur", [True, False])
def test_windows_of_a_moving_page_are_deblurred_and_counted(deblur: bool) -> None:
    ev = moving_strokes((300.0, 100.0), span_ms=60.0)
    source = ListSource(chunked(ev, 2000), pause_s=0.002)
    frames, metrics, _ = run_pipeline(source, FixedGaze(), every_window(deblur=deblur))
    assert frames
    assert (metrics.totals["frames_deblurred"] > 0) is deblur
    if deblur:  # a moved event that would leave the window is dropped, so some frames bin fewer
        assert min(frame.events_used for frame, _ in frames) < 1600


class ShiftRight:
    """A known head motion: the scene moves 1 px right per millisecond; ``warp`` moves every event
    one pixel left and notes each window it was given."""

    def __init__(self) -> None:
        self.windows: list[int] = []

    def scene_px(self, t_us: int) -> tuple[float, float] | None:
        return (t_us / 1000.0, 0.0)

    def warp(self, window: Events, origin: tuple[int, int], shape_hw: tuple[int, int]) -> Events:
        self.windows.append(len(window))
        moved = window[window["x"] > origin[0]]
        moved["x"] -= 1
        return moved


def test_a_known_head_motion_replaces_the_measured_one() -> None:
    """(Both modes cut their windows and look up the scene offset through the same two methods.)"""
    ev = moving_strokes((300.0, 100.0), span_ms=60.0)
    known = ShiftRight()
    settings = every_window(lossless=True, denoise=False)
    frames, metrics, _ = run_pipeline(ListSource(chunked(ev, 2000)), FixedGaze(), settings, known_motion=known)
    assert frames and known.windows  # every window went through the known motion's warp, none through the search
    assert metrics.totals["frames_deblurred"] == len(known.windows)
    assert all(f.scene_px == (f.t_us / 1000.0, 0.0) for f, _ in frames)  # the scene offset is the known one


@pytest.mark.parametrize("denoise", [True, False])
def test_noisy_windows_lose_their_isolated_events_and_are_counted(denoise: bool) -> None:
    ev = events_in_box(16_000, 540, 310, 200, 100)  # uniform over the window: shot noise, most of it isolated
    frames, metrics, _ = run_pipeline(ListSource(chunked(ev, 200)), FixedGaze(), every_window(lossless=True, denoise=denoise))
    assert frames
    if denoise:
        assert metrics.totals["frames_denoised"] == len(frames) and all(f.events_used < 1600 for f, _ in frames)
    else:
        assert metrics.totals["frames_denoised"] == 0 and all(f.events_used == 1600 for f, _ in frames[:-1])


class MovingGaze(FixedGaze):
    """The gaze jumps ``step`` px right every ``every_us`` of event time."""

    def __init__(self, step: float, every_us: int) -> None:
        super().__init__()
        self.step, self.every_us = step, every_us

    def at(self, t_event_us: int) -> GazeSample | None:
        return GazeSample((500.0 + self.step * (t_event_us // self.every_us), 360.0), (0.0, 0.0))


def test_the_roi_moves_only_when_the_window_leaves_its_margin() -> None:
    ev = events_in_box(24_000, 300, 250, 700, 250)
    settings = every_window(lossless=True, sensor_roi="on", scene_motion=False, n_events=200, denoise=False)  # a frame per ~2 ms
    small = ListSource(chunked(ev, 500))
    _, metrics, _ = run_pipeline(small, MovingGaze(5.0, 2000), settings)  # 5 px a jump: inside the 64-px margin
    large = ListSource(chunked(ev, 500))
    _, moved, _ = run_pipeline(large, MovingGaze(80.0, 2000), settings)  # 80 px: out of it every time
    assert 1 <= metrics.totals["roi_writes"] <= 3 and moved.totals["roi_writes"] >= 8
    assert len(small.rois) == metrics.totals["roi_writes"] and len(large.rois) == moved.totals["roi_writes"]


class FailingMotion(ShiftRight):
    """A known head motion whose source (an IMU) stops being healthy at ``t_fail``."""

    def __init__(self, t_fail: int) -> None:
        super().__init__()
        self.t_fail = t_fail

    def healthy(self, t_us: int) -> bool:
        return t_us < self.t_fail


def test_the_roi_is_on_while_a_known_motion_is_healthy_and_given_back_when_it_fails() -> None:
    ev = moving_strokes((300.0, 100.0), span_ms=60.0)
    t_fail = int(ev["t"][0]) + 30_000
    known = FailingMotion(t_fail)
    source = ListSource(chunked(ev, 2000))
    settings = every_window(lossless=True, denoise=False)  # sensor_roi "auto", the default
    frames, metrics, _ = run_pipeline(source, FixedGaze(), settings, known_motion=known)
    full = (0, 0, *SENSOR)
    assert source.rois[0] != full and source.rois[-1] == full  # narrowed while healthy, the whole sensor after
    assert metrics.totals["roi_writes"] == len(source.rois) >= 2
    warped_before = sum(1 for f, _ in frames if f.t_us < t_fail)
    assert len(known.windows) == warped_before  # after the failure the deblur searches the events again
    assert metrics.totals["frames_deblurred"] == len(frames)


class ReadingTheLight:
    """A light controller that wants the whole sensor the whole time (a light reading in progress)."""

    def __init__(self) -> None:
        self.pushed = 0
        self.lux: float | None = None  # (no estimate yet)

    def push(self, events: Events, gaze_window: object) -> None:
        self.pushed += 1

    def wants_whole(self) -> bool:
        return True


def test_while_the_light_is_read_the_roi_gives_way_to_the_whole_sensor() -> None:
    ev = moving_strokes((300.0, 100.0), span_ms=60.0)
    light = ReadingTheLight()
    source = ListSource(chunked(ev, 2000))
    frames, metrics, _ = run_pipeline(source, FixedGaze(), every_window(lossless=True, denoise=False),
                                      known_motion=ShiftRight(), light=light)
    assert frames and light.pushed and not source.rois and metrics.totals["roi_writes"] == 0


class EstimatingTheLight(ReadingTheLight):
    """A light controller whose first estimate, 6 lux, comes with its fifth chunk."""

    def push(self, events: Events, gaze_window: object) -> None:
        super().push(events, gaze_window)
        if self.pushed == 5:
            self.lux = 6.0

    def wants_whole(self) -> bool:
        return False


def test_each_frame_says_the_light_the_glasses_measured_once_they_have() -> None:
    ev = events_in_box(16_000, 540, 310, 200, 100)
    settings = every_window(n_events=1600, period_ms=1000.0, lossless=True, denoise=False)
    frames, _, _ = run_pipeline(ListSource(chunked(ev, 1000)), FixedGaze(), settings, light=EstimatingTheLight())
    said = [f.light_lux for f, _ in frames]
    assert said[0] is None and said[-1] == 6.0 and said == sorted(said, key=lambda lux: lux is not None)
    assert frames[-1][0].to_message().light_lux == 6.0
    assert {f.light_lux for f, _ in run_pipeline(ListSource(chunked(ev, 1000)), FixedGaze(), settings)[0]} == {None}


def test_a_healthy_known_motion_leaves_the_event_tracker_idle() -> None:
    ev = moving_strokes((300.0, 100.0), span_ms=60.0)
    settings = every_window(lossless=True, denoise=False)
    source = ListSource(chunked(ev, 2000))
    frames: list = []
    pipeline = build_pipeline(source, FixedGaze(), ink_where_events, lambda f, t: frames.append(f), settings,
                              known_motion=ShiftRight())
    pipeline.start()
    assert source.done.wait(5)
    pipeline.stop()
    assert frames and pipeline.windows.scene is not None  # standing by ...
    assert pipeline.windows.scene.at(int(ev["t"][-1])) is None  # ... and fed nothing
    assert all(f.scene_px == (f.t_us / 1000.0, 0.0) for f in frames)


class StillRows(FixedGaze):
    """A still gaze as the tracker's 60-Hz rows too (what the on-change step reads)."""

    def rows(self, t0: int, t1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.arange((t0 // 16_667 + 1) * 16_667, t1 + 1, 16_667, dtype=np.int64)
        return t, np.full(t.shape, 0.01), np.full(t.shape, -0.02)


def test_live_chunks_are_gathered_to_the_step_grid_and_none_is_lost() -> None:
    """A live source's 1-ms chunks reach the pipeline's per-chunk work (scene tracker, light, ring,
    count) gathered into pieces that cross one line of the on-change step's 5-ms grid, and the last
    chunks, which cross no line, are handed on when the pipeline stops."""
    ev = events_in_box(20_000, 540, 310, 200, 100)  # 1 M events/s: 20 ms
    ev["t"] += 3_000  # the stream starts inside a grid cell
    cuts = np.searchsorted(ev["t"], np.arange(ev["t"][0], ev["t"][-1] + 1, 1_000))[1:]
    source = ListSource(np.split(ev, cuts))
    pipeline = build_pipeline(source, StillRows(), ink_where_events, lambda f, t: None,
                              PipelineConfig(infer="on-change", ring_capacity=1 << 16), metrics=EdgeMetrics())
    grid = pipeline.step.replay_grid_us
    assert grid == 5_000
    taken: list[Events] = []
    take = pipeline._take
    pipeline._take = lambda events: (taken.append(events.copy()), take(events))  # type: ignore[method-assign]
    for chunk in source.chunks:  # the reader's calls, from here: no step runs between them
        pipeline.sink(chunk)
    pipeline.stop()
    assert pipeline.error is None
    assert np.array_equal(np.concatenate(taken), ev)  # every event, once, in order
    # 21 chunks; a piece per 5-ms cell crossed and the rest (a pause of 5 ms of wall clock would cut one more)
    assert len(source.chunks) >= 20 and len(taken) <= 7
    for piece in taken[:-1]:  # each piece ends with the chunk that crossed a line (or after a grid's worth of wall clock)
        assert int(piece["t"][-1]) // grid >= int(piece["t"][0]) // grid
    assert pipeline.metrics.totals["events_in"] == ev.shape[0]
