"""Undo a finished line's warp: KLT-track features between the page above and the line's strip
where they overlap (a window is ~3 lines tall, so each strip also shows the previous line), fit the
displacement as a low-order polynomial of x, and resample the strip to agree with the page."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from darkread.stitch.canvas import Canvas
from darkread.stitch.config import StitchConfig

_FB_MAX_ERROR_PX = 1.0  # forward-backward KLT disagreement above which a track is discarded
_MIN_SHIFT_PX = 0.25  # smaller corrections are not worth resampling (and blurring) the strip


@dataclass(frozen=True)
class LineWarp:
    """Where the strip shows what the page shows at x: strip(x + dx(x), y + dy(x)) = page(x, y)."""

    dx_coef: np.ndarray  # np.polyval coefficients in page x
    dy_coef: np.ndarray
    x_range: tuple[float, float]  # observed span; evaluation is clamped to it
    points: int

    def at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xc = np.clip(x, *self.x_range)
        return np.polyval(self.dx_coef, xc), np.polyval(self.dy_coef, xc)


def _as_u8(image: np.ndarray) -> np.ndarray:
    return np.clip(cv2.GaussianBlur(image.astype(np.float32), (0, 0), 1.0) * 255.0, 0, 255).astype(np.uint8)


def _robust_polyfit(x: np.ndarray, v: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    keep = np.ones(x.size, bool)
    coef = np.zeros(degree + 1)
    for _ in range(3):
        deg = degree if np.ptp(x[keep]) > 20 else 0
        coef = np.polyfit(x[keep], v[keep], deg)
        coef = np.concatenate([np.zeros(degree - deg), coef])
        resid = np.abs(v - np.polyval(coef, x))
        mad = float(np.median(resid[keep])) * 1.4826
        keep = resid <= max(3.0 * mad, 0.5)
        if keep.sum() < degree + 2:
            break
    return coef, keep


def estimate_line_warp(
    reference: np.ndarray,
    reference_valid: np.ndarray,
    strip: np.ndarray,
    strip_valid: np.ndarray,
    x0: int,
    cfg: StitchConfig = StitchConfig(),
) -> LineWarp | None:
    """Warp of ``strip`` relative to ``reference`` (same box, page x of column 0 is ``x0``).

    None when too few features track reliably or the correction is implausibly large.
    """
    overlap = cv2.erode((reference_valid & strip_valid).astype(np.uint8), np.ones((5, 5), np.uint8))
    if overlap.sum() < 100:
        return None
    ref8, strip8 = _as_u8(reference), _as_u8(strip)
    corners = cv2.goodFeaturesToTrack(ref8, maxCorners=300, qualityLevel=0.02, minDistance=4, mask=overlap * 255)
    if corners is None or len(corners) < cfg.dewarp_min_points:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    fwd, st1, _ = cv2.calcOpticalFlowPyrLK(ref8, strip8, corners, None, winSize=(15, 15), maxLevel=2, criteria=criteria)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(strip8, ref8, fwd, None, winSize=(15, 15), maxLevel=2, criteria=criteria)
    good = (
        (st1.ravel() == 1)
        & (st2.ravel() == 1)
        & (np.linalg.norm((back - corners).reshape(-1, 2), axis=1) < _FB_MAX_ERROR_PX)
    )
    if good.sum() < cfg.dewarp_min_points:
        return None
    p0 = corners.reshape(-1, 2)[good]
    d = fwd.reshape(-1, 2)[good] - p0
    xs = p0[:, 0].astype(np.float64) + x0
    dx_coef, keep_x = _robust_polyfit(xs, d[:, 0].astype(np.float64), cfg.dewarp_degree)
    dy_coef, keep_y = _robust_polyfit(xs, d[:, 1].astype(np.float64), cfg.dewarp_degree)
    inliers = keep_x & keep_y
    if inliers.sum() < cfg.dewarp_min_points:
        return None
    warp = LineWarp(dx_coef, dy_coef, (float(xs[inliers].min()), float(xs[inliers].max())), int(inliers.sum()))
    dx, dy = warp.at(np.array(warp.x_range))
    if max(np.abs(dx).max(), np.abs(dy).max()) > cfg.dewarp_max_shift_px:
        return None
    return warp


def warped_layers(canvas: Canvas, warp: LineWarp) -> dict[str, np.ndarray] | None:
    """Every layer of a strip canvas resampled by ``warp``; None when the warp is negligible."""
    h, w = canvas.shape
    cols = np.arange(w, dtype=np.float64) + canvas.x0
    dx, dy = warp.at(cols)
    if max(np.abs(dx).max(initial=0), np.abs(dy).max(initial=0)) < _MIN_SHIFT_PX:
        return None
    map_x = np.ascontiguousarray(np.broadcast_to((np.arange(w) + dx).astype(np.float32), (h, w)))
    map_y = (np.arange(h, dtype=np.float32)[:, None] + dy.astype(np.float32)[None, :]).astype(np.float32)
    out = {}
    for name, layer in canvas.layers.items():
        interp = cv2.INTER_LINEAR if name in ("avg", "conf") else cv2.INTER_NEAREST
        out[name] = cv2.remap(layer, map_x, map_y, interp, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out


def apply_line_warp(canvas: Canvas, warp: LineWarp) -> bool:
    """Resample every layer of a strip canvas in place; False when the warp is negligible."""
    layers = warped_layers(canvas, warp)
    if layers is None:
        return False
    canvas.layers = layers
    return True


def _agreement(reference: np.ndarray, strip: np.ndarray, where: np.ndarray) -> float:
    """Normalised correlation of two ink images over ``where``."""
    a, b = reference[where].astype(np.float64), strip[where].astype(np.float64)
    if a.size < 2 or a.std() == 0 or b.std() == 0:
        return -1.0
    return float(np.corrcoef(a, b)[0, 1])


def dewarp_strip(
    canvas: Canvas, reference: np.ndarray, reference_valid: np.ndarray, cfg: StitchConfig
) -> LineWarp | None:
    """Estimate a finished strip's warp against the page (same box as the canvas) and undo it, but
    only if that makes the strip agree better with the page where both have content (a warp fitted
    to the neighbouring line's features must not tilt the line itself)."""
    valid = canvas.layers["count"] > 0
    warp = estimate_line_warp(reference, reference_valid, canvas.layers["avg"], valid, canvas.x0, cfg)
    if warp is None:
        return None
    layers = warped_layers(canvas, warp)
    if layers is None:
        return None
    before_where = reference_valid & valid
    after_where = reference_valid & (layers["count"] > 0)
    before = _agreement(reference, canvas.layers["avg"], before_where)
    after = _agreement(reference, layers["avg"], after_where)
    if after < before + cfg.dewarp_min_gain:
        return None
    canvas.layers = layers
    return warp
