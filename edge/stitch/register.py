"""Register a frame against what the page already shows, around the place the sensor predicts.

Template matching (normalised cross-correlation) of the blurred frame over a small search window
seeded by the gaze/sensor-predicted position. Only the part of the frame that overlaps known page
content takes part, so fresh text entering on the right does not pull the match.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

# Tie-breaker towards the predicted place: text repeats itself (letters, lines), and among near-equal
# peaks the one needing less head motion is the likelier.
_CENTRE_PRIOR = 0.03


@dataclass(frozen=True)
class Registration:
    shift_xy: tuple[int, int]  # correction to the predicted top-left
    score: float  # normalised correlation at the peak, in [-1, 1]
    overlap: float  # share of the frame that overlapped known content
    subpixel_xy: tuple[float, float] = (0.0, 0.0)  # parabolic refinement of the peak, within +-0.5 px


def _parabola_vertex(left: float, centre: float, right: float) -> float:
    """Offset of the vertex of the parabola through three equally spaced samples."""
    curvature = left - 2.0 * centre + right
    if curvature >= 0:  # not a maximum
        return 0.0
    return float(np.clip(0.5 * (left - right) / curvature, -0.5, 0.5))


def blur(image: np.ndarray, sigma: float) -> np.ndarray:
    image = image.astype(np.float32, copy=False)
    return cv2.GaussianBlur(image, (0, 0), sigma) if sigma > 0 else image


def _known_span(fraction: np.ndarray) -> tuple[int, int]:
    """First and one-past-last index where more than half is known."""
    idx = np.flatnonzero(fraction > 0.5)
    return (int(idx[0]), int(idx[-1]) + 1) if idx.size else (0, 0)


def register_frame(
    reference: np.ndarray,
    known: np.ndarray,
    template: np.ndarray,
    radius: int,
    blur_sigma: float = 1.2,
    min_overlap_fraction: float = 0.25,
) -> Registration | None:
    """Best shift of ``template`` inside ``reference`` (``radius`` px around the centre).

    ``reference``/``known`` cover the predicted box grown by ``radius`` on every side (shape
    h + 2r, w + 2r): the ink probability seen so far and where anything was seen. Returns None when
    too little of the frame overlaps known content to trust a correlation.
    """
    h, w = template.shape
    if reference.shape != (h + 2 * radius, w + 2 * radius) or known.shape != reference.shape:
        raise ValueError(f"reference {reference.shape} must be the template {template.shape} grown by {radius} px")
    at_prediction = known[radius : radius + h, radius : radius + w]
    x0, x1 = _known_span(at_prediction.mean(axis=0))
    y0, y1 = _known_span(at_prediction[:, x0:x1].mean(axis=1)) if x1 > x0 else (0, 0)
    overlap = (y1 - y0) * (x1 - x0) / float(h * w)
    if overlap < min_overlap_fraction:
        return None
    sub = blur(template, blur_sigma)[y0:y1, x0:x1]
    if float(sub.std()) < 1e-3:
        return None
    search = blur(reference, blur_sigma)[y0 : y1 + 2 * radius, x0 : x1 + 2 * radius]
    scores = np.nan_to_num(cv2.matchTemplate(search, sub, cv2.TM_CCOEFF_NORMED), nan=-1.0, posinf=-1.0, neginf=-1.0)
    if radius > 0:
        yy, xx = np.mgrid[-radius : radius + 1, -radius : radius + 1]
        scores = scores - _CENTRE_PRIOR * (xx**2 + yy**2) / float(radius**2)
    by, bx = np.unravel_index(int(np.argmax(scores)), scores.shape)
    dx, dy = int(bx) - radius, int(by) - radius
    peak = float(scores[by, bx]) + _CENTRE_PRIOR * (dx * dx + dy * dy) / float(max(1, radius) ** 2)
    sx = _parabola_vertex(*scores[by, bx - 1 : bx + 2]) if 0 < bx < scores.shape[1] - 1 else 0.0
    sy = _parabola_vertex(*scores[by - 1 : by + 2, bx]) if 0 < by < scores.shape[0] - 1 else 0.0
    return Registration((dx, dy), peak, overlap, (sx, sy))
