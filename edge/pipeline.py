"""The real-time loop: source thread -> ring -> (fovea at the gaze -> voxel -> U-Net) -> frames.

Two threads meet here. The source's reader thread calls :meth:`Pipeline.sink`, which only pushes
the chunk into the :class:`EventRing` and counts how many of its events fall inside the *current*
foveal window. The reconstruction thread wakes when ``n_events`` new foveated events arrived (or
every ``period_ms``), looks up the gaze at the newest event, and runs the pure core
:func:`make_frame` (choose window -> crop -> voxel -> infer). If inference fell behind, it jumps to
the newest window and counts the windows it skipped; the ring is fixed-size, so memory never grows
with load. In ``lossless`` mode (offline replays) the reader thread reconstructs each window
itself, so it waits for inference instead of skipping.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from darkread.edge.events import Events
from darkread.edge.fovea import FoveaConfig, crop, window_origin
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.ring import EventRing
from darkread.edge.sources.base import EventSource
from darkread.edge.voxel import VoxelConfig, voxel_grid
from darkread.frame_record import FrameRecord

if TYPE_CHECKING:
    from darkread.proto.messages import Frame

logger = logging.getLogger(__name__)

MIN_HISTORY_EVENTS = 4096

Infer = Callable[[np.ndarray], np.ndarray]
"""Voxel grid [bins, H, W] float32 -> ink mask [H, W] uint8 (a ``Reconstructor``)."""


class GazeLookup(Protocol):
    """Where the wearer looks at an event time (``GazeMapper`` or a live feed)."""

    def pixel_at(self, t_event_us: int) -> tuple[float, float] | None: ...
    def angles_at(self, t_event_us: int) -> tuple[float, float] | None: ...


@dataclass(frozen=True)
class PipelineSettings:
    n_events: int = 1600  # foveated events per voxel grid; that many new ones trigger a frame
    period_ms: float = 50.0  # a frame at least this often when some new foveated events arrived
    fovea: FoveaConfig = field(default_factory=FoveaConfig)
    bins: int = 4
    history_events: int = 1 << 16  # usual cap of the ring events searched for a window's events
    lossless: bool = False  # the reader reconstructs (waits for inference) instead of skipping windows
    stall_s: float = 5.0  # no events for this long: stop feeding the watchdog (a sensor always has noise)
    sensor_roi: bool = False  # follow the window with the source's ROI (less USB traffic; sees only the window)

    @property
    def voxel(self) -> VoxelConfig:
        return VoxelConfig(bins=self.bins, n_events=self.n_events, height=self.fovea.height, width=self.fovea.width)


@dataclass(frozen=True)
class FrameResult(FrameRecord):
    """The frame record of one reconstructed foveal window, with how it was made."""

    gaze_rad: tuple[float, float]  # (yaw, pitch), radians
    events_used: int
    inference_ms: float

    def to_message(self) -> Frame:
        """The wire message (``seq`` is assigned by the uplink)."""
        from darkread.proto.messages import Frame  # lazily: the core needs no msgpack

        return Frame.of(self, gaze_rad=self.gaze_rad, events_used=self.events_used)


# -- the pure core -------------------------------------------------------------------------------


def count_in_window(events: Events, origin: tuple[int, int] | None, cfg: FoveaConfig) -> int:
    """How many ``events`` fall inside the window at ``origin`` (0 without a window)."""
    if origin is None or events.shape[0] == 0:
        return 0
    dx = events["x"] - np.uint16(origin[0])  # uint16 wrap: one comparison tests both bounds
    dy = events["y"] - np.uint16(origin[1])
    return int(np.count_nonzero((dx < cfg.width) & (dy < cfg.height)))


def window_events(recent: Events, origin: tuple[int, int], settings: PipelineSettings) -> Events:
    """The newest ``n_events`` of ``recent`` inside the window at ``origin``."""
    inside = crop(recent, origin[0], origin[1], settings.fovea)
    return inside[-settings.n_events :]


def make_frame(
    events: Events,
    gaze_px: tuple[float, float],
    gaze_rad: tuple[float, float],
    sensor_wh: tuple[int, int],
    settings: PipelineSettings,
    infer: Infer,
    frame_id: int,
) -> FrameResult | None:
    """Choose the window at the gaze, crop, bin, infer. None when the window holds no events."""
    origin = window_origin(gaze_px, sensor_wh, settings.fovea)
    window = window_events(events, origin, settings)
    if window.shape[0] == 0:
        return None
    voxel = voxel_grid(window, origin[0], origin[1], settings.voxel)
    started = time.perf_counter()
    mask = np.asarray(infer(voxel), dtype=np.uint8)
    inference_ms = (time.perf_counter() - started) * 1e3
    return FrameResult(
        frame_id=frame_id,
        t_us=int(window["t"][-1]),
        origin=origin,
        gaze_px=(float(gaze_px[0]), float(gaze_px[1])),
        gaze_rad=(float(gaze_rad[0]), float(gaze_rad[1])),
        events_used=int(window.shape[0]),
        mask=mask,
        inference_ms=inference_ms,
    )


# -- the threads ---------------------------------------------------------------------------------

FrameHandler = Callable[[FrameResult, float], None]
"""Receives each frame and the ``time.monotonic()`` at which its newest event arrived."""


class Pipeline:
    """Wires a source, a gaze lookup and a reconstructor; frames go to ``on_frame``."""

    def __init__(
        self,
        source: EventSource,
        gaze: GazeLookup,
        infer: Infer,
        on_frame: FrameHandler,
        settings: PipelineSettings = PipelineSettings(),
        metrics: EdgeMetrics | None = None,
        ring_capacity: int = 1 << 19,
        watchdog: Callable[[], object] | None = None,
    ) -> None:
        self.source = source
        self.gaze = gaze
        self.infer = infer
        self.on_frame = on_frame
        self.settings = settings
        self.metrics = metrics or EdgeMetrics()
        self.ring = EventRing(ring_capacity)
        self.watchdog = watchdog
        self.sensor_wh = (int(source.width), int(source.height))
        self.frames_made = 0
        self.error: BaseException | None = None
        self._origin: tuple[int, int] | None = None
        self._new_foveated = 0
        self._new_events = 0
        self._last_arrival = 0.0
        self._period_t0: int | None = None  # lossless mode: event time of the last period start
        self._started_at = 0.0
        self._ring_dropped = 0
        self._history = MIN_HISTORY_EVENTS
        self._cond = threading.Condition()
        self._step_lock = threading.Lock()
        self._source_done = threading.Event()
        self._thread: threading.Thread | None = None

    # -- reader thread ----------------------------------------------------------------------
    def sink(self, events: Events) -> None:
        if events.shape[0] == 0:
            return
        self.ring.push(events)
        n_foveated = count_in_window(events, self._origin, self.settings.fovea)
        self.metrics.add("events_in", int(events.shape[0]))
        self.metrics.add("events_foveated", n_foveated)
        if self.ring.dropped != self._ring_dropped:
            self.metrics.add("events_dropped", self.ring.dropped - self._ring_dropped)
            self._ring_dropped = self.ring.dropped
        with self._cond:
            # before the first window is placed every event counts, so the loop wakes to place it
            self._new_foveated += n_foveated if self._origin is not None else int(events.shape[0])
            self._new_events += int(events.shape[0])
            self._last_arrival = time.monotonic()
            due = self._new_foveated >= self.settings.n_events
            if self.settings.lossless:
                due = due or self._event_period_due(int(events["t"][-1]))
            elif due:
                self._cond.notify()
        if due and self.settings.lossless:
            # no clock to keep up with: reconstruct right here, so the reader waits for inference
            self._process(self._take())

    def _event_period_due(self, t_newest: int) -> bool:
        """Lossless mode's ``period_ms``, counted on the event clock so a replay is reproducible."""
        if self._period_t0 is None:
            self._period_t0 = t_newest
        if self._new_foveated > 0 and t_newest - self._period_t0 >= self.settings.period_ms * 1e3:
            self._period_t0 = t_newest
            return True
        return False

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("pipeline already started")
        self._started_at = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="edge-reconstruct", daemon=True)
        self._thread.start()
        self.source.start(self.sink)

    def stop(self) -> None:
        """Stop the source, then let the loop make the last frame from what is buffered."""
        self.source.stop()
        self._source_done.set()
        with self._cond:
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=10.0)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # -- reconstruction thread ------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # surfaced to the daemon, which exits non-zero
            self.error = exc
            logger.exception("reconstruction loop failed")

    def _loop(self) -> None:
        period_s = self.settings.period_ms / 1e3
        k = self.settings.n_events
        lossless = self.settings.lossless  # then the reader reconstructs; this loop only ticks
        while True:
            with self._cond:
                self._cond.wait_for(
                    lambda: (self._new_foveated >= k and not lossless) or self._source_done.is_set(), timeout=period_s
                )
                final = self._source_done.is_set()
            if self.watchdog is not None and self._alive():
                self.watchdog()
            if lossless and not final:
                continue  # the reader makes every frame (on the event clock); the timer only feeds the watchdog
            self._process(self._take())
            if final:
                return

    def _alive(self) -> bool:
        """Events arrived recently (or the source is still starting): the pipeline is not stalled."""
        last = self._last_arrival or self._started_at
        return time.monotonic() - last < self.settings.stall_s

    def _take(self) -> tuple[int, int, float, bool]:
        """Claim the pending counts: (new foveated, new events, newest arrival, window placed)."""
        with self._cond:
            taken = (self._new_foveated, self._new_events, self._last_arrival, self._origin is not None)
            self._new_foveated = self._new_events = 0
        return taken

    def _process(self, taken: tuple[int, int, float, bool]) -> None:
        new, new_events, arrival, had_window = taken
        k = self.settings.n_events
        with self._step_lock:
            if new > k and had_window and not self.settings.lossless:
                self.metrics.add("frames_skipped", new // k - 1)
            if new > 0 or (self._origin is None and new_events > 0):
                self._step(new, arrival)

    def _step(self, new_foveated: int, arrival: float) -> None:
        t_newest = self.ring.newest_t
        if t_newest is None:
            return
        gaze_px = self.gaze.pixel_at(t_newest)
        gaze_rad = self.gaze.angles_at(t_newest) if gaze_px is not None else None
        if gaze_px is None or gaze_rad is None:
            self.metrics.add("frames_no_gaze")  # events arrived, but nowhere to look
            self._origin = None
            return
        origin = window_origin(gaze_px, self.sensor_wh, self.settings.fovea)
        moved = origin != self._origin
        self._origin = origin
        if moved and self.settings.sensor_roi:
            self.source.set_roi(origin[0], origin[1], self.settings.fovea.width, self.settings.fovea.height)
        if new_foveated == 0 and not moved:
            return
        recent = self._recent_events(origin)
        frame = make_frame(recent, gaze_px, gaze_rad, self.sensor_wh, self.settings, self.infer, self.frames_made)
        if frame is None:
            return
        self.frames_made += 1
        self.metrics.add("frames")
        self.metrics.observe_inference(frame.inference_ms)
        self.on_frame(frame, arrival)

    def _recent_events(self, origin: tuple[int, int]) -> Events:
        """The newest ``n_events`` inside the window, searching back through the ring as needed.

        The search starts from twice the depth the previous window needed, so a frame copies a
        few thousand ring events, not the whole history.
        """
        k, cfg = self.settings.n_events, self.settings.fovea
        n = self._history
        while True:
            recent = self.ring.last(n)
            dx = recent["x"] - np.uint16(origin[0])
            dy = recent["y"] - np.uint16(origin[1])
            inside = np.flatnonzero((dx < cfg.width) & (dy < cfg.height))
            if inside.shape[0] >= k or n >= len(self.ring):
                break
            n *= 2
        used = inside[-k:]
        if used.shape[0]:
            depth = recent.shape[0] - int(used[0])
            self._history = int(min(max(2 * depth, MIN_HISTORY_EVENTS), self.settings.history_events))
        return recent[used]
