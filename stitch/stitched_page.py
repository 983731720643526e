"""What the stitcher gives back: the stitched page, and ink rendered as black on white paper."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from darkread.core.image_codec import encode_png


def ink_mask_to_paper(mask: np.ndarray) -> np.ndarray:
    """Ink mask (nonzero = ink) -> uint8 black (0) on white (255), as OCR engines and people read it."""
    return np.where(np.asarray(mask) != 0, 0, 255).astype(np.uint8)


def ink_probability_to_paper(probability: np.ndarray, saturation: float = 0.8) -> np.ndarray:
    """Ink probability in [0, 1] -> uint8 black (ink) on white (paper), saturating at ``saturation``."""
    shade = np.clip(np.asarray(probability, np.float32) / saturation, 0.0, 1.0)
    return np.round(255.0 * (1.0 - shade)).astype(np.uint8)


@dataclass
class StitchedPage:
    """A stitched page. Coordinates are page pixels, (0, 0) at the top-left of the covered area."""

    image: np.ndarray  # uint8 ink mask of the whole page (1 = ink)
    lines: list[tuple[int, int, int, int]]  # line boxes (x0, y0, x1, y1), top to bottom
    line_images: list[np.ndarray]  # each line's ink mask (the page cut to its box; the line's own strip dominates it)
    frames_used: int = 0
    frames_dropped: int = 0
    frame_positions: dict[int, tuple[float, float]] = field(default_factory=dict)  # frame_id -> top-left on the page
    skew_deg: float = 0.0  # rotation applied to level the text lines (cv2.getRotationMatrix2D sense)
    # alpha-averaged ink probability behind ``image`` (float32, same shape); None when not stitched
    ink_probability: np.ndarray | None = None
    grey_saturation: float = 0.8
    views: np.ndarray | None = None  # how many frames (views) covered each pixel (same shape); None when not stitched

    def to_grey(self) -> np.ndarray:
        """Black-on-white uint8 page with shades where frames disagreed: what OCR should read.

        Falls back to the binary page when no probability is known.
        """
        if self.ink_probability is None:
            return ink_mask_to_paper(self.image)
        return ink_probability_to_paper(self.ink_probability, self.grey_saturation)

    def to_png_bytes(self) -> bytes:
        """Black ink on white, 8-bit grey PNG."""
        grey = ink_mask_to_paper(self.image)
        if grey.size == 0:
            grey = np.full((1, 1), 255, np.uint8)
        return encode_png(grey)
