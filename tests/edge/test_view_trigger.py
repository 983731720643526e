"""The on-change mode: the gaze gates inference, one view per fixation (pipeline and pure parts)."""

from __future__ import annotations

from typing import Any

import numpy as np

from darkread.edge.builder import build_pipeline
from darkread.edge.config import PipelineConfig
from darkread.edge.events import Events, make_events
from darkread.edge.gaze import GazeSample
from darkread.edge.gaze_events import EventKind
from darkread.edge.roi import ROI_FOLLOW_MARGIN_PX
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.view_fusion import ViewRecord
from darkread.edge.view_trigger import GazeGate, ViewTrigger, fixation_key

SENSOR = (1280, 720)
RATE_HZ = 60
PX_PER_DEG = 30.0


class ScanGaze:
    """A reader's gaze in rows at 60 Hz: fixations of 250 ms stepping 2 deg right with two rows
    in flight between them (a 50 ms saccade); ``at`` holds the last row like a live feed."""

    def __init__(self, n_fixations: int = 6) -> None:
        t, x = [], []
        now = 0
        for i in range(n_fixations):
            for k in range(15 + 3):  # 250 ms at rest, then the saccade's rows on the way to the next place
                t.append(now), x.append(2.0 * i + (0.0 if k < 15 else 2.0 * (k - 14) / 4))
                now += 16_667
        self.t = np.asarray(t, np.int64)
        self.yaw = -np.radians(np.asarray(x))  # CPF yaw: x left
        self.pitch = np.zeros_like(self.yaw)
        self.fixation_starts = self.t[::18]
        self.rate_hz = RATE_HZ

    def rows(self, t0: int, t1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i0, i1 = np.searchsorted(self.t, [t0, t1], side="right")
        return self.t[i0:i1], self.yaw[i0:i1], self.pitch[i0:i1]

    def at(self, t_event_us: int) -> GazeSample | None:
        i = int(np.searchsorted(self.t, t_event_us, side="right")) - 1
        if i < 0:
            return None
        x_deg = -np.degrees(self.yaw[i])
        return GazeSample((400.0 + PX_PER_DEG * x_deg, 360.0), (float(self.yaw[i]), 0.0))


class Chunks:
    width, height = SENSOR

    def __init__(self, events: Events) -> None:
        self.events = events

    def start(self, sink) -> None:
        self.sink = sink

    def stop(self) -> None:
        pass

    def set_roi(self, *roi: int) -> None:
        pass


def busy_events(duration_us: int, rate_hz: float = 200_000.0, seed: int = 1) -> Events:
    """Events everywhere around the gaze path (text under a moving head)."""
    rng = np.random.default_rng(seed)
    n = int(duration_us * rate_hz / 1e6)
    t = np.sort(rng.integers(0, duration_us, n))
    return make_events(rng.integers(300, 900, n), rng.integers(280, 440, n), rng.integers(0, 2, n), t)


def ink_where_events(grid: np.ndarray) -> np.ndarray:
    return (np.abs(grid).sum(axis=0) > 0).astype(np.uint8)


def glyphs(shape: tuple[int, int] = (100, 200), seed: int = 2) -> np.ndarray:
    """A line of glyph-like blobs: what the model sees of a page in a window that stays put."""
    rng = np.random.default_rng(seed)
    ink = np.zeros(shape, np.uint8)
    x = 4
    while x < shape[1] - 10:
        w = int(rng.integers(3, 8))
        top = int(rng.integers(38, 46))
        ink[top : top + int(rng.integers(8, 16)), x : x + w] = 1
        x += w + int(rng.integers(2, 6))
    return ink


def the_same_text(grid: np.ndarray) -> np.ndarray:
    """A model that reads the same words in every frame (a locked window over still text)."""
    return glyphs(grid.shape[1:])


def run_on_change(gaze: ScanGaze, events: Events, infer=the_same_text, source=None, **settings: Any):
    """Views of one lossless replay. The frames stay in the view's window (``dither_px`` 0) unless
    asked: ``the_same_text`` sees the same words wherever the window is."""
    views: list[tuple[ViewRecord, float]] = []
    source = source or Chunks(events)
    settings = {"dither_px": 0, **settings}
    config = PipelineConfig(lossless=True, infer="on-change", **settings)
    metrics = EdgeMetrics()
    pipeline = build_pipeline(source, gaze, infer, lambda v, t: views.append((v, t)), config, metrics=metrics)
    pipeline.start()
    step = 5_000
    for t0 in range(0, int(events["t"][-1]) + 1, step):
        i0, i1 = np.searchsorted(events["t"], [t0, t0 + step])
        if i1 > i0:
            source.sink(events[i0:i1])
    pipeline.stop()
    assert pipeline.error is None
    return [v for v, _ in views], metrics


def test_one_view_per_fixation_and_no_inference_in_saccades() -> None:
    gaze = ScanGaze()
    views, metrics = run_on_change(gaze, busy_events(int(gaze.t[-1]) + 20_000))
    assert len(views) == len(gaze.fixation_starts)
    for view, start in zip(views, gaze.fixation_starts):
        # inside its fixation (the saccade's first row, a third of the way, is not yet told from noise)
        assert start <= view.t0_us <= view.t_us <= start + 16 * 16_667
        # the first once the landing settled, a second that agrees with it (the same text), then no more
        assert view.frames == 2
    assert metrics.totals["views"] == len(views)
    assert metrics.totals["frames"] == sum(v.frames for v in views)
    # far fewer inferences than the every-window mode's one per 1600 events
    reading_s = (int(gaze.t[-1]) + 20_000) / 1e6
    assert metrics.totals["frames"] <= 20 * reading_s < metrics.totals["events_foveated"] / 1600


def test_a_view_stays_in_one_window_placed_at_the_fixations_mean_gaze() -> None:
    gaze = ScanGaze(n_fixations=2)
    noise = np.random.default_rng(4).normal(0.0, 0.1, gaze.t.shape)  # tracker noise: 3 px a row
    noise[np.arange(noise.size) % 18 >= 15] = 0.0  # (the saccades' rows as they were)
    gaze.yaw = gaze.yaw - np.radians(noise)
    views, metrics = run_on_change(gaze, busy_events(int(gaze.t[-1]) + 20_000))
    assert len(views) == 2 and metrics.totals["views_split"] == 0  # its frames register onto each other
    for i, view in enumerate(views):
        assert view.frames >= 2
        # the window is where the fixation's rows are on average, not where one noisy row was
        assert abs(view.origin[0] + 100 - (400.0 + PX_PER_DEG * 2.0 * i)) <= 2.0


def test_a_views_frames_look_above_and_below_its_window_and_the_view_holds_both() -> None:
    """The tracker's bias can put the line being read at the window's edge: a view's frames go
    ``dither_px`` above and below its window, and the view is the union of what they saw."""
    rng = np.random.default_rng(8)
    page = np.zeros(SENSOR[::-1], np.uint8)  # text that stays put on the sensor (a still head)
    for row in range(250, 480, 30):
        x = 300
        while x < 900:
            w = int(rng.integers(3, 8))
            page[row : row + int(rng.integers(8, 14)), x : x + w] = 1
            x += w + int(rng.integers(3, 7))
    ys, xs = np.nonzero(page)
    gaze = ScanGaze(n_fixations=2)
    duration = int(gaze.t[-1]) + 20_000
    n = duration * 400_000 // 1_000_000  # events at the ink only, 400 kev/s
    pick = rng.integers(0, ys.size, n)
    events = make_events(xs[pick], ys[pick], rng.integers(0, 2, n), np.sort(rng.integers(0, duration, n)))
    views, metrics = run_on_change(gaze, events, infer=ink_where_events, dither_px=20, n_events=8000)
    assert len(views) == 2 and metrics.totals["views_split"] == 0
    for view in views:
        assert view.frames >= 2
        x0, y0 = view.origin
        assert y0 == 360 - 50 - 20 and view.mask.shape == (140, 200)  # 20 px above the window to 20 px below it
        seen = page[y0 : y0 + 140, x0 : x0 + 200]
        assert np.mean(view.mask == seen) > 0.97  # the union, each part from the frames that saw it


class RoiChunks(Chunks):
    def __init__(self, events: Events) -> None:
        super().__init__(events)
        self.rois: list[tuple[int, ...]] = []

    def set_roi(self, *roi: int) -> None:
        self.rois.append(roi)


def test_the_sensor_roi_spans_a_views_dithered_windows() -> None:
    gaze = ScanGaze(n_fixations=2)
    events = busy_events(int(gaze.t[-1]) + 20_000)
    source = RoiChunks(events)
    views, _ = run_on_change(gaze, events, source=source, dither_px=20, sensor_roi="on", scene_motion=False)
    assert views and source.rois
    m = ROI_FOLLOW_MARGIN_PX
    for _x0, y0, w, h in source.rois:  # the window 20 px up to 20 px down, and the margin
        assert (w, h) == (200 + 2 * m, 140 + 2 * m) and y0 == 360 - 50 - 20 - m


def test_a_long_fixation_sends_its_view_every_view_every_ms() -> None:
    gaze = ScanGaze(n_fixations=1)
    gaze.t = np.arange(0, 1_000_000, 16_667)  # one fixation of a second
    gaze.yaw = np.zeros(gaze.t.shape)
    gaze.pitch = np.zeros(gaze.t.shape)
    views, _ = run_on_change(gaze, busy_events(1_000_000))
    assert 3 <= len(views) <= 5
    assert all(v.t_us - v.t0_us < 250_000 for v in views)


def test_the_trigger_waits_for_the_landing_then_bounds_the_rate() -> None:
    trigger = ViewTrigger(PipelineConfig())
    start = 1_000_000
    assert not trigger.due(start + 10_000, start, 5000, 5000, (0, 0))  # the classifier may still revise the landing
    assert trigger.due(start + 60_000, start, 500, 500, (0, 0))  # then even a thin window (low light) will do
    trigger.inferred(start + 60_000, (0, 0))
    assert not trigger.due(start + 65_000, start, 9000, 9000, (50, 0))  # moved, but within min_interval_ms (10 ms)
    assert not trigger.due(start + 170_000, start, 700, 9000, (0, 0))  # not enough new, not moved
    assert trigger.due(start + 170_000, start, 800, 9000, (0, 0))  # renew_fraction (half) of a window is new
    assert trigger.due(start + 170_000, start, 10, 9000, (8, 0))  # or the window moved


def test_the_gate_says_saccade_after_a_jump_and_blink_without_rows() -> None:
    gaze = ScanGaze(n_fixations=3)
    gate = GazeGate(gaze)
    second = gate.update(int(gaze.t[18 + 10]))
    assert second.kind == EventKind.FIXATION and fixation_key(second) is not None
    assert gate.update(int(gaze.t[18 + 15])).kind == EventKind.SACCADE  # the first row on the way (noise learnt by now)
    late = gate.update(int(gaze.t[-1]) + 500_000)  # no rows for half a second
    assert late.kind == EventKind.BLINK and fixation_key(late) is None


def test_once_a_frame_agrees_with_its_view_the_trigger_waits_longer() -> None:
    settings = PipelineConfig(infer="on-change", min_interval_ms=10.0, settled_interval_ms=400.0, settled_score=0.85)
    trigger = ViewTrigger(settings)
    start = 1_000_000
    trigger.inferred(start, (0, 0), None)  # the view's first frame: nothing to agree with
    assert trigger.due(start + 12_000, start, 1600, 9000, (0, 0))  # frames still change the view: 10 ms apart
    trigger.inferred(start + 12_000, (0, 0), 0.80)  # fused, but it still moved the view
    assert trigger.due(start + 24_000, start, 1600, 9000, (0, 0))
    trigger.inferred(start + 24_000, (0, 0), 0.91)  # agreed: a third frame would add little
    assert not trigger.ready(start + 300_000, start)
    assert not trigger.due(start + 300_000, start, 9000, 9000, (0, 0))
    assert trigger.due(start + 424_000, start, 1600, 9000, (0, 0))
    trigger.reset()  # the next fixation starts afresh
    assert not trigger.settled


def test_a_frame_the_network_doubted_does_not_settle_its_view() -> None:
    """Dim light or small text: frames that agree with their view are still noisy, and the view
    is better for every frame averaged in; only a frame the network was sure of settles it."""
    trigger = ViewTrigger(PipelineConfig(infer="on-change", settled_score=0.85, settle_max_doubt=1.1))
    start = 1_000_000
    trigger.inferred(start, (0, 0), None, doubt=1.0)
    trigger.inferred(start + 12_000, (0, 0), 0.93, doubt=1.8)  # agreed, but doubted (10 lux: ~1.6-2.2)
    assert not trigger.settled and trigger.due(start + 24_000, start, 1600, 9000, (0, 0))
    trigger.inferred(start + 24_000, (0, 0), 0.93, doubt=1.1)  # agreed and sure (100 lux: ~1.0-1.4)
    assert trigger.settled and not trigger.due(start + 36_000, start, 1600, 9000, (0, 0))
    trigger.inferred(start + 424_000, (0, 0), 0.93)  # no probability (fuse = "mask"): agreement alone settles
    assert trigger.settled
