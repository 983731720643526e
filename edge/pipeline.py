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

That is the ``every-window`` mode (for research and evaluation). ``on-change`` (``[pipeline] infer``, the default) lets the gaze
decide (:mod:`darkread.edge.view_trigger`): every chunk the reader hands over is one processing
step that feeds the gaze-event classifier; no inference during saccades and blinks; during a
fixation one when enough new events arrived, at most every ``min_interval_ms`` until a frame agrees
with the view (then none until it is sent), all in one window
placed at the fixation's mean gaze; the fixation's frames are fused into one view
(:mod:`darkread.edge.view_fusion`) that goes to ``on_frame`` when the fixation ends and every
``view_every_ms`` during a long one. The same step runs on the reconstruction thread live and on
the reader thread in lossless replays.

The window's size and the bin count come from the model (``voxel``, see ``Reconstructor.voxel``);
the loop's settings are the config's :class:`~darkread.edge.config.PipelineConfig`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.edge.config import PipelineConfig
from darkread.edge.deblur import DeblurConfig, deblur_window
from darkread.edge.denoise import DenoiseConfig, drop_isolated
from darkread.edge.events import Events
from darkread.edge.fovea import FoveaConfig, in_window, window_origin
from darkread.edge.gaze import GazeLookup, GazeSample
from darkread.edge.head_motion import KnownHeadMotion
from darkread.edge.ring import EventRing
from darkread.edge.scene_motion import SceneMotion
from darkread.edge.sources.base import EventSource
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.view_fusion import MARGIN_PX, ViewFuser, ViewRecord
from darkread.edge.view_trigger import GazeGate, ViewTrigger, fixation_key
from darkread.edge.voxel import VoxelConfig, voxel_grid

if TYPE_CHECKING:
    from darkread.proto.messages import Frame

logger = logging.getLogger(__name__)

MIN_HISTORY_EVENTS = 4096
LOSSLESS_STEP_US = 5_000
"""Lossless on-change replays take one processing step per this much event time (a grid on the
event clock, finer than any gaze row at 11-100 ms), however large the chunks the source hands over:
the same steps, and so the same views, whatever the replay's chunking."""
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
    # the network's calibrated ink probability (float32 [h, w]) when asked for (views are fused
    # from it); never sent: a frame goes on the wire as its binary mask
    probability: np.ndarray | None = field(default=None, kw_only=True, repr=False, compare=False)

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


def step_ends(t_us: np.ndarray, step_us: int) -> np.ndarray:
    """End indices (exclusive) of the non-empty pieces of time-sorted ``t_us`` cut at multiples of
    ``step_us``: the slices an ``EventsIterator`` with ``delta_t=step_us`` would have made of them."""
    n = t_us.shape[0]
    first, last = int(t_us[0]) // step_us, int(t_us[-1]) // step_us
    if first == last:
        return np.array([n], dtype=np.intp)
    bounds = np.arange(first + 1, last + 1, dtype=np.int64) * step_us
    # a running maximum keeps the cuts ordered when times jitter back by a few µs (real sensors)
    cuts = np.maximum.accumulate(np.searchsorted(t_us, bounds, side="left"))
    ends = np.unique(np.append(cuts, n))
    return ends[ends > 0]


def clean_window(
    window: Events,
    nearby: Events,
    origin: tuple[int, int],
    shape_hw: tuple[int, int],
    sensor_wh: tuple[int, int],
    deblur: DeblurConfig = DeblurConfig(),
    denoise: DenoiseConfig = DenoiseConfig(),
    known_motion: KnownHeadMotion | None = None,
) -> tuple[Events, bool, bool]:
    """A window's events as the network is given them: moved back along the head's motion during
    their span (``edge.deblur``, measured from them and ``nearby``, the sensor's events of that span
    around the window; or by ``known_motion`` when given: ``edge.head_motion``), then in dim light
    without those that have no neighbour (``edge.denoise``); and whether each step changed them.
    The edge and the training windows (``train.windows``) both cut windows this way."""
    if known_motion is not None:
        cleaned, moved = known_motion.warp(window, origin, shape_hw), window.shape[0] > 0
    else:
        cleaned, smear = deblur_window(window, nearby, origin, shape_hw, sensor_wh, deblur)
        moved = smear != (0.0, 0.0)
    before = cleaned.shape[0]
    cleaned = drop_isolated(cleaned, origin, shape_hw, denoise)
    return cleaned, moved, cleaned.shape[0] < before


def make_frame(
    window: Events,
    origin: tuple[int, int],
    gaze: GazeSample,
    t_us: int,
    voxel: VoxelConfig,
    infer: Infer,
    frame_id: int,
    scene_px: tuple[float, float] | None = None,
    probability: bool = False,
) -> FrameResult | None:
    """Bin the window's events and infer. None when the window holds no events.

    ``window`` are exactly the events to bin (``fovea.window_events``), all inside the window at
    ``origin``; ``t_us`` is the frame's timestamp, the time ``gaze`` was looked up; ``scene_px``
    the scene's motion by then (``edge.scene_motion``), if measured. ``probability``: keep the ink
    probability too, from an ``infer`` that has ``ink_probability`` (a ``Reconstructor``).
    """
    if window.shape[0] == 0:
        return None
    # a Reconstructor reads its input in place: bin straight into it (no grid allocated, no copies)
    bound = getattr(infer, "input_window", None)
    grid = voxel_grid(window, origin[0], origin[1], voxel, out=bound if bound is not None and bound.shape == voxel.shape else None)
    started = time.perf_counter()
    soft = getattr(infer, "ink_probability", None) if probability else None
    ink = soft(grid) if soft is not None else None
    mask = (ink > 0.5).astype(np.uint8) if ink is not None else np.asarray(infer(grid), dtype=np.uint8)
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
        scene_px=scene_px,
        probability=ink,
    )


# -- the threads ---------------------------------------------------------------------------------

FrameHandler = Callable[[FrameResult | ViewRecord, float], None]
"""Receives each frame (every-window) or view (on-change) and the ``time.monotonic()`` at which the
data that completed it arrived (its newest event, or the chunk that ended the fixation)."""


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
        known_motion: KnownHeadMotion | None = None,
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
        self.deblur = DeblurConfig(enabled=settings.deblur)
        self.denoise = DenoiseConfig(enabled=settings.denoise)
        self.frames_made = 0
        self.error: BaseException | None = None
        self._origin: tuple[int, int] | None = None
        self._new_foveated = 0
        self._new_events = 0
        self._last_arrival = 0.0
        self._period_t0: int | None = None  # lossless mode: event time of the last period start
        self._started_at = 0.0
        self._ring_overwritten = 0
        self._history = MIN_HISTORY_EVENTS
        self._cond = threading.Condition()
        self._step_lock = threading.Lock()
        self._source_done = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_t: int | None = None
        # the head's motion from all events (the reader thread pushes, the processing thread asks),
        # unless it is known from elsewhere (``edge.head_motion``: then it is neither measured nor searched)
        self.known_motion = known_motion
        measure_scene = settings.scene_motion and not settings.sensor_roi and known_motion is None
        self.scene = SceneMotion(self.sensor_wh) if measure_scene else None
        self._scene_lock = threading.Lock()
        self.on_change = settings.infer == "on-change"
        if self.on_change:
            self.gate = GazeGate(gaze)
            self.trigger = ViewTrigger(settings)
            # the canvas reaches as far as the head drifts, beyond both dithered windows
            self.fuser = ViewFuser(margin_px=MARGIN_PX + 2 * settings.dither_px)
            self.views_made = 0
            self._chunks = 0  # chunks not yet looked at by a processing step
            self._fixation: int | None = None  # the current fixation's key (its first row, event clock)
            self._fixation_events = 0  # window events since it started
            self._since_infer = 0  # window events since the last inference
            self._view_origin: tuple[int, int] | None = None  # the current view's window (placed once per view)
            self._open_piece: tuple[int, int, int] | None = None  # lossless: (grid index, newest t, new events) not yet stepped

    # -- reader thread ----------------------------------------------------------------------
    def sink(self, events: Events) -> None:
        if events.shape[0] == 0:
            return
        if self.scene is not None:
            with self._scene_lock:
                self.scene.push(events)
        if self.on_change and self.settings.lossless:
            self._sink_steps(events)
            return
        self.ring.push(events)
        n_foveated = count_in_window(events, self._origin, self.fovea)
        self._count_arrival(events, n_foveated)
        with self._cond:
            # before the first window is placed every event counts, so the loop wakes to place it
            self._new_foveated += n_foveated if self._origin is not None else int(events.shape[0])
            self._new_events += int(events.shape[0])
            self._last_arrival = time.monotonic()
            if self.on_change:
                self._chunks += 1
                self._cond.notify()
        if self.on_change:
            return
        with self._cond:
            due = self._new_foveated >= self.settings.n_events
            if self.settings.lossless:
                due = due or self._event_period_due(int(events["t"][-1]))
            elif due:
                self._cond.notify()
        if due and self.settings.lossless:
            # no clock to keep up with: reconstruct right here, so the reader waits for inference
            self._process(self._take())

    def _count_arrival(self, events: Events, n_foveated: int) -> None:
        """The reader's metrics of one chunk: events in, inside the window, reading time, ring history overwritten."""
        self.metrics.add("events_in", int(events.shape[0]))
        self.metrics.add("events_foveated", n_foveated)
        t_newest = int(events["t"][-1])
        if self._last_t is not None and t_newest > self._last_t:
            self.metrics.add("event_us", t_newest - self._last_t)  # reading time covered: the CPU-per-second figure
        self._last_t = t_newest
        if self.ring.overwritten != self._ring_overwritten:
            self.metrics.add("events_overwritten", self.ring.overwritten - self._ring_overwritten)
            self._ring_overwritten = self.ring.overwritten

    def _sink_steps(self, events: Events) -> None:
        """Lossless on-change: the chunk into the ring at once, then one processing step per piece
        of it on the ``LOSSLESS_STEP_US`` grid, each seeing its piece's newest event as "now".

        A step cuts its window at its own time (``_recent_events``), so the events after it in the
        ring change nothing; a piece's count inside the window comes from one window test per
        chunk (again only after a step moved the window). The piece a chunk ends in may go on in
        the next chunk, so its step waits for that chunk (or the end of the stream): any chunking
        makes the steps 5 ms slices would have made. Per piece that leaves a few integer
        operations and the decision itself.
        """
        if events.shape[0] > self.ring.capacity // 8:  # keep the ring's history far longer than a chunk
            half = events.shape[0] // 2
            self._sink_steps(events[:half])
            self._sink_steps(events[half:])
            return
        self.ring.push(events)
        t = events["t"]
        ends = step_ends(t, LOSSLESS_STEP_US)
        last = ends.shape[0] - 1
        fov = self.fovea
        counted_origin: tuple[int, int] | None = None
        inside_before: list[int] = []  # window events of the chunk before each piece's end, from `counted_at`
        counted_at = 0
        n_foveated = 0
        start = 0
        with self._step_lock:
            self._last_arrival = arrival = time.monotonic()
            for i, (end, t_now) in enumerate(zip(ends.tolist(), t[ends - 1].tolist())):
                piece = t_now // LOSSLESS_STEP_US
                carried = 0
                if self._open_piece is not None:
                    open_piece, open_t, open_new = self._open_piece
                    self._open_piece = None
                    if open_piece == piece:
                        carried = open_new  # the last chunk's last piece goes on here
                    else:
                        self._decide(open_t, open_new, arrival)
                origin = self._origin
                if origin is None:
                    new = end - start  # before the first window is placed every event counts
                else:
                    if origin != counted_origin:  # (the first piece, or a step moved the window)
                        inside = np.flatnonzero(in_window(events[start:], origin[0], origin[1], fov.width, fov.height))
                        inside_before = np.searchsorted(inside, ends[i:] - start).tolist()
                        counted_origin, counted_at = origin, i
                    j = i - counted_at
                    new = inside_before[j] - (inside_before[j - 1] if j else 0)
                    n_foveated += new
                if i == last:
                    self._open_piece = (piece, t_now, new + carried)  # stepped by the next chunk or at the end
                else:
                    self._decide(t_now, new + carried, arrival)
                start = end
        self._count_arrival(events, n_foveated)

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
                    lambda: (not lossless and (self._chunks if self.on_change else self._new_foveated >= k))
                    or self._source_done.is_set(),
                    timeout=period_s,
                )
                final = self._source_done.is_set()
            if self.watchdog is not None and self._alive():
                self.watchdog()
            if lossless and not final:
                continue  # the reader makes every frame (on the event clock); the timer only feeds the watchdog
            if self.on_change:
                self._change_step(final=final)
            else:
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
        frame = make_frame(window, origin, gaze, t_frame, self.voxel, self.infer, self.frames_made, self._scene_at(t_frame))
        if frame is None:
            return
        self.frames_made += 1
        self.metrics.add("frames")
        self.metrics.observe_inference(frame.inference_ms)
        self.on_frame(frame, arrival)

    # -- on-change: one processing step per chunk ----------------------------------------------
    def _change_step(self, final: bool = False) -> None:
        """Feed the gaze classifier up to the newest event; end, extend or start the fixation's view."""
        with self._step_lock:
            if self._open_piece is not None:  # lossless: the stream's last piece, complete now
                _, open_t, open_new = self._open_piece
                self._open_piece = None
                self._decide(open_t, open_new, self._last_arrival)
            with self._cond:
                new, arrival = self._new_foveated, self._last_arrival
                self._new_foveated = self._chunks = 0
            t = self.ring.newest_t
            if t is None:
                return
            self._decide(t, new, arrival, final)

    def _decide(self, t: int, new: int, arrival: float, final: bool = False) -> None:
        """One step at event time ``t`` with ``new`` window events since the last (step lock held)."""
        status = self.gate.update(t)
        key = None if final else fixation_key(status)
        # a later key is a new fixation; an earlier one is the classifier merging two halves of this one
        if self._fixation is not None and (key is None or key > self._fixation):
            self._end_view(arrival, t if final else min(t, status.since_us))
            self._fixation = None
        if key is None:
            return  # saccade, blink, no gaze: nothing to infer
        if self._fixation is None:
            self._fixation, self._fixation_events, self._since_infer = key, 0, 0
            self.trigger.reset()
        self._fixation_events += new
        self._since_infer += new
        if len(self.fuser) and t - self.fuser.t0_us >= self.settings.view_every_ms * 1e3:
            self._send_view(arrival)  # a long fixation: its view so far, the next one starts afresh
        if not self.trigger.ready(t, self._fixation):
            return  # the bounded rate (and the landing's wait), checked before anything costs
        window = self._view_window(t)
        if window is None:
            return
        origin, gaze = window
        if self.trigger.due(t, self._fixation, self._since_infer, self._fixation_events, origin):
            self._infer_into_view(origin, gaze, t, self._fixation, arrival)

    def _view_window(self, t: int) -> tuple[tuple[int, int], GazeSample] | None:
        """Where the current view's window is, and the gaze at ``t``. A view's window stays put: it
        is placed once, at the mean gaze of the fixation's rows so far (one row's tracker noise
        would put it tens of pixels off), so its frames all see the same stretch of text."""
        gaze = self.gaze.at(t)
        if gaze is None:
            return None
        if len(self.fuser) and self._view_origin is not None:
            return self._view_origin, gaze
        centre = self._fixation_centre(t) or gaze.pixel
        origin = window_origin(centre, self.sensor_wh, self.fovea)
        if origin != self._origin and self.settings.sensor_roi:
            self._roi_for_view(origin)
        self._origin = self._view_origin = origin
        return origin, gaze

    def _fixation_centre(self, t: int) -> tuple[float, float] | None:
        """Mean gaze pixel over the current fixation's valid tracker rows up to ``t`` (None without any)."""
        if self._fixation is None:
            return None
        times, yaw, _ = self.gaze.rows(self._fixation - 1, t)
        pixels = [g.pixel for g in map(self.gaze.at, times[np.isfinite(yaw)].tolist()) if g is not None]
        if not pixels:
            return None
        u, v = np.mean(np.asarray(pixels, np.float64), axis=0)
        return float(u), float(v)

    def _infer_into_view(self, origin: tuple[int, int], gaze: GazeSample, t: int, t_from: int, arrival: float) -> bool:
        """One frame of the current fixation (its events only, up to ``n_events``), fused into the
        view; a frame that does not register onto the view sends it and starts the next one."""
        placed = self._dithered(origin, len(self.fuser))
        window = self._recent_events(placed, t, t_from=t_from)
        if window.shape[0] < min(self.settings.min_events, self.settings.n_events):
            return False
        soft = self.settings.fuse == "probability"
        frame = make_frame(window, placed, gaze, t, self.voxel, self.infer, self.frames_made, self._scene_at(t), probability=soft)
        if frame is None:
            return False
        self.frames_made += 1
        self.metrics.add("frames")
        self.metrics.observe_inference(frame.inference_ms)
        if self.fuser.add(frame, frame.events_used, frame.gaze_rad, frame.probability) is None:
            self.metrics.add("views_split")
            self._send_view(arrival)
            self.fuser.add(frame, frame.events_used, frame.gaze_rad, frame.probability)
        self.trigger.inferred(t, origin, self.fuser.last_score, self.fuser.last_doubt)
        self._since_infer = 0
        return True

    def _roi_for_view(self, origin: tuple[int, int]) -> None:
        """The sensor's ROI over the view's window and both dithered ones (all its frames' events)."""
        top, bottom = self._dithered(origin, 0), self._dithered(origin, 1)
        y0, y1 = min(origin[1], top[1]), max(origin[1], bottom[1]) + self.fovea.height
        self.source.set_roi(origin[0], y0, self.fovea.width, y1 - y0)

    def _dithered(self, origin: tuple[int, int], k: int) -> tuple[int, int]:
        """The window of a view's ``k``-th frame: the view's window moved up (even ``k``) or down
        (odd) by ``dither_px``, inside the sensor. The tracker's bias (about 1 deg) puts the line
        being read anywhere in the window, often at its edge; two frames a few tens of pixels apart
        see it whole, and the view is the union of its frames' windows."""
        d = self.settings.dither_px
        if d <= 0:
            return origin
        fov = self.fovea
        dy = -d if k % 2 == 0 else d
        centre = (origin[0] + fov.width // 2, origin[1] + fov.height // 2 + dy)
        return window_origin(centre, self.sensor_wh, fov)

    def _end_view(self, arrival: float, t_end: int) -> None:
        """The fixation ended at ``t_end``: a fixation too short for a frame gets one now; send its view."""
        lasted = self._fixation is not None and t_end - self._fixation >= self.gate.cfg.min_fixation_ms * 1e3
        if not len(self.fuser) and lasted and self._origin is not None:  # (not a landing the classifier revised)
            window = self._view_window(t_end)
            if window is not None and self._fixation is not None:
                self._infer_into_view(window[0], window[1], t_end, self._fixation, arrival)
        if len(self.fuser):
            self._send_view(arrival)

    def _send_view(self, arrival: float) -> None:
        view = self.fuser.view(self.views_made)
        self.fuser = self.fuser.fresh()
        self._view_origin = None
        self.views_made += 1
        self.metrics.add("views")
        self.on_frame(view, arrival)

    def _scene_at(self, t_us: int) -> tuple[float, float] | None:
        """The scene's motion at ``t_us`` (None when not measured)."""
        if self.known_motion is not None:
            return self.known_motion.scene_px(t_us)
        if self.scene is None:
            return None
        with self._scene_lock:
            return self.scene.at(t_us)

    def _recent_events(self, origin: tuple[int, int], t_until: int, t_from: int | None = None) -> Events:
        """Exactly the window's events for one frame: the newest ``n_events`` inside the window at
        ``origin`` with ``t <= t_until`` (and ``t >= t_from``), searching back through the ring as needed,
        moved back along the head's motion during their span (``edge.deblur``; measured from them and
        the sensor's other events of that span around the window), and in dim light without those
        that have no neighbour: shot noise (``edge.denoise``; a frame may then have fewer events).

        The search starts from twice the depth the previous window needed, so a frame copies a
        few thousand ring events, not the whole history.
        """
        k, cfg = self.settings.n_events, self.fovea
        n = self._history
        while True:
            recent = self.ring.last(n, until_t=t_until)  # (the reader may have pushed newer events)
            inside = np.flatnonzero(in_window(recent, origin[0], origin[1], cfg.width, cfg.height))
            reached_start = t_from is not None and recent.shape[0] and int(recent["t"][0]) <= t_from
            if inside.shape[0] >= k or n >= len(self.ring) or reached_start:
                break
            n *= 2
        if t_from is not None and inside.shape[0]:
            inside = inside[recent["t"][inside] >= t_from]
        used = inside[-k:]
        if used.shape[0]:
            depth = recent.shape[0] - int(used[0])
            self._history = int(min(max(2 * depth, MIN_HISTORY_EVENTS), MAX_HISTORY_EVENTS))
        nearby = recent[int(used[0]) :] if used.shape[0] else recent[:0]
        window, deblurred, denoised = clean_window(recent[used], nearby, origin, (cfg.height, cfg.width), self.sensor_wh,
                                                   self.deblur, self.denoise, self.known_motion)
        if deblurred:
            self.metrics.add("frames_deblurred")
        if denoised:
            self.metrics.add("frames_denoised")
        return window
