"""The one record of a reconstructed frame, shared by every step after the U-Net.

The edge makes it (``edge.frame.FrameResult`` adds how it was made), the wire carries it
(``proto.messages.Frame.of`` / ``Frame.record``), the cloud stores it (``cloud.store.StoredFrame``
adds the sequence number) and the stitcher reads it (``darkread.stitch``). Pure: numpy only.

A fused view of one fixation (``edge.view_fusion``) is the same record with its ink probability in
grey ``levels`` and the number of ``frames`` it stands for: the stitcher averages it in as that
many frames of that probability, which is what stitching the frames one by one would have done.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

MAX_VIEW_GROWTH = 2
"""A fused view is the union of its frames' windows: at most this many windows per side (the
glasses cut it so, protocol version 4 refuses larger ones)."""
MAX_SHED_LEVEL = 3  # the deepest of the live edge's shedding levels (``edge.load.LEVELS``)


@dataclass(frozen=True)
class FrameRecord:
    """One reconstructed window (a binary frame or a fused view) and where it was taken.

    ``origin`` and ``gaze_px`` are sensor pixels; the page moves in the sensor with the head, so
    they predict the frame's place on the page only roughly (the stitcher refines by correlation).
    """

    frame_id: int
    t_us: int  # event clock, microseconds: the newest event when the frame was made (no event in it is newer)
    mask: np.ndarray  # uint8 [h, w] ink mask (1 = ink, 0 = paper); 100x200 with the shipped model
    origin: tuple[int, int]  # window top-left (x0, y0) in sensor pixels
    gaze_px: tuple[float, float]  # gaze pixel (u, v) in sensor pixels at t_us
    # a fused view: ink probability as level indices 0 .. n_levels - 1 (level / (n_levels - 1));
    # None for a binary frame, whose probability is its mask
    levels: np.ndarray | None = field(default=None, kw_only=True, repr=False)
    n_levels: int = field(default=2, kw_only=True)
    frames: int = field(default=1, kw_only=True)  # frames fused into this record (its weight when stitched)
    # how far the whole scene had moved in the sensor by ``t_us`` (sensor px, since the stream began;
    # ``edge.scene_motion``): the head's motion, from which the stitcher predicts the frame's place
    scene_px: tuple[float, float] | None = field(default=None, kw_only=True)
    # how much a live edge that could not keep up was giving up while it made this record
    # (``edge.load``: 0 none .. 3 one frame per view and fixations left without one): the cloud
    # trusts a starved page's lines less
    shed_level: int = field(default=0, kw_only=True)
    # the light at the page when the record was made, lux, as the glasses measured it (their
    # background-event estimate, ``edge.bias_control``, or a configured light level); None: not known.
    # Dim light makes reading fail and is the one cause more light fixes: the cloud weighs the
    # page's lines and chooses its advice by it
    light_lux: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mask", ink_mask(self.mask, f"frame {self.frame_id}"))
        object.__setattr__(self, "origin", (int(self.origin[0]), int(self.origin[1])))
        object.__setattr__(self, "gaze_px", (float(self.gaze_px[0]), float(self.gaze_px[1])))
        if int(self.frames) < 1:
            raise ValueError(f"frame {self.frame_id}: frames must be >= 1, got {self.frames}")
        object.__setattr__(self, "frames", int(self.frames))
        if not 0 <= int(self.shed_level) <= MAX_SHED_LEVEL:
            raise ValueError(f"frame {self.frame_id}: shed_level must be 0..{MAX_SHED_LEVEL}, got {self.shed_level}")
        object.__setattr__(self, "shed_level", int(self.shed_level))
        if self.light_lux is not None:
            lux = float(self.light_lux)
            if not math.isfinite(lux) or lux <= 0:
                raise ValueError(f"frame {self.frame_id}: light_lux must be a positive number of lux, got {self.light_lux}")
            object.__setattr__(self, "light_lux", lux)
        if self.scene_px is not None:
            object.__setattr__(self, "scene_px", (float(self.scene_px[0]), float(self.scene_px[1])))
        if self.levels is not None:
            object.__setattr__(self, "levels", ink_levels(self.levels, self.n_levels, self.mask.shape, f"frame {self.frame_id}"))

    def ink_probability(self) -> np.ndarray:
        """float32 [h, w] ink probability in [0, 1]: the levels of a view, the mask of a frame."""
        if self.levels is None:
            return self.mask.astype(np.float32)
        return self.levels.astype(np.float32) * np.float32(1.0 / (self.n_levels - 1))


def ink_mask(mask: np.ndarray, what: str = "mask") -> np.ndarray:
    """A non-empty 2-D integer or boolean mask as uint8 with ink = 1 (any positive value is ink)."""
    array = np.asarray(mask)
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{what}: mask must be a non-empty 2-D image, got shape {array.shape}")
    if array.dtype != np.uint8 and array.dtype != np.bool_ and not np.issubdtype(array.dtype, np.integer):  # (uint8 first: np.issubdtype is slow)
        raise ValueError(f"{what}: mask must be uint8 (1 = ink), got {array.dtype}")
    if array.dtype != np.uint8 or array.max(initial=0) > 1:
        array = (array > 0).astype(np.uint8)
    return array


def ink_levels(levels: np.ndarray, n_levels: int, shape: tuple[int, int], what: str = "levels") -> np.ndarray:
    """Level indices checked against ``n_levels`` and the mask's ``shape``, as uint8."""
    array = np.asarray(levels)
    if not 2 <= int(n_levels) <= 256:
        raise ValueError(f"{what}: n_levels must be 2..256, got {n_levels}")
    if array.shape != tuple(shape):
        raise ValueError(f"{what}: levels of shape {array.shape} for a mask of shape {tuple(shape)}")
    if not np.issubdtype(array.dtype, np.integer) or int(array.min(initial=0)) < 0 or int(array.max(initial=0)) >= n_levels:
        raise ValueError(f"{what}: levels must be integers 0 .. {int(n_levels) - 1}")
    return array.astype(np.uint8, copy=False)


def threshold_levels(levels: np.ndarray, n_levels: int) -> np.ndarray:
    """Level indices -> binary ink where the probability is at least one half (what a binary stitcher takes)."""
    return (2 * np.asarray(levels).astype(np.int32) >= n_levels - 1).astype(np.uint8)
