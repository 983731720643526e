"""Annotation from pose: every window of a recording of a marker page gets its ink target from the
known page, placed by the page-to-sensor homography found from the markers in the events.

1. **Event images.** The page moves a little all the time (head drift, tremor), so its edges fire.
   Signed events integrated with an exponential decay (``tau`` ~0.1 s) approximate the log
   intensity now minus its recent average: a high-passed picture of the page in which the markers'
   black borders and cells stand out (a cheap reconstruction; no learned network needed).
2. **Markers.** ``cv2.aruco`` finds them (detector tuned for these images: wider adaptive
   thresholds, finer cell sampling) in images every ``image_every_ms``; several decay constants are
   tried per image and the detections are pooled by marker id.
   **Without markers** (dim light: the noise drowns their cells) the page itself is searched in
   the events (``page_search.find_page``: its rendered edge map against 25 ms of events, over a
   grid of scales and rotations), whenever there is neither a marker pose nor a live track.
   Hot pixels (``page_search.hot_pixel_mask``) are dropped from the events used for poses.
3. **Homography.** Detected corners are undistorted with the recording's calibration and
   page-mm -> normalised-image homographies fitted with RANSAC (``cv2.findHomography``). Each
   detection is summarised by where four reference points of the page land; those tracks are
   interpolated in time (only across gaps up to ``max_gap_ms``), and a detection far from what its
   neighbours say is dropped as an outlier.
4. **Time offset.** Events lag the page in dim light (the photoreceptor slows down), and windows end
   between detection images: one offset per recording (within +-``max_offset_ms``) is chosen by
   matching the rendered page's edges against the windows' events.
5. **Targets.** Each 1600-event window (cut exactly as on the glasses: gaze -> fovea -> voxel
   grid) gets the page's ink sampled through the homography at its end time (exact under lens
   distortion: every pixel's undistorted ray is mapped to the page).

Output: a shard (``shard-00000.npz``, the format ``models/train/data.py`` reads and ``train
finetune`` consumes) and ``annotation.json`` with the share of windows annotated, the marker
detection rate and, when the recording carries the simulator's ``pose_truth.npz``, the alignment
residual in pixels against it.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from darkread.edge.calibrate.event_image import count_image
from darkread.edge.calibrate.markers import detector_parameters
from darkread.edge.io.calibration import Calibration
from darkread.models.synth.camera import region_rays
from darkread.models.synth.marker_page import MarkerPage, load_layout, mm_to_px
from darkread.models.synth.recording import load_pose_truth
from darkread.models.synth.shards import SampleMeta, ncc, window_count_image, write_shard
from darkread.models.train.page_search import (
    SearchConfig,
    edge_map,
    find_page,
    homography_from_affine,
    hot_pixel_mask,
)
from darkread.models.train.windows import Windows, read_events, window_stack

log = logging.getLogger(__name__)

WINDOW_HW: tuple[int, int] = (100, 200)
SHARD_NAME = "shard-00000.npz"
SUMMARY_NAME = "annotation.json"
MARKER_MARGIN_MM = 1.0  # the ignore mask's margin around each marker: > the alignment residual, < the gap to the text


class AnnotationError(ValueError):
    """The recording cannot be annotated (no markers found, no windows, ...)."""


@dataclass(frozen=True)
class AnnotateConfig:
    image_every_ms: float = 20.0  # one detection image (and pose) per this interval
    taus_ms: tuple[float, ...] = (150.0, 100.0)  # decay constants tried in turn for a detection image
    redetect_ms: float = 100.0  # while tracking, look for markers again this often
    min_markers: int = 2  # per image, for a homography
    ransac_px: float = 2.0
    max_gap_ms: float = 100.0  # interpolate (and track) between poses at most this far apart
    outlier_px: float = 6.0  # a pose this far from its neighbours' interpolation is dropped
    refine_pose: bool = True  # align rendered page edges to the events (ECC) at every pose
    refine_events_ms: float = 6.0  # events of this span before each image time are aligned
    min_cc: float = 0.2  # weakest accepted ECC correlation
    ink_px_per_mm: float = 8.0  # page raster used for edges
    window_every_ms: float = 40.0
    max_windows: int = 400
    deblur: bool = True  # windows cut as the edge cuts them: moved back along the head's motion ...
    denoise: bool = True  # ... and in dim light without their isolated events, so the network is tuned on what it is given
    max_offset_ms: float = 8.0
    offset_step_ms: float = 1.0
    refine_offset: bool = True
    search_page: bool = True  # without markers and without a track, search the page in the events
    search_events_ms: float = 25.0  # events of this span make the search image
    search_every_ms: float = 100.0  # at most one search per this interval
    search: SearchConfig = SearchConfig()


# -- event images and markers ------------------------------------------------------------------


def decayed_image(events: np.ndarray, t_us: float, tau_us: float, width: int, height: int) -> np.ndarray:
    """Signed events before ``t_us`` weighted by exp(-age / tau), per pixel (float64 [h, w])."""
    t = events["t"]
    lo = int(np.searchsorted(t, t_us - 4.0 * tau_us))
    hi = int(np.searchsorted(t, t_us, side="right"))
    ev = events[lo:hi]
    weight = np.exp(-(t_us - ev["t"]) / tau_us) * (2.0 * ev["p"] - 1.0)
    pixel = ev["y"].astype(np.int64) * width + ev["x"]
    return np.bincount(pixel, weights=weight, minlength=width * height).reshape(height, width)


def to_detection_image(signed: np.ndarray, percentile: float = 98.0) -> np.ndarray:
    """uint8 around mid-grey: darkening (ink arriving) dark, brightening bright; median-filtered."""
    active = np.abs(signed[signed != 0])
    scale = float(np.percentile(active, percentile)) if active.size else 1.0
    image = np.clip(128.0 + 127.0 * signed / max(scale, 1e-9), 0, 255).astype(np.uint8)
    return cv2.medianBlur(image, 3)


def detector(page: MarkerPage) -> cv2.aruco.ArucoDetector:
    """An ArUco detector for event images of ``page``'s dictionary."""

    params = detector_parameters()  # the calibration's (sub-pixel corner refinement)
    params.adaptiveThreshWinSizeMin = 5
    params.adaptiveThreshWinSizeMax = 45
    params.adaptiveThreshWinSizeStep = 8
    params.perspectiveRemovePixelPerCell = 8
    return cv2.aruco.ArucoDetector(page.spec.dictionary_obj(), params)


def detect_markers(image: np.ndarray, det: cv2.aruco.ArucoDetector, known: set[int]) -> dict[int, np.ndarray]:
    """id -> corners (4, 2) px of the page's markers found in ``image``."""
    corners, ids, _ = det.detectMarkers(image)
    if ids is None:
        return {}
    return {int(i): c.reshape(4, 2).astype(np.float64) for c, i in zip(corners, ids.reshape(-1)) if int(i) in known}


# -- homographies ------------------------------------------------------------------------------


def fit_homography(
    found: dict[int, np.ndarray], page: MarkerPage, calib: Calibration, ransac_px: float = 2.0
) -> tuple[np.ndarray, float] | None:
    """Page mm -> undistorted normalised image coordinates from detected markers, and its RMS (px)."""
    if not found:
        return None
    mm = np.concatenate([page.markers[i] for i in found])
    px = np.concatenate([found[i] for i in found])
    norm = calib.unproject(px)
    H, inliers = cv2.findHomography(mm, norm, cv2.RANSAC, ransac_px / calib.fx)
    if H is None or inliers is None or int(inliers.sum()) < 8:
        return None
    H = H / H[2, 2]
    ok = inliers.reshape(-1).astype(bool)
    rms = float(np.sqrt(np.mean(np.sum((project_page(H, calib, mm[ok]) - px[ok]) ** 2, axis=1))))
    return H, rms


def apply_h(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    p = np.c_[np.asarray(points, np.float64).reshape(-1, 2), np.ones(len(points))] @ np.asarray(H).T
    return p[:, :2] / p[:, 2:3]


def project_page(H: np.ndarray, calib: Calibration, points_mm: np.ndarray) -> np.ndarray:
    """Sensor pixels (with distortion) of page points under the page -> normalised homography ``H``."""
    norm = apply_h(H, points_mm)
    return calib.project(np.c_[norm, np.ones(len(norm))])


def reference_points(page: MarkerPage) -> np.ndarray:
    """Four page points spanning the markers (their outer corners): a homography is fixed by them."""
    _, corners = page.marker_points()
    pts = corners.reshape(-1, 2)
    x0, y0 = pts.min(axis=0)
    x1, y1 = pts.max(axis=0)
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


@dataclass
class PoseTrack:
    """Page -> normalised-image homographies over time, interpolated between detections."""

    t_us: np.ndarray  # [n] detection times (sorted)
    tracks: np.ndarray  # [n, 4, 2] normalised image coordinates of the reference points
    reference_mm: np.ndarray  # [4, 2]
    max_gap_us: float

    @staticmethod
    def from_detections(times_us: np.ndarray, homographies: list[np.ndarray], reference_mm: np.ndarray,
                        max_gap_us: float, outlier: float = np.inf) -> PoseTrack:
        """``outlier`` (normalised units): drop detections this far from their neighbours' interpolation."""
        t = np.asarray(times_us, np.float64)
        tracks = np.stack([apply_h(H, reference_mm) for H in homographies]) if homographies else np.zeros((0, 4, 2))
        order = np.argsort(t)
        t, tracks = t[order], tracks[order]
        keep = np.ones(len(t), bool)
        if np.isfinite(outlier) and len(t) >= 3:
            for i in range(1, len(t) - 1):
                w = (t[i] - t[i - 1]) / max(t[i + 1] - t[i - 1], 1.0)
                between = (1 - w) * tracks[i - 1] + w * tracks[i + 1]
                if np.abs(tracks[i] - between).max() > outlier and t[i + 1] - t[i - 1] <= 2 * max_gap_us:
                    keep[i] = False
        return PoseTrack(t[keep], tracks[keep], np.asarray(reference_mm, np.float64), float(max_gap_us))

    def __len__(self) -> int:
        return int(self.t_us.size)

    def at(self, t_us: float) -> np.ndarray | None:
        """The homography at ``t_us``, or None outside the detections or across a longer gap."""
        t = self.t_us
        if t.size == 0 or t_us < t[0] or t_us > t[-1]:
            return None
        k = int(np.clip(np.searchsorted(t, t_us), 1, max(t.size - 1, 1)))
        nearest = int(np.argmin(np.abs(t - t_us)))
        if abs(t[nearest] - t_us) < 1.0:  # at a detection: that detection
            quad = self.tracks[nearest]
        else:
            t0, t1 = t[k - 1], t[k]
            if t1 - t0 > self.max_gap_us:
                return None
            w = 0.0 if t1 == t0 else (t_us - t0) / (t1 - t0)
            quad = (1 - w) * self.tracks[k - 1] + w * self.tracks[k]
        return cv2.getPerspectiveTransform(self.reference_mm.astype(np.float32), quad.astype(np.float32)).astype(np.float64)


# -- targets -----------------------------------------------------------------------------------


def window_rays(calib: Calibration, origin: tuple[int, int], hw: tuple[int, int] = WINDOW_HW) -> np.ndarray:
    """Undistorted normalised rays of a window's pixel centres, [h*w, 2]."""

    return region_rays(calib, int(origin[0]), int(origin[1]), hw[1], hw[0])


def page_coordinates(H: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Page mm of each ray under the page -> normalised homography ``H``."""
    return apply_h(np.linalg.inv(H), rays)


def render_coverage(page_ink: np.ndarray, ink_px_per_mm: float, H: np.ndarray, rays: np.ndarray,
                    hw: tuple[int, int] = WINDOW_HW, shift_px: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Ink coverage (float32 [h, w]) the window sees: every pixel's ray mapped onto the page raster."""
    mm = page_coordinates(H, rays)
    uv = mm_to_px(mm, ink_px_per_mm).astype(np.float32)
    mx = uv[:, 0].reshape(hw)
    my = uv[:, 1].reshape(hw)
    cov = cv2.remap(page_ink, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    if shift_px != (0.0, 0.0):
        m = np.array([[1, 0, shift_px[0]], [0, 1, shift_px[1]]], dtype=np.float32)
        cov = cv2.warpAffine(cov, m, (hw[1], hw[0]), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    return cov


def render_target(page_ink: np.ndarray, ink_px_per_mm: float, H: np.ndarray, rays: np.ndarray,
                  hw: tuple[int, int] = WINDOW_HW) -> np.ndarray:
    """The window's binary target (uint8, 1 = ink), as the synthetic shards define it (coverage >= 0.5)."""
    return (render_coverage(page_ink, ink_px_per_mm, H, rays, hw) >= 0.5).astype(np.uint8)


def pixels_per_mm(H: np.ndarray, calib: Calibration, at_mm: np.ndarray) -> float:
    """Sensor pixels per page millimetre near ``at_mm`` (for sampling the ink at the right scale)."""
    p = np.array([at_mm, at_mm + [1.0, 0.0], at_mm + [0.0, 1.0]], np.float64)
    uv = project_page(H, calib, p)
    return float((np.linalg.norm(uv[1] - uv[0]) + np.linalg.norm(uv[2] - uv[0])) / 2)


PageRaster = Callable[[np.ndarray, Calibration], tuple[np.ndarray, float]]  # (H, calibration) -> (raster, texels per mm)


def page_raster_for_pose(page: MarkerPage, raster_at: Callable[[float], np.ndarray]) -> PageRaster:
    """(H, calibration) -> ``raster_at(s)`` and ``s``, its texels per mm, ~1.25 texels per sensor pixel
    under that pose (as the simulator's texture); one raster per quarter step of scale, kept."""
    centre_mm = np.asarray(page.text_box_mm).reshape(2, 2).mean(axis=0)
    cache: dict[float, np.ndarray] = {}

    def at(H: np.ndarray, calib: Calibration) -> tuple[np.ndarray, float]:
        s = max(1.0, round(1.25 * pixels_per_mm(H, calib, centre_mm) * 4) / 4)
        if s not in cache:
            cache[s] = raster_at(s)
        return cache[s], s

    return at


def page_ink_for_pose(page: MarkerPage) -> PageRaster:
    """The page's ink at a pose's scale (the targets)."""
    return page_raster_for_pose(page, page.ink_at)


def marker_area_for_pose(page: MarkerPage, margin_mm: float = MARKER_MARGIN_MM) -> PageRaster:
    """The markers' squares (grown by ``margin_mm``) at a pose's scale (the ignore masks)."""
    return page_raster_for_pose(page, lambda s: page.marker_area_at(s, margin_mm))


def render_ignore(marker_area: np.ndarray, px_per_mm: float, H: np.ndarray, rays: np.ndarray,
                  hw: tuple[int, int] = WINDOW_HW) -> np.ndarray:
    """The window's ignore mask (uint8, 1 = a pixel that sees any of a marker's area): tuning must not
    learn the markers, which no page a user reads carries; rendered exactly as the target is."""
    return (render_coverage(marker_area, px_per_mm, H, rays, hw) > 0.0).astype(np.uint8)


def alignment_residual(H_est: np.ndarray, H_true_cam: np.ndarray, calib: Calibration, origin: tuple[int, int],
                       hw: tuple[int, int] = WINDOW_HW) -> float:
    """Mean pixel distance, over a grid of the window, between where the estimate and the truth put
    the page point each pixel sees (``H_true_cam``: page mm -> camera point, the simulator's pose)."""
    xs, ys = np.meshgrid(np.linspace(0, hw[1] - 1, 9) + origin[0], np.linspace(0, hw[0] - 1, 5) + origin[1])
    uv = np.c_[xs.ravel(), ys.ravel()]
    mm = page_coordinates(H_est, calib.unproject(uv))
    cam = np.c_[mm, np.ones(len(mm))] @ np.asarray(H_true_cam).T
    return float(np.mean(np.linalg.norm(calib.project(cam) - uv, axis=1)))


# -- the whole recording -----------------------------------------------------------------------


class SensorRays:
    """Undistorted rays of every sensor pixel, computed once per recording (crops are views)."""

    def __init__(self, calib: Calibration) -> None:

        self.rays = region_rays(calib, 0, 0, calib.width, calib.height).reshape(calib.height, calib.width, 2)

    def box(self, x0: int, y0: int, w: int, h: int) -> np.ndarray:
        return self.rays[y0 : y0 + h, x0 : x0 + w].reshape(-1, 2)


def page_box(H: np.ndarray, page: MarkerPage, calib: Calibration, margin: int = 10) -> tuple[int, int, int, int] | None:
    """(x0, y0, w, h): the sensor pixels the page covers under ``H`` (None when off the sensor)."""
    w_mm, h_mm = page.size_mm
    grid = np.stack(np.meshgrid(np.linspace(0, w_mm, 9), np.linspace(0, h_mm, 7)), -1).reshape(-1, 2)
    uv = project_page(H, calib, grid)
    if not np.isfinite(uv).all():
        return None
    x0, y0 = np.maximum(np.floor(uv.min(0)) - margin, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(uv.max(0)) + margin, [calib.width, calib.height]).astype(int)
    if x1 - x0 < 16 or y1 - y0 < 16:
        return None
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)


def refine_pose(H: np.ndarray, events: np.ndarray, page: MarkerPage, ink: np.ndarray, ink_px_per_mm: float,
                calib: Calibration, rays: SensorRays, iterations: int = 40,
                max_jump_px: float = 12.0) -> tuple[np.ndarray, float] | None:
    """Align the page's rendered edges to the events' count image (``cv2.findTransformECC``, a
    homography in sensor pixels), and fold the correction back into page -> normalised ``H``.

    Returns (H, correlation) or None when ECC does not converge or the page is out of view.
    """
    box = page_box(H, page, calib)
    if box is None or len(events) == 0:
        return None
    x0, y0, bw, bh = box
    template = edge_map(render_coverage(ink, ink_px_per_mm, H, rays.box(*box), (bh, bw)))
    x = events["x"].astype(np.int64) - x0
    y = events["y"].astype(np.int64) - y0
    keep = (x >= 0) & (x < bw) & (y >= 0) & (y < bh)
    counts: np.ndarray = np.bincount(y[keep] * bw + x[keep], minlength=bw * bh).astype(np.float32).reshape(bh, bw)
    counts = cv2.GaussianBlur(counts, (0, 0), 1.0)
    warp = np.eye(3, dtype=np.float32)
    try:
        cc, warp = cv2.findTransformECC(template, counts, warp, cv2.MOTION_HOMOGRAPHY,  # type: ignore[call-overload]  # OpenCV takes no mask (None), its stubs do not
                                        (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, 1e-5), None, 5)
    except cv2.error:  # no convergence (too few events, featureless view)
        return None
    w_mm, h_mm = page.size_mm
    grid = np.stack(np.meshgrid(np.linspace(0, w_mm, 7), np.linspace(0, h_mm, 5)), -1).reshape(-1, 2)
    uv = project_page(H, calib, grid)
    moved = apply_h(warp.astype(np.float64), uv - [x0, y0]) + [x0, y0]
    if np.abs(moved - uv).max() > max_jump_px:  # a jump this large is a wrong optimum, not a correction
        return None
    refined, _ = cv2.findHomography(grid, calib.unproject(moved), 0)
    if refined is None:
        return None
    return refined / refined[2, 2], float(cc)


def detect_track(events: np.ndarray, page: MarkerPage, calib: Calibration, cfg: AnnotateConfig,
                 width: int, height: int, progress: bool = False) -> tuple[PoseTrack, dict[str, Any]]:
    """Markers in event images -> poses refined on the events -> the pose track and statistics.

    Between marker detections the last refined pose seeds the next refinement (tracking), for at
    most ``max_gap_ms``; a pose is kept when the refinement converges with correlation >= ``min_cc``.
    """
    from tqdm import tqdm

    det = detector(page)
    known = set(page.markers)
    rays = SensorRays(calib)
    ink = page.ink_at(cfg.ink_px_per_mm)
    hot = hot_pixel_mask(events, width, height)
    events = events[~hot[events["y"], events["x"]]]  # hot pixels say nothing about the page
    t_first, t_last = float(events["t"][0]), float(events["t"][-1])
    start = min(max(cfg.taus_ms), cfg.search_events_ms if cfg.search_page else np.inf) * 1e3
    times = np.arange(t_first + start, t_last, cfg.image_every_ms * 1e3)
    det_t, det_h, per_image, rms, ccs, search_scores = [], [], [], [], [], []
    n_marker_poses = n_tracked = n_searched = n_search_poses = 0
    last: tuple[float, np.ndarray] | None = None
    last_detection = last_search = -np.inf
    for t in tqdm(times, desc="poses", disable=not progress, leave=False):
        tracking = last is not None and t - last[0] <= cfg.max_gap_ms * 1e3
        found: dict[int, np.ndarray] = {}
        if (not tracking or t - last_detection >= cfg.redetect_ms * 1e3) and t - t_first >= max(cfg.taus_ms) * 1e3:
            last_detection = t
            for tau in cfg.taus_ms:  # until enough markers are found
                image = to_detection_image(decayed_image(events, t, tau * 1e3, width, height))
                for i, c in detect_markers(image, det, known).items():
                    found.setdefault(i, c)
                if len(found) >= cfg.min_markers:
                    break
            per_image.append(len(found))
        seed = None
        if len(found) >= cfg.min_markers:
            fit = fit_homography(found, page, calib, cfg.ransac_px)
            if fit is not None:
                seed = fit[0]
                rms.append(fit[1])
                n_marker_poses += 1
        from_markers = seed is not None
        if seed is None and tracking and last is not None:
            seed = last[1]
        span_ms = cfg.refine_events_ms
        from_search = False
        if seed is None and cfg.search_page and cfg.refine_pose and t - last_search >= cfg.search_every_ms * 1e3:
            last_search = t
            n_searched += 1
            lo, hi = np.searchsorted(events["t"], [t - cfg.search_events_ms * 1e3, t])
            match = find_page(count_image(events[lo:hi], width, height), page, cfg.search)
            if match is not None:
                seed = homography_from_affine(match.affine, page, calib)
                search_scores.append(match.score)
                span_ms, from_search = cfg.search_events_ms, True
        if seed is None:
            continue
        if not cfg.refine_pose:
            if from_markers:
                det_t.append(t)
                det_h.append(seed)
            continue
        lo, hi = np.searchsorted(events["t"], [t - span_ms * 1e3, t])
        # a page search is good to a few per cent of the page's size (its scale and angle steps)
        jump = max(12.0, 0.04 * page.size_mm[0] * match.px_per_mm) if from_search and match is not None else 12.0
        refined = refine_pose(seed, events[lo:hi], page, ink, cfg.ink_px_per_mm, calib, rays, max_jump_px=jump)
        if refined is None or refined[1] < cfg.min_cc:
            continue
        det_t.append(t - span_ms * 500)  # the events' middle
        det_h.append(refined[0])
        ccs.append(refined[1])
        n_tracked += not from_markers and not from_search
        n_search_poses += from_search
        last = (t, refined[0])
    track = PoseTrack.from_detections(np.array(det_t), det_h, reference_points(page), cfg.max_gap_ms * 1e3,
                                      outlier=cfg.outlier_px / calib.fx)
    n = max(len(per_image), 1)
    stats = {
        "pose_times": int(len(times)),
        "detection_images": int(len(per_image)),
        "images_with_marker_pose": int(n_marker_poses),
        "detection_rate": round(n_marker_poses / n, 4),
        "marker_detection_rate": round(float(np.sum(per_image)) / (n * len(page.markers)), 4),
        "markers_per_image_mean": round(float(np.mean(per_image)) if per_image else 0.0, 3),
        "poses": int(len(det_t)),
        "poses_tracked_without_markers": int(n_tracked),
        "page_searches": int(n_searched),
        "poses_from_page_search": int(n_search_poses),
        "page_search_score_median": round(float(np.median(search_scores)), 3) if search_scores else None,
        "outliers_dropped": int(len(det_t) - len(track)),
        "corner_rms_px_median": round(float(np.median(rms)), 3) if rms else None,
        "refine_correlation_median": round(float(np.median(ccs)), 3) if ccs else None,
    }
    return track, stats


def choose_offset(windows: Windows, track: PoseTrack, page: MarkerPage, calib: Calibration, cfg: AnnotateConfig,
                  rays: list[np.ndarray], sample: int = 40) -> tuple[float, list[float]]:
    """The time offset (us) within +-max_offset between the pose track and the windows' events.

    Each window's events are matched against the page rendered at their median time plus the
    offset; the best offset is then applied at the windows' end times (the target's time).
    """
    ink = page.ink_at(cfg.ink_px_per_mm)
    offsets = np.arange(-cfg.max_offset_ms, cfg.max_offset_ms + 1e-9, cfg.offset_step_ms) * 1e3
    idx = np.linspace(0, len(windows.t_end_us) - 1, min(sample, len(windows.t_end_us))).astype(int)
    sensed = windows.raw  # (the page over the events' span, before any deblur)
    counts = {int(i): window_count_image(sensed[i], tuple(windows.origins[i])) for i in idx}
    scores = []
    for off in offsets:
        vals = []
        for i in idx:
            H = track.at(float(np.median(sensed[i]["t"]) + off))  # the events show the page over their span
            if H is None:
                continue
            vals.append(ncc(edge_map(render_coverage(ink, cfg.ink_px_per_mm, H, rays[i])), counts[int(i)]))
        scores.append(float(np.mean(vals)) if vals else -1.0)
    best = int(np.argmax(scores))
    off = float(offsets[best])
    if 0 < best < len(scores) - 1:  # parabolic peak
        a, b, c = scores[best - 1], scores[best], scores[best + 1]
        den = a - 2 * b + c
        if den < 0:
            off += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) * cfg.offset_step_ms * 1e3
    return off, scores


def annotate_recording(recording: str | Path, layout: str | Path | None, out: str | Path,
                       cfg: AnnotateConfig = AnnotateConfig(), *, progress: bool = True) -> dict[str, Any]:
    """Annotate every window of ``recording`` from the marker page's pose; writes the shard and summary."""

    recording = Path(recording)
    layout = Path(layout) if layout is not None else recording / "page.layout.json"
    page = load_layout(layout)
    rec, events, (width, height) = read_events(recording, need_text=False)
    calib = rec.calibration
    track, stats = detect_track(events, page, calib, cfg, width, height, progress=progress)
    if len(track) == 0:
        raise AnnotationError(f"{recording}: no markers of {layout.name} found in the events, nor the page itself "
                              f"({stats['detection_images']} event images; is this a recording of that page?)")
    windows = window_stack(rec, events, (width, height), every_ms=cfg.window_every_ms, max_windows=cfg.max_windows,
                           deblur=cfg.deblur, denoise=cfg.denoise)
    if len(windows.t_end_us) == 0:
        raise AnnotationError(f"{recording}: no windows to annotate (no gaze, or too few events)")
    rays = [window_rays(calib, tuple(o)) for o in windows.origins]
    offset_us, offset_scores = (choose_offset(windows, track, page, calib, cfg, rays) if cfg.refine_offset else (0.0, []))
    truth = load_pose_truth(recording)
    ink_for = page_ink_for_pose(page)
    markers_for = marker_area_for_pose(page)
    kept, targets, ignores, metas, residuals, residuals_raw = [], [], [], [], [], []
    meta = rec.meta
    centre_mm = np.asarray(page.text_box_mm).reshape(2, 2).mean(axis=0)
    for i, (t_end, origin) in enumerate(zip(windows.t_end_us, windows.origins)):
        H = track.at(float(t_end + offset_us))
        if H is None:
            continue
        page_ink, s = ink_for(H, calib)
        target = render_target(page_ink, s, H, rays[i])
        area, s_area = markers_for(H, calib)
        kept.append(i)
        targets.append(target)
        ignores.append(render_ignore(area, s_area, H, rays[i]))
        metas.append(SampleMeta(lux=float(meta.get("lux", 0.0)), motion=str(meta.get("motion", "")), kind="marker_page",
                                font=page.spec.font, xheight_px=float(page.xheight_mm * pixels_per_mm(H, calib, centre_mm)),
                                seed=int(meta.get("seed", 0)), x0=int(origin[0]), y0=int(origin[1]),
                                t_end_us=int(t_end), n_events=int(len(windows.events[i]))))
        if truth is not None:
            residuals.append(alignment_residual(H, truth.at(float(t_end)), calib, tuple(origin)))
            H_raw = track.at(float(t_end))
            if H_raw is not None:
                residuals_raw.append(alignment_residual(H_raw, truth.at(float(t_end)), calib, tuple(origin)))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if kept:
        write_shard(out / SHARD_NAME, windows.voxels[kept], np.stack(targets), metas, ignore=np.stack(ignores))
    summary: dict[str, Any] = {
        "recording": str(recording),
        "layout": str(layout),
        "lux": meta.get("lux"),
        "windows": int(len(windows.t_end_us)),
        "annotated": int(len(kept)),
        "annotated_share": round(len(kept) / len(windows.t_end_us), 4),
        **stats,
        "time_offset_ms": round(offset_us / 1e3, 3),
        "ignored_pixel_share": round(float(np.mean(ignores)), 4) if ignores else 0.0,
        "marker_margin_mm": MARKER_MARGIN_MM,
        "config": asdict(cfg),
    }
    if residuals:
        summary["residual_px"] = {"median": round(float(np.median(residuals)), 3),
                                  "p90": round(float(np.percentile(residuals, 90)), 3), "n": len(residuals)}
    if residuals_raw:
        summary["residual_px_without_offset"] = {"median": round(float(np.median(residuals_raw)), 3),
                                                 "p90": round(float(np.percentile(residuals_raw, 90)), 3)}
    (out / SUMMARY_NAME).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    if not kept:
        raise AnnotationError(f"{recording}: markers were found but no window falls within the pose track")
    return summary


