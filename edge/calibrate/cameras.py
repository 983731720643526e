"""Camera models of the calibration inputs: a pinhole/radtan camera (``Intrinsics``) and Aria's Fisheye624.

Both map camera-frame points (x right, y down, z forward, metres) to pixels and back to
normalised rays (x/z, y/z), so pose estimation can run on undistorted points with an identity
camera matrix whatever the lens model.

Fisheye624 (projectaria_tools' FisheyeRadTanThinPrism), params ``[f, cx, cy, k0..k5, p0, p1, s0..s3]``:
theta = atan(r), r(theta) = theta + k0 theta^3 + ... + k5 theta^13, (u_r, v_r) = r(theta) (cos phi, sin phi),
tangential t_x = p0 (2 u_r^2 + rr) + 2 p1 u_r v_r, t_y = p1 (2 v_r^2 + rr) + 2 p0 u_r v_r and thin prism
s0 rr + s1 rr^2 (x), s2 rr + s3 rr^2 (y) with rr = u_r^2 + v_r^2; u = f (u_r + t_x + prism_x) + cx.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import Intrinsics, intrinsics_from_dict


class Camera(Protocol):
    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...

    def project(self, points_camera: np.ndarray) -> np.ndarray: ...

    def unproject(self, uv: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Fisheye624Camera:
    """Aria's FisheyeRadTanThinPrism model with one focal length (15 parameters)."""

    width: int
    height: int
    params: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.params) != 15:
            raise CalibrationError(f"Fisheye624 needs 15 parameters [f, cx, cy, k0..k5, p0, p1, s0..s3], got {len(self.params)}")

    def _distort(self, ab: np.ndarray) -> np.ndarray:
        """Normalised rays (x/z, y/z) -> distorted unit-focal coordinates."""
        p = self.params
        k = np.asarray(p[3:9])
        p0, p1 = p[9], p[10]
        s0, s1, s2, s3 = p[11:15]
        r = np.hypot(ab[:, 0], ab[:, 1])
        theta = np.arctan(r)
        t2 = theta * theta
        poly = theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * (k[3] + t2 * (k[4] + t2 * k[5]))))))
        scale = np.where(r > 1e-12, poly / np.maximum(r, 1e-12), 1.0)
        ur, vr = ab[:, 0] * scale, ab[:, 1] * scale
        rr = ur * ur + vr * vr
        x = ur + p0 * (2 * ur * ur + rr) + 2 * p1 * ur * vr + s0 * rr + s1 * rr * rr
        y = vr + p1 * (2 * vr * vr + rr) + 2 * p0 * ur * vr + s2 * rr + s3 * rr * rr
        return np.stack([x, y], axis=1)

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        pts = np.asarray(points_camera, dtype=np.float64).reshape(-1, 3)
        z = pts[:, 2]
        ab = pts[:, :2] / np.where(z > 0, z, 1.0)[:, None]
        f, cx, cy = self.params[:3]
        uv = self._distort(ab) * f + np.array([cx, cy])
        uv[z <= 0] = np.nan
        return uv

    def unproject(self, uv: np.ndarray, *, iterations: int = 20) -> np.ndarray:
        """Pixels -> normalised rays by Gauss-Newton on the distortion (numerical Jacobian)."""
        f, cx, cy = self.params[:3]
        target = (np.asarray(uv, dtype=np.float64).reshape(-1, 2) - np.array([cx, cy])) / f
        ab = target.copy()
        eps = 1e-7
        for _ in range(iterations):
            d = self._distort(ab)
            residual = d - target
            if np.max(np.abs(residual), initial=0.0) < 1e-12:
                break
            jx = (self._distort(ab + [eps, 0.0]) - d) / eps
            jy = (self._distort(ab + [0.0, eps]) - d) / eps
            a, b, c, e = jx[:, 0], jy[:, 0], jx[:, 1], jy[:, 1]
            det = a * e - b * c
            det = np.where(np.abs(det) < 1e-15, 1e-15, det)
            ab = ab - np.stack([(e * residual[:, 0] - b * residual[:, 1]) / det, (a * residual[:, 1] - c * residual[:, 0]) / det], 1)
        return ab


def matrix_from_list(value: Any, where: str) -> np.ndarray:
    matrix = np.asarray(value, dtype=np.float64)
    if matrix.shape != (4, 4) or not np.allclose(matrix[3], [0, 0, 0, 1]):
        raise CalibrationError(f"{where} must be a 4x4 rigid transform, rows listed first")
    return matrix


def rgb_camera_from_calibration(doc: dict) -> tuple[Intrinsics, np.ndarray]:
    """(camera, T_rgb_cpf) from the ``rgb_camera`` block of ``calibration.json``."""
    rgb = doc.get("rgb_camera")
    if not isinstance(rgb, dict):
        raise CalibrationError("calibration.json has no rgb_camera block (or pass --aria-calibration)")
    camera = intrinsics_from_dict(rgb, "rgb_camera", "calibration.json", distortion_required=False)
    if "T_rgb_cpf" not in rgb:
        raise CalibrationError("calibration.json: missing key rgb_camera.T_rgb_cpf")
    return camera, matrix_from_list(rgb["T_rgb_cpf"], "rgb_camera.T_rgb_cpf")


def _pose_from_aria(entry: dict, where: str) -> np.ndarray:
    """``{Translation: [x,y,z], UnitQuaternion: [w, [x,y,z]]}`` -> 4x4."""
    try:
        t = np.asarray(entry["Translation"], dtype=np.float64)
        w, (x, y, z) = entry["UnitQuaternion"]
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{where}: expected Translation and UnitQuaternion [w, [x, y, z]]") from exc
    q = np.array([w, x, y, z], dtype=np.float64)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = t
    return T


def aria_camera_from_device_calibration(
    path: str | Path, *, label: str = "camera-rgb", width: int | None = None, height: int | None = None
) -> tuple[Fisheye624Camera, np.ndarray]:
    """(camera, T_device_camera) of ``label`` from an Aria device-calibration JSON.

    The image size comes from ``ConfigData`` when present, else from ``width``/``height``
    (2880 x 2880 for the full-resolution Gen1 RGB camera). Images must be the raw (not upright-
    rotated) sensor images the calibration refers to.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"{path}: not a readable device-calibration JSON: {exc}") from exc
    for entry in doc.get("CameraCalibrations", []):
        if entry.get("Label") != label:
            continue
        projection = entry.get("Projection", {})
        if projection.get("Name") != "FisheyeRadTanThinPrism":
            raise CalibrationError(f"{path}: {label} uses {projection.get('Name')!r}; only FisheyeRadTanThinPrism is supported")
        config = entry.get("ConfigData", {})
        w = int(config.get("ImageWidth", width or 2880))
        h = int(config.get("ImageHeight", height or 2880))
        camera = Fisheye624Camera(w, h, tuple(float(v) for v in projection["Params"]))
        return camera, _pose_from_aria(entry.get("T_Device_Camera", {}), f"{path}: {label}.T_Device_Camera")
    raise CalibrationError(f"{path}: no camera labelled {label!r}")


def pose_from_aria_json(entry: dict, where: str = "pose") -> np.ndarray:
    """Public wrapper of the Aria pose layout, e.g. for a T_Device_CPF given on the command line."""
    return _pose_from_aria(entry, where)
