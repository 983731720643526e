"""Event-camera intrinsics (fx, fy, cx, cy, radtan k1 k2 p1 p2) from a flashing or moved board.

A board flashing on a screen, or a printed board moved to several poses and lit by a lamp
switched on at each: every burst of the capture gives one detection image; the board corners found in each feed
``cv2.calibrateCamera`` with k3 fixed at zero (the recording format's radtan model has four
coefficients). Views with too few corners are skipped; at least three views are needed.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from darkread.edge.calibrate.event_image import (
    Burst,
    burst_events,
    detection_image,
    find_bursts,
    latency_image,
)
from darkread.edge.calibrate.markers import BoardSpec, Detection, detect_board
from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import RADTAN_KEYS, Intrinsics

logger = logging.getLogger(__name__)

MIN_VIEWS = 3


@dataclass
class View:
    """One detection image of the board and what was found in it."""

    burst: Burst
    detection: Detection | None


@dataclass(frozen=True, eq=False)
class IntrinsicsResult(Intrinsics):
    """The fitted camera, and how well it fits the board corners."""

    rms_px: float  # RMS reprojection error over all corners of all used views
    std: dict[str, float]  # standard deviations of fx, fy, cx, cy, k1, k2, p1, p2 (from the fit's Jacobian)
    per_view_rms_px: list[float]
    n_views: int
    n_corners: int
    poses: list[np.ndarray] = field(repr=False, default_factory=list)  # T_event_board per used view

    def to_dict(self) -> dict:
        return {
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "distortion": dict(zip(RADTAN_KEYS, self.distortion)),
            "rms_px": self.rms_px, "std": self.std, "n_views": self.n_views, "n_corners": self.n_corners,
        }


def detect_views(
    events: np.ndarray, spec: BoardSpec, width: int, height: int, *, bursts: list[Burst] | None = None, lamp: bool = False
) -> list[View]:
    """One view per burst: its detection image and the board corners in it (or None).

    ``lamp``: a printed board held at each pose while a lamp is switched on (ON bursts, imaged by
    first-event latency) instead of a board flashing on a screen (every burst, imaged by counts).
    """
    views = []
    for burst in bursts if bursts is not None else find_bursts(events):
        if lamp:
            if burst.polarity != 1:
                continue
            image = latency_image(burst_events(events, burst), width, height, burst.onset_us - 200.0)
        else:
            image = detection_image(burst_events(events, burst), width, height)
        views.append(View(burst, detect_board(image, spec)))
    found = sum(v.detection is not None for v in views)
    logger.info("board found in %d of %d bursts", found, len(views))
    return views


def calibrate_intrinsics(
    detections: list[Detection], width: int, height: int, *, min_corners: int = 8, zero_tangential: bool = True
) -> IntrinsicsResult:
    """``cv2.calibrateCamera`` on the detections (k3 fixed at 0); CalibrationError if too few views."""
    used = [d for d in detections if d is not None and len(d) >= min_corners]
    if len(used) < MIN_VIEWS:
        raise CalibrationError(
            f"the board was found in only {len(used)} views with >= {min_corners} corners; "
            f"intrinsics need at least {MIN_VIEWS} views from different angles"
        )
    obj = [d.object_points.reshape(-1, 1, 3).astype(np.float32) for d in used]
    img = [d.image_points.reshape(-1, 1, 2).astype(np.float32) for d in used]
    flags = cv2.CALIB_FIX_K3 | (cv2.CALIB_ZERO_TANGENT_DIST if zero_tangential else 0)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs, std_intrinsics, _, _ = cv2.calibrateCameraExtended(  # type: ignore[call-overload]  # OpenCV takes None for the initial camera matrix and distortion, its stubs do not
        obj, img, (width, height), None, None, flags=flags, criteria=criteria
    )
    dist = np.asarray(dist, dtype=np.float64).reshape(-1)
    std = np.asarray(std_intrinsics, dtype=np.float64).reshape(-1)
    per_view, poses = [], []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        projected, _ = cv2.projectPoints(o, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((projected - i) ** 2, axis=2)))))
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(r)[0]
        T[:3, 3] = np.asarray(t).reshape(3)
        poses.append(T)
    return IntrinsicsResult(
        width=width,
        height=height,
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        distortion=(float(dist[0]), float(dist[1]), float(dist[2]), float(dist[3])),
        rms_px=float(rms),
        std=dict(zip(("fx", "fy", "cx", "cy", *RADTAN_KEYS), (float(v) for v in std[:8]))),
        per_view_rms_px=per_view,
        n_views=len(used),
        n_corners=int(sum(len(d) for d in used)),
        poses=poses,
    )
