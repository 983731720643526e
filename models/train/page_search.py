"""Finding the page in an event image without its markers: a global search for the initial pose.

In dim light the sensor's noise (shot noise of several hertz per pixel, hot pixels) drowns the
markers' 5-10 px cells, so ``cv2.aruco`` finds nothing; but the page as a whole (every text line,
every marker border: thousands of edge pixels) still stands out in an image of a few tens of
milliseconds of events. The page's rendered edge map is matched against that image by normalised
cross-correlation (``cv2.matchTemplate``, FFT-based) over a small grid of scales and in-plane
rotations at a quarter of the sensor's resolution; the best match is an initial pose good to a few
pixels, which the edge alignment (``annotate.refine_pose``) then makes exact.

The search ignores perspective and lens distortion (a printed page read at arm's length is nearly
fronto-parallel and small on the sensor); the refinement that follows models both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from darkread.edge.calibrate.event_image import count_image
from darkread.edge.io.calibration import Calibration
from darkread.models.synth.marker_page import MarkerPage


@dataclass(frozen=True)
class SearchConfig:
    px_per_mm: tuple[float, float] = (2.0, 8.0)  # page scales searched: markers of 12 mm at 24-96 px
    scale_step: float = 1.05  # ratio between searched scales
    max_angle_deg: float = 10.0  # in-plane rotations searched, +-
    angle_step_deg: float = 2.5
    down: int = 4  # the search runs at 1/down of the sensor's resolution
    min_score: float = 0.3  # weakest accepted correlation of the best match
    min_margin: float = 0.08  # ... and by how much it must beat the best match elsewhere


@dataclass(frozen=True)
class PageMatch:
    """The best match: page mm -> sensor pixel as an affine map, and how convincing it was."""

    affine: np.ndarray  # [2, 3]: pixel = affine[:, :2] @ mm + affine[:, 2]
    score: float  # normalised cross-correlation of the best match
    margin: float  # score minus the best score away from it (another place, scale or angle)
    px_per_mm: float
    angle_deg: float


def hot_pixel_mask(events: np.ndarray, width: int, height: int, factor: float = 5.0, floor: float = 20.0) -> np.ndarray:
    """Pixels firing far more than their neighbourhood over the whole recording (bool [h, w]).

    A hot pixel fires hundreds of times a second whatever it sees; the page's edges fire as
    often but along lines, so a pixel is hot when it beats ``factor`` x the 5x5 median around it.
    """
    counts = count_image(events, width, height)
    return counts > factor * cv2.medianBlur(counts, 5) + floor


def edge_map(coverage: np.ndarray, sigma: float = 1.0) -> np.ndarray:
    """Where a moving page fires: the gradient magnitude of its ink, lightly blurred."""
    gx = cv2.Sobel(coverage, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(coverage, cv2.CV_32F, 0, 1, ksize=3)
    return cv2.GaussianBlur(np.sqrt(gx * gx + gy * gy), (0, 0), sigma)


def page_template(page: MarkerPage, px_per_mm: float, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The page's edge map at ``px_per_mm``, rotated by ``angle_deg``, and the affine page mm -> template px."""
    ink_ppm = max(1.25 * px_per_mm, 1.0)  # sample the ink a little finer than the template, as the simulator
    ink = page.ink_at(ink_ppm)
    theta = np.radians(angle_deg)
    rotation = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    w_mm, h_mm = page.size_mm
    corners = np.array([[0.0, 0.0], [w_mm, 0.0], [w_mm, h_mm], [0.0, h_mm]]) @ (rotation * px_per_mm).T
    offset = -corners.min(axis=0)
    size = np.ceil(corners.max(axis=0) + offset).astype(int) + 1
    to_template = np.c_[rotation * px_per_mm / ink_ppm, offset]  # ink px -> template px
    coverage = cv2.warpAffine(ink, to_template, (int(size[0]), int(size[1])), flags=cv2.INTER_AREA)
    return edge_map(coverage), np.c_[rotation * px_per_mm, offset]


def search_grid(cfg: SearchConfig) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = cfg.px_per_mm
    scales = np.exp(np.arange(np.log(lo), np.log(hi) + 1e-9, np.log(cfg.scale_step)))
    angles = np.arange(-cfg.max_angle_deg, cfg.max_angle_deg + 1e-9, cfg.angle_step_deg)
    return scales, angles


def find_page(counts: np.ndarray, page: MarkerPage, cfg: SearchConfig = SearchConfig()) -> PageMatch | None:
    """The page's pose in an event count image (noise and hot pixels allowed), or None when no
    scale and angle of the grid fits it convincingly (``min_score``, ``min_margin``)."""
    d = cfg.down
    h, w = counts.shape
    image = cv2.resize(cv2.GaussianBlur(counts.astype(np.float32), (0, 0), d / 1.5), (w // d, h // d),
                       interpolation=cv2.INTER_AREA)
    scales, angles = search_grid(cfg)
    hypotheses = []  # (peak, px_per_mm, angle, location, page mm -> template px, best score elsewhere)
    for s in scales:
        for a in angles:
            template, to_template = page_template(page, s / d, a)
            if template.shape[0] >= image.shape[0] or template.shape[1] >= image.shape[1] or template.max() <= 0:
                continue
            scores = cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED)
            _, peak, _, loc = cv2.minMaxLoc(scores)
            hypotheses.append((float(peak), float(s), float(a), loc, to_template,
                               _elsewhere(scores, loc, radius=max(3, int(round(2 * s))))))
    if not hypotheses:
        return None
    best = max(hypotheses, key=lambda h: h[0])
    score, s, a, (lx, ly), to_template, elsewhere = best
    rivals = [h[0] for h in hypotheses if not _near(best, h[1], h[2])] + [elsewhere]
    margin = score - max(rivals)
    if score < cfg.min_score or margin < cfg.min_margin:
        return None
    # template px at 1/d -> sensor px: pixel centres of the reduced image sit at d * (i + 0.5) - 0.5
    affine = np.c_[to_template[:, :2] * d, (to_template[:, 2] + [lx, ly]) * d + (d - 1) / 2]
    return PageMatch(affine, score, float(margin), s, a)


def _near(best: tuple, s: float, a: float) -> bool:
    """A neighbour in the grid of the best hypothesis (its peak is the same page, not a rival)."""
    return abs(np.log(s / best[1])) < 0.25 and abs(a - best[2]) <= 5.0


def _elsewhere(scores: np.ndarray, loc: Sequence[int], radius: int) -> float:
    """The best score away from ``loc`` (outside a square of ``radius``)."""
    x, y = loc
    masked = scores.copy()
    masked[max(0, y - radius) : y + radius + 1, max(0, x - radius) : x + radius + 1] = -1.0
    return float(masked.max())


def homography_from_affine(affine: np.ndarray, page: MarkerPage, calib: Calibration) -> np.ndarray:
    """Page mm -> undistorted normalised image homography that puts the page where ``affine`` puts it."""
    w_mm, h_mm = page.size_mm
    grid = np.stack(np.meshgrid(np.linspace(0, w_mm, 5), np.linspace(0, h_mm, 4)), -1).reshape(-1, 2)
    uv = grid @ affine[:, :2].T + affine[:, 2]
    H, _ = cv2.findHomography(grid, calib.unproject(uv), 0)
    return H / H[2, 2]
