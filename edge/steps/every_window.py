"""``every-window`` (for research and evaluation): a frame every ``n_events`` new foveated events.

A step takes the newest event time ``t`` as the frame's one timestamp, looks up the gaze at ``t``,
places the window there, collects exactly the window's newest ``n_events`` (up to ``t``) and makes
the frame (voxel -> infer), sent as it is. A step that comes late (live, inference fell behind)
jumps to the newest window and counts the windows it skipped.
"""

from __future__ import annotations

from darkread.edge.config import PipelineConfig
from darkread.edge.fovea import window_origin
from darkread.edge.steps import FrameHandler, Pending
from darkread.edge.windows import Windows


class EveryWindowStep:
    """A frame per window of ``n_events`` new events inside it (or per ``period_ms`` with fewer)."""

    replay_grid_us: int | None = None  # lossless: a step after each chunk that completes a window (or ends a period)

    def __init__(self, windows: Windows, settings: PipelineConfig, on_frame: FrameHandler) -> None:
        self.windows = windows
        self.settings = settings
        self.on_frame = on_frame

    def due(self, pending: Pending) -> bool:
        return pending.foveated >= self.settings.n_events

    def skipped(self, pending: Pending) -> int:
        k = self.settings.n_events
        return pending.foveated // k - 1 if pending.foveated > k and self.windows.origin is not None else 0

    def step(self, t_us: int, pending: Pending, final: bool = False) -> None:
        """The frame at ``t_us`` of the window at the gaze then, if new events arrived (or the window moved)."""
        w = self.windows
        if not (pending.foveated > 0 or (w.origin is None and pending.events > 0)):
            return
        gaze = w.gaze.at(t_us)
        if gaze is None:
            w.metrics.add("frames_no_gaze")  # events arrived, but nowhere to look
            w.origin = None
            return
        origin = window_origin(gaze.pixel, w.sensor_wh, w.fovea)
        moved = origin != w.origin
        w.origin = origin
        if moved:
            w.place_roi((origin[0], origin[1], w.fovea.width, w.fovea.height), t_us)
        if pending.foveated == 0 and not moved:
            return
        frame = w.frame(w.recent_events(origin, t_us), origin, gaze, t_us)
        if frame is not None:
            self.on_frame(frame, pending.arrival)
