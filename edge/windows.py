"""The foveal window and its events, as the pipeline's steps see them.

:class:`Windows` holds what both steps (:mod:`darkread.edge.steps`) share: the ring the reader
fills, the gaze, where the window is now, the head's motion (measured from all events by
:mod:`darkread.edge.scene_motion`, or known from elsewhere: :mod:`darkread.edge.head_motion`) and
the sensor's ROI that follows the window while that motion is known (:mod:`darkread.edge.roi`);
it cuts one frame's events out of the ring and makes the frame (:mod:`darkread.edge.frame`).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable

import numpy as np

from darkread.edge.config import PipelineConfig
from darkread.edge.deblur import DeblurConfig
from darkread.edge.denoise import DenoiseConfig
from darkread.edge.events import Events
from darkread.edge.fovea import in_window
from darkread.edge.frame import FrameResult, Infer, clean_window, make_frame
from darkread.edge.gaze import GazeLookup, GazeSample
from darkread.edge.head_motion import KnownHeadMotion, SmearPrior
from darkread.edge.imu_motion import JoinedSceneMotion
from darkread.edge.ring import EventRing
from darkread.edge.roi import ROI_FOLLOW_MARGIN_PX, Rect, delivered_since, follow_window, motion_healthy, roi_wanted
from darkread.edge.scene_motion import SceneMotion
from darkread.edge.sources.base import EventSource
from darkread.edge.telemetry import EdgeMetrics
from darkread.edge.voxel import VoxelConfig

MIN_HISTORY_EVENTS = 4096
MAX_HISTORY_EVENTS = 1 << 16  # usual cap of the ring events searched for a window's events


def _never() -> bool:
    return False


def _unmeasured() -> float | None:
    return None


class Windows:
    """The ring, the gaze and the window's place; one frame's events and the frame itself.

    ``origin`` is where the window is now: the steps place it, the reader counts the new events
    inside it. The scene's motion is pushed by the reader thread and asked for by the processing
    step, hence its lock.
    """

    def __init__(
        self,
        ring: EventRing,
        source: EventSource,
        gaze: GazeLookup,
        infer: Infer,
        settings: PipelineConfig,
        voxel: VoxelConfig,
        metrics: EdgeMetrics,
        known_motion: KnownHeadMotion | None = None,
        light_probe: Callable[[], bool] | None = None,
        light_level: Callable[[], float | None] | None = None,
    ) -> None:
        self.ring = ring
        self.source = source  # (its ROI follows the window while ``roi_wanted``: ``place_roi``)
        self.gaze = gaze
        self.infer = infer
        self.settings = settings
        self.voxel = voxel
        self.fovea = voxel.fovea
        self.metrics = metrics
        self.sensor_wh = (int(source.width), int(source.height))
        self.deblur = DeblurConfig(enabled=settings.deblur)
        self.denoise = DenoiseConfig(enabled=settings.denoise)
        self.origin: tuple[int, int] | None = None
        self.frames_made = 0
        self._history = MIN_HISTORY_EVENTS
        # the head's motion from all events, unless it is known from elsewhere and healthy (then it
        # is neither measured nor searched); the tracker stands by for when it is not. A gyroscope's
        # (a SmearPrior) is searched around, and while the whole sensor is delivered the tracker runs
        # beside it as a check
        self.known_motion = known_motion
        self.light_probe = light_probe or _never  # the light is being read: the whole sensor (edge.bias_control)
        # the light at the page now, lux (None: not measured yet, or not at all); each frame and view says it
        self.light_level = light_level or _unmeasured
        self.imu = known_motion if isinstance(known_motion, SmearPrior) else None
        self._measure_scene = settings.scene_motion and settings.sensor_roi != "on"
        self.scene = SceneMotion(self.sensor_wh) if self._measure_scene else None
        self._scene_lock = threading.Lock()
        self._joined = JoinedSceneMotion()
        self.roi: Rect | None = None  # what the sensor delivers (None: all of it)
        self.shed_level = 0  # live and falling behind: what the steps give up (edge.load)
        self._roi_lock = threading.Lock()  # (placed by the steps, given back by the reader thread)
        self._roi_writes: deque[tuple[int | None, Rect | None]] = deque(maxlen=64)  # (in effect from, what), newest last

    def motion_known(self, t_us: int) -> bool:
        """The head's motion at ``t_us`` comes from the known motion (present and healthy)."""
        return motion_healthy(self.known_motion, t_us)

    def push_scene(self, events: Events) -> None:
        """Reader thread: every event goes to the scene's motion tracker while the head's motion is
        not known, or beside a gyroscope (its check) while the whole sensor is delivered; a known
        motion that stopped being healthy gets the whole sensor back first (the chunk delivered
        through the ROI is not measured, and the tracker starts afresh)."""
        t = int(events["t"][-1])
        self._roi_took_effect(events)
        if self.roi is not None and not roi_wanted(self.settings.sensor_roi, self.known_motion, t, self.light_probe()):
            self._write_roi(None, t)
            if self._measure_scene:  # its last slices are from before the pause: it starts afresh
                with self._scene_lock:
                    self.scene = SceneMotion(self.sensor_wh)
            return
        if self.scene is not None and self.roi is None and (self.imu is not None or not self.motion_known(t)):
            with self._scene_lock:
                self.scene.push(events)

    def scene_at(self, t_us: int) -> tuple[float, float] | None:
        """The scene's motion at ``t_us`` (None when not measured)."""
        if self.imu is not None:
            return self._imu_scene_at(t_us)
        if self.known_motion is not None and self.motion_known(t_us):
            return self.known_motion.scene_px(t_us)
        if self.scene is None:
            return None
        with self._scene_lock:
            return self.scene.at(t_us)

    def gyro_moved(self, t_from_us: int, t_to_us: int) -> tuple[float, float] | None:
        """How far the scene moved in the sensor from ``t_from_us`` to ``t_to_us`` by the gyroscope,
        where it is healthy at both (None without one, or where it is not: its ``scene_px`` says so)."""
        if self.imu is None or self.known_motion is None:
            return None
        a, b = self.known_motion.scene_px(t_from_us), self.known_motion.scene_px(t_to_us)
        if a is None or b is None:
            return None
        return b[0] - a[0], b[1] - a[1]

    def _imu_scene_at(self, t_us: int) -> tuple[float, float] | None:
        """The gyroscope's offset where healthy, else the tracker's, joined (``JoinedSceneMotion``); counted."""
        assert self.known_motion is not None and self.imu is not None
        imu = self.known_motion.scene_px(t_us) if self.imu.healthy(t_us) else None
        tracker = None
        if self.scene is not None:
            with self._scene_lock:
                tracker = self.scene.at(t_us)
        offset, disagreement = self._joined.at(imu, tracker)
        self.metrics.add("frames_imu_motion" if imu is not None else "frames_imu_fallback")
        if disagreement is not None:
            self.metrics.observe_motion_disagreement(disagreement)
        return offset

    def place_roi(self, wanted: Rect, t_us: int) -> None:
        """A step wants the sensor's events of ``wanted`` (x0, y0, width, height) from ``t_us`` on:
        while ``[pipeline] sensor_roi`` wants the ROI (``edge.roi.roi_wanted``) the sensor delivers
        it with a margin, rewritten only once ``wanted`` leaves the window delivered (hysteresis);
        otherwise the whole sensor."""
        if not roi_wanted(self.settings.sensor_roi, self.known_motion, t_us, self.light_probe()):
            if self.roi is not None:
                self._write_roi(None, t_us)
            return
        target = follow_window(wanted, self.roi, ROI_FOLLOW_MARGIN_PX, self.sensor_wh)
        if target is not None:
            self._write_roi(target, t_us)

    def _write_roi(self, roi: Rect | None, t_us: int) -> None:
        """Program the source's ROI (None: the whole sensor) from ``t_us`` on and count the write (``roi_writes``)."""
        with self._roi_lock:
            if roi == self.roi:
                return
            x0, y0, w, h = roi if roi is not None else (0, 0, *self.sensor_wh)
            self.source.set_roi(x0, y0, w, h)
            self.roi = roi
            self._roi_writes.append((None, roi))  # (in effect from its first delivered event: _roi_took_effect)
        self.metrics.add("roi_writes")

    def delivered_since(self, rect: Rect) -> int | None:
        """Since when the sensor has delivered every event of ``rect`` (``edge.roi.delivered_since``
        over the ROI writes held). A frame takes no older events there: where an earlier ROI left
        part of its window dark, it would see half a page."""
        with self._roi_lock:
            self._poll_roi_effect()
            return delivered_since(list(self._roi_writes), rect)

    def _roi_took_effect(self, events: Events) -> None:
        """Reader thread, each chunk: the newest ROI write's first delivered event, as the source
        tells it (a replay's decoder: ``roi_since_us``) or else this chunk's first (the first read
        after the write)."""
        with self._roi_lock:
            if self._roi_writes and self._roi_writes[-1][0] is None and not hasattr(self.source, "roi_since_us"):
                self._roi_writes[-1] = (int(events["t"][0]), self._roi_writes[-1][1])
            self._poll_roi_effect()

    def _poll_roi_effect(self) -> None:
        """(Under the ROI lock.) The newest write in effect once the source says from when."""
        if self._roi_writes and self._roi_writes[-1][0] is None:
            since = getattr(self.source, "roi_since_us", None)
            if since is not None:
                self._roi_writes[-1] = (int(since), self._roi_writes[-1][1])

    def frame(self, window: Events, origin: tuple[int, int], gaze: GazeSample, t_us: int,
              probability: bool = False) -> FrameResult | None:
        """The frame of ``window`` (``make_frame``), counted; None when it holds no events."""
        frame = make_frame(window, origin, gaze, t_us, self.voxel, self.infer, self.frames_made, self.scene_at(t_us),
                           probability=probability, light_lux=self.light_level())
        if frame is None:
            return None
        self.frames_made += 1
        self.metrics.add("frames")
        self.metrics.observe_inference(frame.inference_ms)
        return frame

    def recent_events(self, origin: tuple[int, int], t_until: int, t_from: int | None = None, at_least: int = 0) -> Events:
        """Exactly the window's events for one frame: the newest ``n_events`` inside the window at
        ``origin`` with ``t <= t_until`` (and ``t >= t_from``), searching back through the ring as needed,
        moved back along the head's motion during their span (``edge.deblur``; measured from them and
        the sensor's other events of that span around the window), and in dim light without those
        that have no neighbour: shot noise (``edge.denoise``; a frame may then have fewer events).

        Fewer than ``at_least`` inside are returned as they are: a caller that drops such a window
        would throw the cleaning away (it never adds events: the window stays too small).

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
        if used.shape[0] < at_least:
            return recent[used]
        nearby = recent[int(used[0]) :] if used.shape[0] else recent[:0]
        known = self.known_motion if self.motion_known(t_until) else None
        window, deblurred, denoised = clean_window(recent[used], nearby, origin, (cfg.height, cfg.width), self.sensor_wh,
                                                   self.deblur, self.denoise, known)
        if deblurred:
            self.metrics.add("frames_deblurred")
        if denoised:
            self.metrics.add("frames_denoised")
        return window
