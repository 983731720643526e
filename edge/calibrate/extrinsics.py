"""``T_event_cpf`` from a board seen by the Aria RGB camera and the event camera at the same time.

Each camera's pose relative to the board comes from solvePnP on the known board geometry (the
RGB camera with its own model: a rectified pinhole from ``calibration.json``'s ``rgb_camera`` or
Aria's Fisheye624 from a device-calibration JSON); the RGB camera's pose relative to CPF is
known, so ``T_event_cpf = T_event_board · T_board_rgb · T_rgb_cpf``. Several views are averaged
(chordal mean of the rotations, mean of the translations) and their spread reported.

Fallback for a flat page when no board geometry is known: a homography between the two images
of the page's markers. It maps page points only (RGB pixel -> event pixel), so it gives **no**
``T_event_cpf``: it is only valid for gaze points that lie on that page plane.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from darkread.edge.calibrate.cameras import Camera, Fisheye624Camera
from darkread.edge.calibrate.markers import Detection, board_pose, pose_matrix
from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import Intrinsics

logger = logging.getLogger(__name__)


def camera_board_pose(detection: Detection, camera: Camera) -> tuple[np.ndarray, float]:
    """``T_camera_board`` and the RMS reprojection error (px) for any supported camera model."""
    if isinstance(camera, Intrinsics):
        return board_pose(detection, camera.camera_matrix(), camera.distortion_coefficients())
    if isinstance(camera, Fisheye624Camera):
        rays = camera.unproject(detection.image_points.astype(np.float64))
        normalised = Detection(detection.object_points, rays.astype(np.float32), detection.ids, detection.n_markers)
        T, _ = board_pose(normalised, np.eye(3), None)
        pts = detection.object_points.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        err = camera.project(pts) - detection.image_points
        return T, float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    raise CalibrationError(f"unsupported camera model {type(camera).__name__}")


def average_poses(poses: list[np.ndarray]) -> np.ndarray:
    """Chordal mean of the rotations (SVD projection of their sum) and mean translation."""
    if not poses:
        raise CalibrationError("no poses to average")
    u, _, vt = np.linalg.svd(sum(T[:3, :3] for T in poses))
    R = u @ vt
    if np.linalg.det(R) < 0:
        u[:, -1] *= -1
        R = u @ vt
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.mean([T_[:3, 3] for T_ in poses], axis=0)
    return T


def rotation_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    cos = (np.trace(R_a.T @ R_b) - 1) / 2
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


@dataclass
class ExtrinsicsResult:
    T_event_cpf: np.ndarray
    n_views: int
    rotation_spread_deg: float  # largest angle of a single view's estimate from the mean
    translation_spread_m: float  # largest distance of a single view's estimate from the mean
    event_rms_px: list[float] = field(default_factory=list)
    rgb_rms_px: list[float] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "T_event_cpf": self.T_event_cpf.tolist(), "n_views": self.n_views,
            "rotation_spread_deg": self.rotation_spread_deg, "translation_spread_m": self.translation_spread_m,
            "event_rms_px": self.event_rms_px, "rgb_rms_px": self.rgb_rms_px,
        }


def extrinsics_from_views(
    views: list[tuple[Detection, Detection]],
    event_camera: Intrinsics,
    rgb_camera: Camera,
    T_rgb_cpf: np.ndarray,
    *,
    max_rms_px: float = 2.0,
) -> ExtrinsicsResult:
    """``T_event_cpf`` from (event detection, RGB detection) pairs taken at the same instant."""
    estimates, ev_rms, rgb_rms = [], [], []
    for event_det, rgb_det in views:
        T_event_board, e_rms = camera_board_pose(event_det, event_camera)
        T_rgb_board, r_rms = camera_board_pose(rgb_det, rgb_camera)
        if e_rms > max_rms_px or r_rms > max_rms_px:
            logger.warning("view skipped: reprojection error %.2f px (event), %.2f px (RGB)", e_rms, r_rms)
            continue
        estimates.append(T_event_board @ np.linalg.inv(T_rgb_board) @ T_rgb_cpf)
        ev_rms.append(e_rms)
        rgb_rms.append(r_rms)
    if not estimates:
        raise CalibrationError("no view had the board detected well in both cameras")
    mean = average_poses(estimates)
    rot = max(rotation_deg(mean[:3, :3], T[:3, :3]) for T in estimates)
    trans = max(float(np.linalg.norm(mean[:3, 3] - T[:3, 3])) for T in estimates)
    return ExtrinsicsResult(mean, len(estimates), rot, trans, ev_rms, rgb_rms)


@dataclass
class HomographyResult:
    """RGB pixel -> event pixel for points on one flat page; NOT a camera pose."""

    H_event_rgb: np.ndarray
    rms_px: float
    n_points: int
    note: str = "valid only for points on the page plane; gives no T_event_cpf"

    def to_dict(self) -> dict:
        return {"H_event_rgb": self.H_event_rgb.tolist(), "rms_px": self.rms_px, "n_points": self.n_points, "note": self.note}

    def map(self, rgb_uv: np.ndarray) -> np.ndarray:
        pts = np.asarray(rgb_uv, dtype=np.float64).reshape(-1, 1, 2)
        return cv2.perspectiveTransform(pts, self.H_event_rgb).reshape(-1, 2)


def page_homography(event_det: Detection, rgb_det: Detection, *, rgb_camera: Camera | None = None,
                    event_camera: Intrinsics | None = None) -> HomographyResult:
    """Homography from matched marker corners (by id) of a flat page; undistorts when cameras are given."""
    common, ie, ir = np.intersect1d(event_det.ids, rgb_det.ids, return_indices=True)
    if common.size < 4:
        raise CalibrationError(f"only {common.size} marker corners seen by both cameras; a homography needs 4")
    src = rgb_det.image_points[ir].astype(np.float64)
    dst = event_det.image_points[ie].astype(np.float64)
    if rgb_camera is not None and isinstance(rgb_camera, Fisheye624Camera):
        raise CalibrationError("undistort fisheye RGB points before the homography fallback (use the pose route instead)")
    H, _ = cv2.findHomography(src, dst, cv2.USAC_MAGSAC, 2.0)
    if H is None:
        raise CalibrationError("no consistent homography between the two views of the page")
    mapped = cv2.perspectiveTransform(src.reshape(-1, 1, 2), H).reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((mapped - dst) ** 2, axis=1))))
    return HomographyResult(H, rms, int(common.size))


__all__ = [
    "ExtrinsicsResult", "HomographyResult", "average_poses", "camera_board_pose", "extrinsics_from_views",
    "page_homography", "pose_matrix", "rotation_deg",
]
