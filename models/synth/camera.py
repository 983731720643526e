"""The head-mounted event camera: a plausible calibration and the pixel rays of a sensor region."""

from __future__ import annotations

import math

import cv2
import numpy as np

from darkread.edge.io.calibration import Calibration

SENSOR_WH = (1280, 720)


def rotation_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rotation matrix from small angles (radians) about x, then y, then z."""
    return cv2.Rodrigues(np.array([rx, ry, rz], dtype=np.float64))[0]


def random_calibration(rng: np.random.Generator, *, time_offset_us: int = 0) -> Calibration:
    """A 1280x720 camera with ~50x28 deg field of view, mounted a few cm off the CPF origin.

    CPF is x left, y up, z forward; the camera is x right, y down, z forward, so the nominal
    rotation flips x and y; mounting adds a small misalignment.
    """
    width, height = SENSOR_WH
    hfov = math.radians(rng.uniform(48.5, 51.5))
    fx = (width / 2) / math.tan(hfov / 2)
    fy = fx * rng.uniform(0.998, 1.002)
    flip = np.diag([-1.0, -1.0, 1.0])
    misalign = rotation_xyz(*np.radians(rng.normal(0.0, 1.5, 3)))
    T = np.eye(4)
    T[:3, :3] = misalign @ flip
    T[:3, 3] = [rng.uniform(-0.04, -0.025), rng.uniform(0.005, 0.015), rng.uniform(-0.005, 0.005)]
    return Calibration(
        width=width,
        height=height,
        fx=float(fx),
        fy=float(fy),
        cx=float(width / 2 + rng.normal(0, 4)),
        cy=float(height / 2 + rng.normal(0, 4)),
        distortion=(
            float(rng.uniform(-0.07, -0.02)),
            float(rng.uniform(0.0, 0.04)),
            float(rng.normal(0, 5e-4)),
            float(rng.normal(0, 5e-4)),
        ),
        T_event_cpf=T,
        gaze_to_event_time_offset_us=int(time_offset_us),
    )


def region_rays(calib: Calibration, x0: int, y0: int, width: int, height: int) -> np.ndarray:
    """Undistorted normalised rays (x/z, y/z) of the pixel centres of a region, float64 [h*w, 2]."""
    xs, ys = np.meshgrid(np.arange(x0, x0 + width, dtype=np.float64), np.arange(y0, y0 + height, dtype=np.float64))
    return calib.unproject(np.stack([xs.ravel(), ys.ravel()], axis=1), iterations=20, eps=1e-9)


def pixels_per_degree(calib: Calibration) -> float:
    return calib.fx * math.tan(math.radians(1.0))
