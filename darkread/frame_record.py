"""The one record of a reconstructed frame, shared by every step after the U-Net.

The edge makes it (``edge.pipeline.FrameResult`` adds how it was made), the wire carries it
(``proto.messages.Frame.of`` / ``Frame.record``), the cloud stores it (``cloud.store.StoredFrame``
adds the sequence number) and the stitcher reads it (``darkread.stitch``). Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FrameRecord:
    """One reconstructed binary window and where it was taken.

    ``origin`` and ``gaze_px`` are sensor pixels; the page moves in the sensor with the head, so
    they predict the frame's place on the page only roughly (the stitcher refines by correlation).
    """

    frame_id: int
    t_us: int  # event clock, microseconds: the newest event when the frame was made (no event in it is newer)
    mask: np.ndarray  # uint8 [h, w] ink mask (1 = ink, 0 = paper); 100x200 with the shipped model
    origin: tuple[int, int]  # window top-left (x0, y0) in sensor pixels
    gaze_px: tuple[float, float]  # gaze pixel (u, v) in sensor pixels at t_us

    def __post_init__(self) -> None:
        object.__setattr__(self, "mask", ink_mask(self.mask, f"frame {self.frame_id}"))
        object.__setattr__(self, "origin", (int(self.origin[0]), int(self.origin[1])))
        object.__setattr__(self, "gaze_px", (float(self.gaze_px[0]), float(self.gaze_px[1])))


def ink_mask(mask: np.ndarray, what: str = "mask") -> np.ndarray:
    """A non-empty 2-D integer or boolean mask as uint8 with ink = 1 (any positive value is ink)."""
    array = np.asarray(mask)
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{what}: mask must be a non-empty 2-D image, got shape {array.shape}")
    if array.dtype != np.bool_ and not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"{what}: mask must be uint8 (1 = ink), got {array.dtype}")
    if array.dtype != np.uint8 or array.max(initial=0) > 1:
        array = (array > 0).astype(np.uint8)
    return array
