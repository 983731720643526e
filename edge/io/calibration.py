"""``calibration.json`` of the recording format: event-camera intrinsics, CPF pose, clock offset.

The event camera uses OpenCV's radial-tangential model (k1, k2, p1, p2), so ``Calibration.project``
equals ``cv2.projectPoints``; it is written out in numpy so that it vectorises over any number of
points and marks points behind the camera as NaN instead of mirroring them into the image.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from darkread.edge.errors import CalibrationError

_RIGID_TOLERANCE = 1e-3


@dataclass(frozen=True, eq=False)
class Calibration:
    """Event camera seen from the glasses' central pupil frame (CPF)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float]  # radtan k1, k2, p1, p2
    T_event_cpf: np.ndarray = field(repr=False)  # 4x4, maps CPF points (m) into the event camera frame
    gaze_to_event_time_offset_us: int = 0  # t_event = t_device + offset
    rgb_camera: dict | None = field(default=None, repr=False)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Calibration):
            return NotImplemented
        scalars = ("width", "height", "fx", "fy", "cx", "cy", "distortion", "gaze_to_event_time_offset_us", "rgb_camera")
        return all(getattr(self, k) == getattr(other, k) for k in scalars) and np.array_equal(
            self.T_event_cpf, other.T_event_cpf
        )

    __hash__ = None  # type: ignore[assignment]

    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def distortion_coefficients(self) -> np.ndarray:
        """``[k1, k2, p1, p2]`` as OpenCV expects them."""
        return np.asarray(self.distortion, dtype=np.float64)

    def cpf_to_event(self, points_cpf: np.ndarray) -> np.ndarray:
        """(N, 3) CPF points -> (N, 3) event-camera-frame points."""
        points = np.asarray(points_cpf, dtype=np.float64).reshape(-1, 3)
        return points @ self.T_event_cpf[:3, :3].T + self.T_event_cpf[:3, 3]

    def project(self, points_event: np.ndarray) -> np.ndarray:
        """(N, 3) event-frame points -> (N, 2) pixels; points with Z <= 0 give NaN rows."""
        points = np.asarray(points_event, dtype=np.float64).reshape(-1, 3)
        z = points[:, 2]
        in_front = z > 0
        safe_z = np.where(in_front, z, 1.0)
        x, y = points[:, 0] / safe_z, points[:, 1] / safe_z
        k1, k2, p1, p2 = self.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)
        uv[~in_front] = np.nan
        return uv

    def on_sensor(self, uv: np.ndarray) -> np.ndarray:
        """Pixel centres sit at integers, so the sensor spans -0.5 <= u < width - 0.5 (likewise v)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            return (
                (uv[:, 0] >= -0.5) & (uv[:, 0] < self.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < self.height - 0.5)
            )


def _number(value: Any, where: str, path: Path) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationError(f"{path}: {where} must be a finite number, got {value!r}")
    return float(value)


def _get(mapping: Any, key: str, where: str, path: Path) -> Any:
    if not isinstance(mapping, dict):
        raise CalibrationError(f"{path}: {where} must be a JSON object")
    if key not in mapping:
        raise CalibrationError(f"{path}: missing key {where}.{key}" if where else f"{path}: missing key {key}")
    return mapping[key]


def _matrix4(value: Any, where: str, path: Path) -> np.ndarray:
    try:
        matrix = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: {where} must be a 4x4 list of numbers") from None
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise CalibrationError(f"{path}: {where} must be a finite 4x4 matrix, got shape {matrix.shape}")
    rotation = matrix[:3, :3]
    if not np.allclose(matrix[3], [0, 0, 0, 1]) or not np.allclose(
        rotation @ rotation.T, np.eye(3), atol=_RIGID_TOLERANCE
    ):
        raise CalibrationError(f"{path}: {where} is not a rigid transform (rotation + translation, last row 0 0 0 1)")
    return matrix


def load_calibration(path: str | Path) -> Calibration:
    """Read ``calibration.json``; ``CalibrationError`` says which key is missing or impossible."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationError(f"{path}: calibration file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"{path}: not a readable JSON file: {exc}") from exc

    camera = _get(doc, "event_camera", "", path)
    numbers = {k: _number(_get(camera, k, "event_camera", path), f"event_camera.{k}", path) for k in
               ("width", "height", "fx", "fy", "cx", "cy")}
    for k in ("width", "height"):
        if numbers[k] <= 0 or not numbers[k].is_integer():
            raise CalibrationError(f"{path}: event_camera.{k} must be a positive integer, got {camera[k]!r}")
    for k in ("fx", "fy"):
        if numbers[k] <= 0:
            raise CalibrationError(f"{path}: event_camera.{k} must be positive, got {camera[k]!r}")

    distortion = _get(camera, "distortion", "event_camera", path)
    model = _get(distortion, "model", "event_camera.distortion", path)
    if model == "radtan":
        coeffs = tuple(
            _number(_get(distortion, k, "event_camera.distortion", path), f"event_camera.distortion.{k}", path)
            for k in ("k1", "k2", "p1", "p2")
        )
    elif model == "none":
        coeffs = (0.0, 0.0, 0.0, 0.0)
    else:
        raise CalibrationError(f"{path}: event_camera.distortion.model {model!r} is not supported (radtan, none)")

    offset = _get(doc, "gaze_to_event_time_offset_us", "", path)
    if isinstance(offset, bool) or not isinstance(offset, int):
        raise CalibrationError(f"{path}: gaze_to_event_time_offset_us must be an integer, got {offset!r}")
    rgb = doc.get("rgb_camera")
    if rgb is not None and not isinstance(rgb, dict):
        raise CalibrationError(f"{path}: rgb_camera must be a JSON object")

    return Calibration(
        width=int(numbers["width"]),
        height=int(numbers["height"]),
        fx=numbers["fx"],
        fy=numbers["fy"],
        cx=numbers["cx"],
        cy=numbers["cy"],
        distortion=coeffs,  # type: ignore[arg-type]
        T_event_cpf=_matrix4(_get(doc, "T_event_cpf", "", path), "T_event_cpf", path),
        gaze_to_event_time_offset_us=offset,
        rgb_camera=rgb,
    )


def calibration_to_dict(calib: Calibration) -> dict[str, Any]:
    k1, k2, p1, p2 = (float(c) for c in calib.distortion)
    doc: dict[str, Any] = {
        "event_camera": {
            "width": int(calib.width),
            "height": int(calib.height),
            "fx": float(calib.fx),
            "fy": float(calib.fy),
            "cx": float(calib.cx),
            "cy": float(calib.cy),
            "distortion": {"model": "radtan", "k1": k1, "k2": k2, "p1": p1, "p2": p2},
        },
        "T_event_cpf": np.asarray(calib.T_event_cpf, dtype=np.float64).tolist(),
        "gaze_to_event_time_offset_us": int(calib.gaze_to_event_time_offset_us),
    }
    if calib.rgb_camera is not None:
        doc["rgb_camera"] = calib.rgb_camera
    return doc


def save_calibration(path: str | Path, calib: Calibration) -> None:
    """Write ``calibration.json`` in the recording format (round-trips through ``load_calibration``)."""
    Path(path).write_text(json.dumps(calibration_to_dict(calib), indent=2) + "\n", encoding="utf-8")
