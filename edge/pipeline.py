"""The real-time loop: source thread -> ring -> a step (fovea at the gaze -> voxel -> U-Net) -> frames.

The source's reader thread calls :meth:`Pipeline.sink`, which pushes the chunk into the
:class:`~darkread.edge.ring.EventRing` and counts how many of its events fall inside the *current*
foveal window. What a step does with them is its strategy's (:mod:`darkread.edge.steps`:
``on-change``, the product, or ``every-window``), chosen once where the pipeline is built
(:func:`darkread.edge.builder.build_pipeline`). Where a step runs is this module's only choice,
and the one place live and lossless differ:

- live (a camera, a paced replay): the reconstruction thread wakes when the step is due (or every
  ``period_ms``) and steps with all that arrived meanwhile, at the newest event's time; if inference
  fell behind, the step jumps to the newest window (the ring is fixed-size, so memory never grows
  with load) and the windows it skipped are counted. How long the oldest data a step takes has
  waited is its lag: a lag that stays long sheds inferences (:mod:`darkread.edge.load`).
- lossless (offline replays): the reader thread steps itself, on the event clock, so it waits for
  inference instead of skipping and a replay is reproducible; the reconstruction thread only feeds
  the watchdog and takes the last step when the stream ends.

The window's size and the bin count come from the model (``voxel``, see ``Reconstructor.voxel``);
the loop's settings are the config's :class:`~darkread.edge.config.PipelineConfig`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from darkread.core.errors import DarkreadError
from darkread.edge.bias_control import BiasController
from darkread.edge.config import PipelineConfig
from darkread.edge.events import Events, concat_events
from darkread.edge.fovea import in_window
from darkread.edge.frame import count_in_window
from darkread.edge.load import LoadShedder
from darkread.edge.sources.base import EventSource
from darkread.edge.steps import Pending, Step
from darkread.edge.windows import Windows

logger = logging.getLogger(__name__)


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


class Pipeline:
    """Runs ``step`` on what ``source`` reads: the ring, the sink, and when and where a step runs."""

    def __init__(
        self,
        source: EventSource,
        windows: Windows,
        step: Step,
        settings: PipelineConfig,
        watchdog: Callable[[], object] | None = None,
        light: BiasController | None = None,
    ) -> None:
        self.source = source
        self.light = light  # sees every chunk: the light level, and the sensor's bias profile (edge.bias_control)
        self.windows = windows
        self.ring = windows.ring
        self.step = step
        self.settings = settings
        self.metrics = windows.metrics
        self.watchdog = watchdog
        self.shedder = LoadShedder()  # live only: lossless replays wait for inference instead
        self.error: BaseException | None = None
        self._pending = Pending()  # what arrived since the last step
        self._open_piece: tuple[int, int] | None = None  # lossless on a grid: (grid index, newest t) of a piece not yet stepped
        self._period_t0: int | None = None  # lossless: event time of the last period start
        self._started_at = 0.0
        self._ring_overwritten = 0
        self._last_t: int | None = None
        self._arrived_t: int | None = None  # live: the newest event time handed over
        self._gathered: list[Events] = []  # live: chunks held back until they cross a line of the step's grid
        self._gathered_n = 0
        self._gather_cell = 0
        self._gather_since = 0.0
        self._gather_lock = threading.Lock()
        self._stepped_t: int | None = None  # live: the event time of the last step
        self._cond = threading.Condition()
        self._step_lock = threading.Lock()
        self._source_done = threading.Event()
        self._thread: threading.Thread | None = None

    # -- reader thread ----------------------------------------------------------------------
    def sink(self, events: Events) -> None:
        """Reader thread: one chunk of events; live, gathered up to the step's grid (``_gather``)."""
        if events.shape[0] == 0:
            return
        if not self.settings.lossless:
            gathered = self._gather(events)
            if gathered is None:
                return
            events = gathered
        self._take(events)

    def _gather(self, events: Events) -> Events | None:
        """Live, on a strategy with a grid: chunks held back until they cross one of its lines (or
        wait a grid's worth of wall clock, or fill a sixteenth of the ring), then handed on as one.

        A camera's chunks can be far shorter than a step (a paced replay hands over 1-ms slices);
        everything a chunk costs before the step (the scene tracker, the light estimate, the ring,
        the window's count, waking the step) is then paid once per grid cell, as in a lossless
        replay. No step runs between two lines anyway (``_live_due``), so nothing waits longer."""
        grid = self.step.replay_grid_us
        if grid is None:
            return events
        with self._gather_lock:
            if not self._gathered:
                self._gather_cell = int(events["t"][0]) // grid
                self._gather_since = time.monotonic()
            self._gathered.append(events)
            self._gathered_n += int(events.shape[0])
            if (int(events["t"][-1]) // grid == self._gather_cell and self._gathered_n < self.ring.capacity // 16
                    and time.monotonic() - self._gather_since < grid / 1e6):
                return None
            return self._release_gathered()

    def _release_gathered(self) -> Events | None:
        """The chunks held back, as one (gather lock held); None when there are none."""
        if not self._gathered:
            return None
        events = self._gathered[0] if len(self._gathered) == 1 else concat_events(self._gathered)
        self._gathered, self._gathered_n = [], 0
        return events

    def _take(self, events: Events) -> None:
        """A chunk, seen by the scene tracker and the light estimate, then live or lossless."""
        self.windows.push_scene(events)
        if self.light is not None:
            origin, fovea = self.windows.origin, self.windows.fovea
            self.light.push(events, None if origin is None else (origin[0], origin[1], fovea.width, fovea.height))
        if self.settings.lossless:
            self._replay(events)
        else:
            self._arrive(events)

    def _arrive(self, events: Events) -> None:
        """Live: the chunk into the ring and counted; the reconstruction thread wakes when a step is due."""
        self.ring.push(events)
        origin = self.windows.origin
        n_foveated = count_in_window(events, origin, self.windows.fovea)
        self._count_arrival(events, n_foveated)
        with self._cond:
            # before the first window is placed every event counts, so the loop wakes to place it
            self._pending.add(n_foveated if origin is not None else int(events.shape[0]), int(events.shape[0]),
                              time.monotonic())
            self._arrived_t = int(events["t"][-1])
            if self._live_due():
                self._cond.notify()

    def _live_due(self) -> bool:
        """Live (condition held): the step is due, and on a strategy with a grid the events crossed
        one of its lines since the last step. A camera hands over chunks of any length (a paced
        replay 1-ms slices); stepping on the lossless replay's grid keeps a live step's work per
        second of events what the replays measure, whatever the chunking."""
        if not self.step.due(self._pending):
            return False
        grid = self.step.replay_grid_us
        if grid is None or self._stepped_t is None or self._arrived_t is None:
            return True
        return self._arrived_t // grid != self._stepped_t // grid

    def _replay(self, events: Events) -> None:
        """Lossless: the chunk into the ring at once, then the steps it makes due, right here, each
        seeing its piece's newest event as "now": one per piece of the step's grid
        (``replay_grid_us``), or after the chunk when due (or ``period_ms`` of event time passed).

        A step cuts its window at its own time (``Windows.recent_events``), so the events after it
        in the ring change nothing; a piece's count inside the window comes from one window test per
        chunk (again only after a step moved the window). On a grid the piece a chunk ends in may go
        on in the next chunk, so its step waits for that chunk (or the end of the stream): any
        chunking makes the steps slices of the grid would have made. Per piece that leaves a few
        integer operations and the step itself.
        """
        grid = self.step.replay_grid_us
        if grid is not None and events.shape[0] > self.ring.capacity // 8:  # keep the ring's history far longer than a chunk
            half = events.shape[0] // 2
            self._replay(events[:half])
            self._replay(events[half:])
            return
        self.ring.push(events)
        t = events["t"]
        ends = step_ends(t, grid) if grid is not None else np.array([t.shape[0]], dtype=np.intp)
        last = ends.shape[0] - 1
        fov = self.windows.fovea
        counted_origin: tuple[int, int] | None = None
        inside_before: list[int] = []  # window events of the chunk before each piece's end, from `counted_at`
        counted_at = 0
        n_foveated = 0
        start = 0
        with self._step_lock:
            with self._cond:
                self._pending.arrival = time.monotonic()
            for i, (end, t_now) in enumerate(zip(ends.tolist(), t[ends - 1].tolist())):
                piece = t_now // grid if grid is not None else i
                if self._open_piece is not None:
                    open_piece, open_t = self._open_piece
                    self._open_piece = None
                    if open_piece != piece:  # (else the last chunk's last piece goes on here)
                        self._step_at(open_t)
                origin = self.windows.origin
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
                with self._cond:
                    self._pending.add(new, end - start)
                    due = self.step.due(self._pending) or self._event_period_due(t_now)
                if grid is not None and i == last:
                    self._open_piece = (piece, t_now)  # stepped by the next chunk or at the end
                elif due:
                    self._step_at(t_now)
                start = end
        self._count_arrival(events, n_foveated)

    def _event_period_due(self, t_newest: int) -> bool:
        """Lossless mode's ``period_ms``, counted on the event clock so a replay is reproducible."""
        if self._period_t0 is None:
            self._period_t0 = t_newest
        if self._pending.foveated > 0 and t_newest - self._period_t0 >= self.settings.period_ms * 1e3:
            self._period_t0 = t_newest
            return True
        return False

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
        with self._gather_lock:
            rest = self._release_gathered()
        if rest is not None:  # the last chunks a live source handed over, not yet across a line
            self._take(rest)
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
            if isinstance(exc, DarkreadError):  # says what failed in words (a full spool disk): no traceback
                logger.error("reconstruction loop failed: %s", exc)
            else:
                logger.exception("reconstruction loop failed")

    def _loop(self) -> None:
        period_s = self.settings.period_ms / 1e3
        live = not self.settings.lossless  # lossless: the reader steps; this loop feeds the watchdog and steps the end
        while True:
            with self._cond:
                self._cond.wait_for(lambda: (live and self._live_due()) or self._source_done.is_set(),
                                    timeout=period_s)
                final = self._source_done.is_set()
            if self.watchdog is not None and self._alive():
                self.watchdog()
            if live or final:
                self._step_now(final)
            if final:
                return

    def _alive(self) -> bool:
        """Events arrived recently (or the source is still starting): the pipeline is not stalled."""
        last = self._pending.arrival or self._started_at
        return time.monotonic() - last < self.settings.stall_s

    def _step_now(self, final: bool = False) -> None:
        """A step with all that arrived, at the newest event's time (a piece a replay left open first)."""
        with self._step_lock:
            if self._open_piece is not None:  # lossless: the stream's last piece, complete now
                _, open_t = self._open_piece
                self._open_piece = None
                self._step_at(open_t)
            with self._cond:
                pending = self._pending.take()
            if not self.settings.lossless and not final:
                self._observe_lag(pending)
            skipped = self.step.skipped(pending)
            if skipped > 0:
                self.metrics.add("frames_skipped", skipped)
            t = self.ring.newest_t
            if t is not None:
                self._stepped_t = t
                self.step.step(t, pending, final)

    def _observe_lag(self, pending: Pending) -> None:
        """Live: how long this step's oldest data waited, to the shedder; its level to the steps."""
        lag_s = time.monotonic() - pending.first_arrival if pending.first_arrival else 0.0
        self.metrics.observe_step_lag(lag_s * 1e3)
        if self.shedder.observe(lag_s):
            self.windows.shed_level = self.metrics.shed_level = self.shedder.level
            self.metrics.add("shed_changes")

    def _step_at(self, t_us: int) -> None:
        """A step at ``t_us`` with what arrived since the last (step lock held)."""
        with self._cond:
            pending = self._pending.take()
        self.step.step(t_us, pending)
