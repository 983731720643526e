"""The real-time loop: source thread -> ring -> (fovea at the gaze -> voxel -> U-Net) -> frames.

Two threads meet here. The source's reader thread calls :meth:`Pipeline.sink`, which only pushes
the chunk into the :class:`EventRing` and counts how many of its events fall inside the *current*
foveal window. The reconstruction thread wakes when ``n_events`` new foveated events arrived (or
every ``period_ms``), takes the newest event time ``t`` as the frame's one timestamp, looks up the
gaze at ``t``, places the window there, collects exactly the window's newest ``n_events`` (up to
``t``) and runs the pure core :func:`make_frame` (voxel -> infer). If inference fell behind, it
jumps to the newest window and counts the windows it skipped; the ring is fixed-size, so memory
never grows with load. In ``lossless`` mode (offline replays) the reader thread reconstructs each
window itself, so it waits for inference instead of skipping.

The window's size and the bin count come from the model (``voxel``, see ``Reconstructor.voxel``);
the loop's settings are the config's :class:`~darkread.edge.config.PipelineConfig`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from darkread.edge.config import PipelineConfig
from darkread.edge.events import Events
from darkread.edge.fovea import FoveaConfig, in_window, window_origin
from darkread.edge.gaze import GazeLookup, GazeSample
from darkread.edge.ring import EventRing
from darkread.edge.sources.base import EventSource
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.voxel import VoxelConfig, voxel_grid
from darkread.frame_record import FrameRecord

if TYPE_CHECKING:
    from darkread.proto.messages import Frame

logger = logging.getLogger(__name__)

MIN_HISTORY_EVENTS = 4096
MAX_HISTORY_EVENTS = 1 << 16  # usual cap of the ring events searched for a window's events

Infer = Callable[[np.ndarray], np.ndarray]
"""Voxel grid [bins, H, W] float32 -> ink mask [H, W] uint8 (a ``Reconstructor``)."""


@dataclass(frozen=True)
class FrameResult(FrameRecord):
    """The frame record of one reconstructed foveal window, with how it was made.

    ``t_us`` is the frame's one timestamp (event clock): the newest event when it was made, the
    time its gaze was looked up and the last time its events may have.
    """

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
    return int(np.count_nonzero(in_window(events, origin[0], origin[1], cfg.width, cfg.height)))


def make_frame(
    window: Events,
    origin: tuple[int, int],
    gaze: GazeSample,
    t_us: int,
    voxel: VoxelConfig,
    infer: Infer,
    frame_id: int,
) -> FrameResult | None:
    """Bin the window's events and infer. None when the window holds no events.

    ``window`` are exactly the events to bin (``fovea.window_events``), all inside the window at
    ``origin``; ``t_us`` is the frame's timestamp, the time ``gaze`` was looked up.
    """
    if window.shape[0] == 0:
        return None
    grid = voxel_grid(window, origin[0], origin[1], voxel)
    started = time.perf_counter()
    mask = np.asarray(infer(grid), dtype=np.uint8)
    inference_ms = (time.perf_counter() - started) * 1e3
    return FrameResult(
        frame_id=frame_id,
        t_us=int(t_us),
        origin=origin,
        gaze_px=gaze.pixel,
        gaze_rad=gaze.angles,
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
        settings: PipelineConfig = PipelineConfig(),
        voxel: VoxelConfig = VoxelConfig(),
        metrics: EdgeMetrics | None = None,
        watchdog: Callable[[], object] | None = None,
    ) -> None:
        self.source = source
        self.gaze = gaze
        self.infer = infer
        self.on_frame = on_frame
        self.settings = settings
        self.voxel = voxel
        self.fovea = voxel.fovea
        self.metrics = metrics or EdgeMetrics()
        self.ring = EventRing(settings.ring_capacity)
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
        n_foveated = count_in_window(events, self._origin, self.fovea)
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
        t_frame = self.ring.newest_t  # the frame's one timestamp: its gaze, its stamp, its newest event
        if t_frame is None:
            return
        gaze = self.gaze.at(t_frame)
        if gaze is None:
            self.metrics.add("frames_no_gaze")  # events arrived, but nowhere to look
            self._origin = None
            return
        origin = window_origin(gaze.pixel, self.sensor_wh, self.fovea)
        moved = origin != self._origin
        self._origin = origin
        if moved and self.settings.sensor_roi:
            self.source.set_roi(origin[0], origin[1], self.fovea.width, self.fovea.height)
        if new_foveated == 0 and not moved:
            return
        window = self._recent_events(origin, t_frame)
        frame = make_frame(window, origin, gaze, t_frame, self.voxel, self.infer, self.frames_made)
        if frame is None:
            return
        self.frames_made += 1
        self.metrics.add("frames")
        self.metrics.observe_inference(frame.inference_ms)
        self.on_frame(frame, arrival)

    def _recent_events(self, origin: tuple[int, int], t_until: int) -> Events:
        """Exactly the window's events for one frame: the newest ``n_events`` inside the window at
        ``origin`` with ``t <= t_until``, searching back through the ring as needed.

        The search starts from twice the depth the previous window needed, so a frame copies a
        few thousand ring events, not the whole history.
        """
        k, cfg = self.settings.n_events, self.fovea
        n = self._history
        while True:
            recent = self.ring.last(n)
            if recent.shape[0] and recent["t"][-1] > t_until:  # the reader pushed newer events meanwhile
                recent = recent[: int(np.searchsorted(recent["t"], t_until, side="right"))]
            inside = np.flatnonzero(in_window(recent, origin[0], origin[1], cfg.width, cfg.height))
            if inside.shape[0] >= k or n >= len(self.ring):
                break
            n *= 2
        used = inside[-k:]
        if used.shape[0]:
            depth = recent.shape[0] - int(used[0])
            self._history = int(min(max(2 * depth, MIN_HISTORY_EVENTS), MAX_HISTORY_EVENTS))
        return recent[used]
