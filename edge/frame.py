"""One foveal window's events -> one frame: the pure core of the edge's loop.

:func:`clean_window` readies a window's events as the network is given them (the edge and the
training windows both cut windows so), :func:`make_frame` bins them into the voxel grid and infers.
Which windows are made, and when, is :mod:`darkread.edge.steps`' business; where their events come
from, :mod:`darkread.edge.windows`'.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.edge.deblur import DeblurConfig, deblur_window
from darkread.edge.denoise import DenoiseConfig, drop_isolated
from darkread.edge.events import Events
from darkread.edge.fovea import FoveaConfig, in_window
from darkread.edge.gaze import GazeSample
from darkread.edge.head_motion import KnownHeadMotion, SmearPrior
from darkread.edge.voxel import VoxelConfig, voxel_grid

if TYPE_CHECKING:
    from darkread.proto.messages import Frame

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


def count_in_window(events: Events, origin: tuple[int, int] | None, cfg: FoveaConfig) -> int:
    """How many ``events`` fall inside the window at ``origin`` (0 without a window)."""
    if origin is None or events.shape[0] == 0:
        return 0
    return int(np.count_nonzero(in_window(events, origin[0], origin[1], cfg.width, cfg.height)))




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
    around the window; or by ``known_motion`` when given: ``edge.head_motion``; a gyroscope's
    motion, a ``SmearPrior``, is searched around instead), then in dim light
    without those that have no neighbour (``edge.denoise``); and whether each step changed them.
    The edge and the training windows (``train.windows``) both cut windows this way."""
    if known_motion is not None and not isinstance(known_motion, SmearPrior):
        cleaned, moved = known_motion.warp(window, origin, shape_hw), window.shape[0] > 0
    else:  # (a gyroscope's prediction is searched around: edge.deblur)
        prior = known_motion if isinstance(known_motion, SmearPrior) else None
        cleaned, smear = deblur_window(window, nearby, origin, shape_hw, sensor_wh, deblur, prior)
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
    light_lux: float | None = None,
) -> FrameResult | None:
    """Bin the window's events and infer. None when the window holds no events.

    ``window`` are exactly the events to bin (``fovea.window_events``), all inside the window at
    ``origin``; ``t_us`` is the frame's timestamp, the time ``gaze`` was looked up; ``scene_px``
    the scene's motion by then (``edge.scene_motion``), if measured. ``probability``: keep the ink
    probability too, from an ``infer`` that has ``ink_probability`` (a ``Reconstructor``).
    ``light_lux``: the light the glasses measure at the page now, if they do.
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
        light_lux=light_lux,
    )

