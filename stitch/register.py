"""Register a frame against what the page already shows, around the place the sensor predicts.

Template matching (normalised cross-correlation) of the blurred frame over a small search window
seeded by the gaze/sensor-predicted position. Only the part of the frame that overlaps known page
content takes part, so fresh text entering on the right does not pull the match.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np

# Tie-breaker towards the predicted place: text repeats itself (letters, lines), and among near-equal
# peaks the one needing less head motion is the likelier.
_CENTRE_PRIOR = 0.03
# a page stretch whose ink varies less than this fraction of the frame's (std) is no place for it:
# anywhere on the page (the anchor search)...
_MIN_SPREAD_RATIO = 0.5
# ... and near the prediction, where only a blank stretch is refused: in dim light the page's ink is
# faint where its frames disagreed, so right places vary less than the frame, though far more than
# paper under a trace of ink, which correlates perfectly with anything (stitch/README.md)
_MIN_SPREAD_RATIO_NEAR = 0.1


@dataclass(frozen=True)
class Registration:
    shift_xy: tuple[int, int]  # correction to the predicted top-left
    score: float  # normalised correlation at the peak, in [-1, 1]
    overlap: float  # share of the frame that overlapped known content
    subpixel_xy: tuple[float, float] = (0.0, 0.0)  # parabolic refinement of the peak, within +-0.5 px
    angle_deg: float = 0.0  # rotation of the frame (about its centre) that matches best
    # the peak lies on (or a pixel from) the edge of the search window: the true match may lie beyond
    on_rim: bool = False
    # how much the peak beats the best match at least ``separation_px`` rows above or below it:
    # text lines look alike, so a small margin means the vertical offset is ambiguous
    vertical_margin: float = 2.0
    # share of the frame that lies on known content where the peak puts it (``overlap`` is at the
    # prediction): a peak far from the prediction can sit on a sliver of the page, where a few
    # strokes correlate perfectly with anything
    overlap_at_peak: float = 1.0


def parabola_vertex(left: float, centre: float, right: float) -> float:
    """Offset of the vertex of the parabola through three equally spaced samples."""
    curvature = left - 2.0 * centre + right
    if curvature >= 0:  # not a maximum
        return 0.0
    # (min/max of scalars: np.clip on a scalar costs microseconds, and the scene tracker asks twice a slice)
    return float(min(max(0.5 * (left - right) / curvature, -0.5), 0.5))


def blur(image: np.ndarray, sigma: float) -> np.ndarray:
    image = image.astype(np.float32, copy=False)
    return cv2.GaussianBlur(image, (0, 0), sigma) if sigma > 0 else image


def _known_span(fraction: np.ndarray) -> tuple[int, int]:
    """First and one-past-last index where more than half is known."""
    idx = np.flatnonzero(fraction > 0.5)
    return (int(idx[0]), int(idx[-1]) + 1) if idx.size else (0, 0)


def _interior(scores: np.ndarray, y: int, x: int, axis: int) -> bool:
    """Both neighbours of (y, x) along ``axis`` exist."""
    return 0 < x < scores.shape[1] - 1 if axis == 0 else 0 < y < scores.shape[0] - 1


def frame_transform(shape: tuple[int, int], angle_deg: float, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """2x3 affine map of a frame: rotation by ``angle_deg`` about its centre, then a shift."""
    h, w = shape
    move = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), float(angle_deg), 1.0)
    move[0, 2] += dx
    move[1, 2] += dy
    return move


@lru_cache(maxsize=64)
def _prior(shape: tuple[int, int], radius: int) -> np.ndarray:
    """Score penalty growing with the distance from the predicted place (zero for radius 0);
    the same few shapes come back every frame, so they are kept (read-only)."""
    if radius <= 0:
        prior = np.zeros(shape, np.float32)
    else:
        yy, xx = np.mgrid[-radius : radius + 1, -radius : radius + 1]
        prior = (_CENTRE_PRIOR * (xx**2 + yy**2) / float(radius**2)).astype(np.float32)
    prior.flags.writeable = False
    return prior


def _finite(scores: np.ndarray) -> np.ndarray:
    """NaN and infinities (flat windows) as the worst score, in place."""
    return np.nan_to_num(scores, copy=False, nan=-1.0, posinf=-1.0, neginf=-1.0)


def _window_mean(image: np.ndarray, shape: tuple[int, int], out: tuple[int, int]) -> np.ndarray:
    """Mean of ``image`` over the ``shape``-sized window (h, w) at every offset (top-left anchored),
    for the ``out`` offsets (rows, cols) a template of that shape has in it."""
    h, w = shape
    mean = cv2.boxFilter(image, -1, (w, h), anchor=(0, 0), normalize=True, borderType=cv2.BORDER_CONSTANT)
    return mean[: out[0], : out[1]]


def _varied_enough(search: np.ndarray, template: np.ndarray, out: tuple[int, int], ratio: float) -> np.ndarray:
    """Where the stretch of ``search`` under ``template`` holds at least ``ratio`` of the template's
    ink variation (std): a nearly blank stretch of page correlates with anything (a few strokes of
    the frame against paper score ~1), so only these offsets may be its place."""
    spread = _window_mean(search * search, template.shape, out) - _window_mean(search, template.shape, out) ** 2
    return spread >= ratio**2 * float(template.var())


def _match(search: np.ndarray, sub: np.ndarray, radius: int, usable: np.ndarray) -> np.ndarray:
    """Normalised correlation of ``sub`` at every offset in ``search``, the worst score where not
    ``usable``, minus the centre prior."""
    scores = np.where(usable, _finite(cv2.matchTemplate(search, sub, cv2.TM_CCOEFF_NORMED)), np.float32(-1.0))
    return scores - _prior(scores.shape, radius) if radius > 0 else scores


def _runner_up(scores: np.ndarray, row: int, separation: int) -> float:
    """Best score in the rows at least ``separation`` away from ``row`` (-1 when there are none)."""
    rows = scores.max(axis=1)
    far = np.abs(np.arange(rows.size) - row) >= separation
    return float(rows[far].max()) if far.any() else -1.0


def register_frame(
    reference: np.ndarray,
    known: np.ndarray,
    template: np.ndarray,
    radius: int,
    blur_sigma: float = 1.2,
    min_overlap_fraction: float = 0.1,
    angles_deg: Sequence[float] = (0.0,),
    separation_px: int = 10,
) -> Registration | None:
    """Best shift (and rotation among ``angles_deg``) of ``template`` inside ``reference``,
    ``radius`` px around the centre.

    ``reference``/``known`` cover the predicted box grown by ``radius`` on every side (shape
    h + 2r, w + 2r): the ink probability seen so far and where anything was seen. With three or
    more equally spaced angles the best one is refined by a parabola. Returns None when too little
    of the frame overlaps known content to trust a correlation. ``on_rim`` and ``vertical_margin``
    (judged with the centre prior) tell how far the peak can be trusted.
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
    blurred = blur(template, blur_sigma)
    if float(cv2.meanStdDev(blurred[y0:y1, x0:x1])[1][0, 0]) < 1e-3:  # (np.std costs several times as much)
        return None
    search = blur(reference, blur_sigma)[y0 : y1 + 2 * radius, x0 : x1 + 2 * radius]

    def turned(angle: float) -> np.ndarray:
        if angle == 0:
            return np.ascontiguousarray(blurred[y0:y1, x0:x1])
        rotated = cv2.warpAffine(blurred, frame_transform((h, w), angle), (w, h), flags=cv2.INTER_LINEAR)
        return np.ascontiguousarray(rotated[y0:y1, x0:x1])

    usable = _varied_enough(search, blurred[y0:y1, x0:x1], (2 * radius + 1, 2 * radius + 1), _MIN_SPREAD_RATIO_NEAR)
    matches = {i: _match(search, turned(angle), radius, usable) for i, angle in enumerate(angles_deg)}
    peaks = {i: (float(scores.max()), scores) for i, scores in matches.items()}
    best = max(peaks, key=lambda i: peaks[i][0])
    scores = peaks[best][1]
    angle = float(angles_deg[best])
    if 0 < best < len(angles_deg) - 1:
        step = (angles_deg[best + 1] - angles_deg[best - 1]) / 2.0
        angle += step * parabola_vertex(peaks[best - 1][0], peaks[best][0], peaks[best + 1][0])
    by, bx = divmod(int(scores.argmax()), scores.shape[1])
    reg = _registration_at(scores, by, bx, radius, separation_px, overlap, angle)
    return replace(reg, overlap_at_peak=float(known[by : by + h, bx : bx + w].mean()))


def _registration_at(
    scores: np.ndarray, by: int, bx: int, radius: int, separation_px: int, overlap: float, angle: float
) -> Registration:
    """The registration of the score map's peak at (``by``, ``bx``), the centre prior taken back out."""
    # within a pixel of the edge: the centre prior holds a peak that lies beyond back by a pixel
    on_rim = radius > 1 and not (1 < by < scores.shape[0] - 2 and 1 < bx < scores.shape[1] - 2)
    margin = float(scores[by, bx]) - _runner_up(scores, by, separation_px)
    dx, dy = bx - radius, by - radius
    peak = float(scores[by, bx]) + _CENTRE_PRIOR * (dx * dx + dy * dy) / float(max(1, radius) ** 2)
    sx = parabola_vertex(*scores[by, bx - 1 : bx + 2]) if _interior(scores, by, bx, 0) else 0.0
    sy = parabola_vertex(*scores[by - 1 : by + 2, bx]) if _interior(scores, by, bx, 1) else 0.0
    return Registration((dx, dy), peak, overlap, (sx, sy), angle, on_rim, margin)


def locate_frame(
    reference: np.ndarray,
    known: np.ndarray,
    template: np.ndarray,
    radius: int,
    blur_sigma: float = 1.2,
    min_known_fraction: float = 0.5,
    angle_deg: float = 0.0,
    separation_px: int = 10,
) -> Registration | None:
    """Where the whole of ``template`` matches ``reference`` best, anywhere within ``radius`` px of
    the centre, among the places where at least ``min_known_fraction`` of it lies on known content.

    Unlike ``register_frame`` this does not need the prediction to overlap anything: it finds a
    frame again after the head moved farther than any prediction (walking). Unknown page pixels
    count as paper. None when no place is known enough or the frame holds no ink.
    """
    h, w = template.shape
    if reference.shape != (h + 2 * radius, w + 2 * radius) or known.shape != reference.shape:
        raise ValueError(f"reference {reference.shape} must be the template {template.shape} grown by {radius} px")
    blurred = blur(template, blur_sigma)
    if angle_deg:
        blurred = cv2.warpAffine(blurred, frame_transform((h, w), angle_deg), (w, h), flags=cv2.INTER_LINEAR)
    if float(blurred.std()) < 1e-3:
        return None
    search = blur(reference, blur_sigma)
    scores = _finite(cv2.matchTemplate(search, np.ascontiguousarray(blurred), cv2.TM_CCOEFF_NORMED))
    share = _window_mean(known.astype(np.float32), (h, w), scores.shape)
    usable = (share >= min_known_fraction) & _varied_enough(search, blurred, scores.shape, _MIN_SPREAD_RATIO)
    scores = np.where(usable, np.clip(scores, -1.0, 1.0), -1.0) - _prior(scores.shape, radius)
    by, bx = np.unravel_index(int(np.argmax(scores)), scores.shape)
    if not usable[by, bx]:
        return None
    return _registration_at(scores, int(by), int(bx), radius, separation_px, float(share[by, bx]), angle_deg)
