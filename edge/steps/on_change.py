"""``on-change`` (``[pipeline] infer``, the product default): the gaze decides when to infer.

Every step feeds the gaze-event classifier (:mod:`darkread.edge.view_trigger`) up to its event
time; no inference during saccades and blinks; during a fixation one when enough new events
arrived, at most every ``min_interval_ms`` until a frame agrees with the view (then none until it
is sent), all in one window placed at the fixation's mean gaze; the fixation's frames are fused
into one view (:mod:`darkread.edge.view_fusion`) that goes to ``on_frame`` when the fixation ends
and every ``view_every_ms`` during a long one.
"""

from __future__ import annotations

import numpy as np

from darkread.edge.config import PipelineConfig
from darkread.edge.fovea import window_origin
from darkread.edge.gaze import GazeSample
from darkread.edge.load import frames_per_view, skip_covered
from darkread.edge.steps import FrameHandler, Pending
from darkread.edge.view_fusion import MARGIN_PX, ViewFuser
from darkread.edge.view_trigger import GazeGate, ViewTrigger, fixation_key
from darkread.edge.windows import Windows

LOSSLESS_STEP_US = 5_000
"""Lossless replays take one step per this much event time (a grid on the event clock, finer than
any gaze row at 11-100 ms), however large the chunks the source hands over: the same steps, and so
the same views, whatever the replay's chunking."""

CATCH_UP_US = 2 * LOSSLESS_STEP_US
"""A live step that comes this much event time or more after the last one (the edge fell behind,
edge.load) first steps through the gaze rows in between: a fixation that began and ended while the
step waited still ends its view (or is counted as shed), instead of passing unseen."""



class OnChangeStep:
    """One view per fixation, fused from the frames that changed it."""

    replay_grid_us: int | None = LOSSLESS_STEP_US

    def __init__(self, windows: Windows, settings: PipelineConfig, on_frame: FrameHandler) -> None:
        self.windows = windows
        self.settings = settings
        self.on_frame = on_frame
        self.gate = GazeGate(windows.gaze)
        self.trigger = ViewTrigger(settings)
        # the canvas reaches as far as the head drifts, beyond both dithered windows
        self.fuser = ViewFuser(margin_px=MARGIN_PX + 2 * settings.dither_px)
        self.views_made = 0
        self._fixation: int | None = None  # the current fixation's key (its first row, event clock)
        self._fixation_events = 0  # window events since it started
        self._since_infer = 0  # window events since the last inference
        self._retry_at = 0  # after a window too thin to infer: _fixation_events it may be tried again at
        self._view_origin: tuple[int, int] | None = None  # the current view's window (placed once per view)
        self._capped = False  # the current view was denied a frame (edge.load)
        self._last_view: tuple[int, int, int, int] | None = None  # the window of the last view sent
        self._shed_fixation = False  # the current fixation gets no view (edge.load: the last one covers it)
        self._view_shed = 0  # the deepest shedding level the current view (or a fixation skipped before it) was made at
        self._stepped_us: int | None = None  # the event time of the last step

    def due(self, pending: Pending) -> bool:
        return pending.events > 0  # every chunk: the gaze may have changed

    def skipped(self, pending: Pending) -> int:
        return 0  # a step looks at all that arrived: nothing is skipped

    def step(self, t_us: int, pending: Pending, final: bool = False) -> None:
        """Feed the gaze classifier up to ``t_us``; end, extend or start the fixation's view. A live
        step late by ``CATCH_UP_US`` or more first takes each gaze row in between as a step of its own
        (with no new events: what arrived counts at ``t_us``)."""
        last, self._stepped_us = self._stepped_us, t_us
        if last is not None and not self.settings.lossless and t_us - last >= CATCH_UP_US:
            rows, _, _ = self.windows.gaze.rows(last, t_us - 1)
            for row_t in rows.tolist():
                self._step_at(int(row_t), Pending(arrival=pending.arrival))
        self._step_at(t_us, pending, final)

    def _step_at(self, t_us: int, pending: Pending, final: bool = False) -> None:
        t, arrival = t_us, pending.arrival
        status = self.gate.update(t)
        key = None if final else fixation_key(status)
        # a later key is a new fixation; an earlier one is the classifier merging two halves of this one
        if self._fixation is not None and (key is None or key > self._fixation):
            self._end_view(arrival, t if final else min(t, status.since_us))
            self._fixation = None
        if key is None:
            return  # saccade, blink, no gaze: nothing to infer
        if self._fixation is None:
            self._fixation, self._fixation_events, self._since_infer, self._retry_at = key, 0, 0, 0
            self._shed_fixation = False
            self.trigger.reset()
            self._roi_at_landing(t)
        self._fixation_events += pending.foveated
        self._since_infer += pending.foveated
        if len(self.fuser) and t - self.fuser.t0_us >= self.settings.view_every_ms * 1e3:
            self._send_view(arrival)  # a long fixation: its view so far, the next one starts afresh
        if not self.trigger.ready(t, self._fixation) or self._fixation_events < self._retry_at:
            return  # the bounded rate (and the landing's wait, a thin window's retry), checked before anything costs
        window = self._view_window(t)
        if window is None:
            return
        origin, gaze = window
        if self.trigger.due(t, self._fixation, self._since_infer, self._fixation_events, origin):
            if self._over_budget():
                return  # shed: the view keeps the frames it has (edge.load)
            self._infer_into_view(origin, gaze, t, self._fixation, arrival)

    def _over_budget(self) -> bool:
        """A live edge falling behind caps a view's frames (edge.load); the first capped inference
        of a view counts it in ``views_capped``."""
        budget = frames_per_view(self.windows.shed_level)
        if budget is None or len(self.fuser) < budget:
            return False
        if not self._capped:
            self._capped = True
            self.windows.metrics.add("views_capped")
        return True

    def _view_window(self, t: int) -> tuple[tuple[int, int], GazeSample] | None:
        """Where the current view's window is, and the gaze at ``t``. A view's window stays put: it
        is placed once, at the mean gaze of the fixation's rows so far (one row's tracker noise
        would put it tens of pixels off), so its frames all see the same stretch of text."""
        w = self.windows
        gaze = w.gaze.at(t)
        if gaze is None or self._shed_fixation:
            return None
        if len(self.fuser) and self._view_origin is not None:
            return self._view_origin, gaze
        centre = self._fixation_centre(t) or gaze.pixel
        origin = window_origin(centre, w.sensor_wh, w.fovea)
        if skip_covered(w.shed_level, (*origin, w.fovea.width, w.fovea.height), self._last_view):
            self._shed_fixation = True  # shed (edge.load): the last view already holds most of this window
            self._view_shed = max(self._view_shed, w.shed_level)
            w.metrics.add("views_shed")
            return None
        if origin != w.origin:
            self._roi_for_view(origin, t)
        w.origin = self._view_origin = origin
        return origin, gaze

    def _fixation_centre(self, t: int) -> tuple[float, float] | None:
        """Mean gaze pixel over the current fixation's valid tracker rows up to ``t`` (None without any)."""
        if self._fixation is None:
            return None
        gaze = self.windows.gaze
        times, yaw, _ = gaze.rows(self._fixation - 1, t)
        pixels = [g.pixel for g in map(gaze.at, times[np.isfinite(yaw)].tolist()) if g is not None]
        if not pixels:
            return None
        u, v = np.mean(np.asarray(pixels, np.float64), axis=0)
        return float(u), float(v)

    def _infer_into_view(self, origin: tuple[int, int], gaze: GazeSample, t: int, t_from: int, arrival: float) -> bool:
        """One frame of the current fixation (its events only, up to ``n_events``), fused into the
        view; a frame that does not register onto the view sends it and starts the next one."""
        self._view_shed = max(self._view_shed, self.windows.shed_level)
        placed = self._dithered(origin, len(self.fuser))
        fov = self.windows.fovea
        delivered = self.windows.delivered_since((placed[0], placed[1], fov.width, fov.height))
        enough = min(self.settings.min_events, self.settings.n_events)
        window = self.windows.recent_events(placed, t, t_from=t_from if delivered is None else max(t_from, delivered),
                                            at_least=enough)
        if window.shape[0] < enough:
            # too thin once cleaned (noise in the dark, a blank stretch): a few milliseconds more of the
            # same events clean down the same way, and each try costs a deblur and a denoise; try again
            # once as many are new as a frame needs to be renewed
            self._retry_at = self._fixation_events + max(1, round(self.settings.renew_fraction * self.settings.n_events))
            return False
        frame = self.windows.frame(window, placed, gaze, t, probability=self.settings.fuse == "probability")
        if frame is None:
            return False
        last = self.fuser.last_t_us
        moved = self.windows.gyro_moved(last, t) if last is not None else None
        if self.fuser.add(frame, frame.events_used, frame.gaze_rad, frame.probability, moved) is None:
            self.windows.metrics.add("views_split")
            self._send_view(arrival)
            self.fuser.add(frame, frame.events_used, frame.gaze_rad, frame.probability)
        elif self.fuser.last_agreed:
            self.windows.metrics.add("frames_gyro_placed")
        self.trigger.inferred(t, origin, self.fuser.last_score, self.fuser.last_doubt)
        self._since_infer = 0
        return True

    def _roi_for_view(self, origin: tuple[int, int], t: int) -> None:
        """The sensor's ROI over the view's window and both dithered ones (all its frames' events)."""
        fov = self.windows.fovea
        top, bottom = self._dithered(origin, 0), self._dithered(origin, 1)
        y0, y1 = min(origin[1], top[1]), max(origin[1], bottom[1]) + fov.height
        self.windows.place_roi((origin[0], y0, fov.width, y1 - y0), t)

    def _roi_at_landing(self, t: int) -> None:
        """A fixation began: the ROI moves to where the gaze landed now, so the events the view's
        first frame takes (from the fixation's start) are delivered; the view's window, placed later
        at the fixation's mean gaze, usually lies inside its margin."""
        gaze = self.windows.gaze.at(t)
        if gaze is not None:
            self._roi_for_view(window_origin(gaze.pixel, self.windows.sensor_wh, self.windows.fovea), t)

    def _dithered(self, origin: tuple[int, int], k: int) -> tuple[int, int]:
        """The window of a view's ``k``-th frame: the view's window moved up (even ``k``) or down
        (odd) by ``dither_px``, inside the sensor. The tracker's bias (about 1 deg) puts the line
        being read anywhere in the window, often at its edge; two frames a few tens of pixels apart
        see it whole, and the view is the union of its frames' windows."""
        d = self.settings.dither_px
        if d <= 0:
            return origin
        fov = self.windows.fovea
        dy = -d if k % 2 == 0 else d
        centre = (origin[0] + fov.width // 2, origin[1] + fov.height // 2 + dy)
        return window_origin(centre, self.windows.sensor_wh, fov)

    def _end_view(self, arrival: float, t_end: int) -> None:
        """The fixation ended at ``t_end``: a fixation too short for a frame gets one now; send its view."""
        fixation = self._fixation
        lasted = fixation is not None and t_end - fixation >= self.gate.cfg.min_fixation_ms * 1e3
        if fixation is not None and lasted and not len(self.fuser) and self.windows.origin is not None:
            window = self._view_window(t_end)  # (not a landing the classifier revised)
            if window is not None:
                self._infer_into_view(window[0], window[1], t_end, fixation, arrival)
        if len(self.fuser):
            self._send_view(arrival)

    def _send_view(self, arrival: float) -> None:
        # the view says how starved the edge was (the cloud trusts a starved page's lines less)
        view = self.fuser.view(self.views_made, shed_level=max(self._view_shed, self.windows.shed_level),
                               light_lux=self.windows.light_level())
        self._view_shed = 0
        self.fuser = self.fuser.fresh()
        if self._view_origin is not None:
            fov = self.windows.fovea
            self._last_view = (*self._view_origin, fov.width, fov.height)
        self._view_origin = None
        self._capped = False
        self.views_made += 1
        self.windows.metrics.add("views")
        self.on_frame(view, arrival)
