"""What the stitcher takes in: one reconstructed binary window and where it was taken."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StitchFrame:
    """One reconstructed binary window and where it was taken.

    ``origin_xy`` and ``gaze_px`` are sensor pixels; the page moves in the sensor with the head, so
    they predict the frame's place on the page only roughly (the stitcher refines by correlation).
    """

    frame_id: int
    t_us: int  # event clock
    mask: np.ndarray  # uint8 [h, w] ink mask (1 = ink, 0 = paper); default 100x200
    origin_xy: tuple[int, int]  # window top-left in sensor pixels
    gaze_px: tuple[float, float]  # gaze pixel (u, v) in sensor pixels at t_us

    def __post_init__(self) -> None:
        mask = np.asarray(self.mask)
        if mask.ndim != 2 or mask.shape[0] < 8 or mask.shape[1] < 8:
            raise ValueError(f"frame {self.frame_id}: mask must be a 2-D image of at least 8x8, got shape {mask.shape}")
        if mask.dtype != np.bool_ and not np.issubdtype(mask.dtype, np.integer):
            raise ValueError(f"frame {self.frame_id}: mask must be uint8 (1 = ink), got {mask.dtype}")
        if mask.dtype != np.uint8 or mask.max(initial=0) > 1:
            mask = (mask > 0).astype(np.uint8)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "origin_xy", (int(self.origin_xy[0]), int(self.origin_xy[1])))
        object.__setattr__(self, "gaze_px", (float(self.gaze_px[0]), float(self.gaze_px[1])))
