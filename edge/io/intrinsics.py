"""Camera intrinsics, once: a pinhole with OpenCV's radial-tangential distortion (k1, k2, p1, p2).

``Intrinsics`` is the value every camera of the glasses is described by: the event camera of
``calibration.json`` (``Calibration`` extends it with the CPF pose and the clock offset), the RGB
camera block, the result of an intrinsics calibration (``IntrinsicsResult`` adds its residuals)
and the simulated RGB camera. ``project`` equals ``cv2.projectPoints`` but is written in numpy so
it vectorises over any number of points and marks points behind the camera as NaN instead of
mirroring them into the image. ``intrinsics_from_dict`` is the one parser of the JSON block.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from darkread.edge.errors import CalibrationError

Distortion = tuple[float, float, float, float]  # radtan k1, k2, p1, p2
RECTIFIED: Distortion = (0.0, 0.0, 0.0, 0.0)
RADTAN_KEYS = ("k1", "k2", "p1", "p2")


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera with radtan distortion; ``RECTIFIED`` (all zeros) is an ideal pinhole."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: Distortion

    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def distortion_coefficients(self) -> np.ndarray:
        """``[k1, k2, p1, p2]`` as OpenCV expects them."""
        return np.asarray(self.distortion, dtype=np.float64)

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points -> (N, 2) pixels; points with Z <= 0 give NaN rows."""
        points = np.asarray(points_camera, dtype=np.float64).reshape(-1, 3)
        z = points[:, 2]
        in_front = z > 0
        safe_z = np.where(in_front, z, 1.0)
        u, v = self._distorted_pixel(points[:, 0] / safe_z, points[:, 1] / safe_z)
        uv = np.stack([u, v], axis=1)
        uv[~in_front] = np.nan
        return uv

    def project_point(self, x: float, y: float, z: float) -> tuple[float, float] | None:
        """One camera-frame point -> its pixel (None behind the camera): ``project`` in plain floats,
        the same arithmetic, for the per-frame lookups where numpy's per-call cost is 50x the work."""
        if not z > 0:
            return None
        return self._distorted_pixel(x / z, y / z)

    def _distorted_pixel(self, x, y):  # floats or arrays alike
        """Normalised image coordinates -> pixel through the radtan model (one formula for both paths)."""
        k1, k2, p1, p2 = self.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return self.fx * xd + self.cx, self.fy * yd + self.cy

    def unproject(self, uv: np.ndarray, *, iterations: int = 30, eps: float = 1e-10) -> np.ndarray:
        """(N, 2) pixels -> (N, 2) undistorted normalised rays (x/z, y/z) (``cv2.undistortPoints``)."""
        import cv2  # lazy: OpenCV only for a lens with distortion

        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
        return cv2.undistortPoints(
            pts, self.camera_matrix(), self.distortion_coefficients(), R=None, P=None, criteria=criteria
        ).reshape(-1, 2)

    def point_on_sensor(self, u: float, v: float) -> bool:
        """``on_sensor`` of one pixel."""
        return -0.5 <= u < self.width - 0.5 and -0.5 <= v < self.height - 0.5

    def on_sensor(self, uv: np.ndarray) -> np.ndarray:
        """Pixel centres sit at integers, so the sensor spans -0.5 <= u < width - 0.5 (likewise v)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            return (
                (uv[:, 0] >= -0.5) & (uv[:, 0] < self.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < self.height - 0.5)
            )

    def intrinsics(self) -> Intrinsics:
        """Just the camera (drops what a subclass adds)."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy, self.distortion)


def _number(block: dict, key: str, name: str, source: str) -> float:
    if key not in block:
        raise CalibrationError(f"{source}: missing key {name}.{key}")
    value = block[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationError(f"{source}: {name}.{key} must be a finite number, got {value!r}")
    return float(value)


def radtan_from_dict(block: Any, name: str, source: str) -> Distortion:
    """``{"model": "radtan", "k1": .., "k2": .., "p1": .., "p2": ..}`` or ``{"model": "none"}``."""
    if not isinstance(block, dict):
        raise CalibrationError(f"{source}: {name} must be a JSON object")
    if "model" not in block:
        raise CalibrationError(f"{source}: missing key {name}.model")
    if block["model"] == "none":
        return RECTIFIED
    if block["model"] != "radtan":
        raise CalibrationError(f"{source}: {name}.model {block['model']!r} is not supported (radtan, none)")
    k1, k2, p1, p2 = (_number(block, k, name, source) for k in RADTAN_KEYS)
    return (k1, k2, p1, p2)


def intrinsics_to_dict(camera: Intrinsics) -> dict[str, Any]:
    """The JSON block of a camera (``event_camera`` of ``calibration.json``, the camera part of ``rgb_camera``)."""
    return {
        "width": int(camera.width),
        "height": int(camera.height),
        "fx": float(camera.fx),
        "fy": float(camera.fy),
        "cx": float(camera.cx),
        "cy": float(camera.cy),
        "distortion": {"model": "radtan", **{k: float(c) for k, c in zip(RADTAN_KEYS, camera.distortion)}},
    }


def intrinsics_from_dict(block: Any, name: str, source: str, *, distortion_required: bool = True) -> Intrinsics:
    """The camera of a JSON block (``width``, ``height``, ``fx``, ``fy``, ``cx``, ``cy``, ``distortion``);
    ``CalibrationError`` names ``source`` and the key (``name.key``) that is missing or impossible.
    Without ``distortion_required`` a missing ``distortion`` means a rectified camera."""
    if not isinstance(block, dict):
        raise CalibrationError(f"{source}: {name} must be a JSON object")
    numbers = {k: _number(block, k, name, source) for k in ("width", "height", "fx", "fy", "cx", "cy")}
    for k in ("width", "height"):
        if numbers[k] <= 0 or not numbers[k].is_integer():
            raise CalibrationError(f"{source}: {name}.{k} must be a positive integer, got {block[k]!r}")
    for k in ("fx", "fy"):
        if numbers[k] <= 0:
            raise CalibrationError(f"{source}: {name}.{k} must be positive, got {block[k]!r}")
    if "distortion" not in block and distortion_required:
        raise CalibrationError(f"{source}: missing key {name}.distortion")
    distortion = radtan_from_dict(block.get("distortion", {"model": "none"}), f"{name}.distortion", source)
    return Intrinsics(
        int(numbers["width"]), int(numbers["height"]), numbers["fx"], numbers["fy"], numbers["cx"], numbers["cy"], distortion
    )
