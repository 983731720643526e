"""``calibration.json`` of the recording format: event-camera intrinsics, CPF pose, clock offset.

The event camera is an ``Intrinsics`` (pinhole + radtan, ``intrinsics.py``); ``Calibration`` adds
where it sits on the glasses and the clock offset to the gaze.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from darkread.core.json_file import read_json_file
from darkread.edge.errors import CalibrationError
from darkread.edge.io.intrinsics import Intrinsics, intrinsics_from_dict, intrinsics_to_dict

_RIGID_TOLERANCE = 1e-3


@dataclass(frozen=True, eq=False)
class Calibration(Intrinsics):
    """The event camera's intrinsics, and where it sits on the glasses: seen from the central
    pupil frame (CPF), on the device clock."""

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

    __hash__ = None  # type: ignore[assignment]  # unhashable, as its equality compares arrays; mypy wants a method here

    def cpf_to_event(self, points_cpf: np.ndarray) -> np.ndarray:
        """(N, 3) CPF points -> (N, 3) event-camera-frame points."""
        points = np.asarray(points_cpf, dtype=np.float64).reshape(-1, 3)
        return points @ self.T_event_cpf[:3, :3].T + self.T_event_cpf[:3, 3]


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
    doc = read_json_file(path, "calibration file", error=CalibrationError)

    camera = intrinsics_from_dict(_get(doc, "event_camera", "", path), "event_camera", str(path))

    offset = _get(doc, "gaze_to_event_time_offset_us", "", path)
    if isinstance(offset, bool) or not isinstance(offset, int):
        raise CalibrationError(f"{path}: gaze_to_event_time_offset_us must be an integer, got {offset!r}")
    rgb = doc.get("rgb_camera")
    if rgb is not None and not isinstance(rgb, dict):
        raise CalibrationError(f"{path}: rgb_camera must be a JSON object")

    return Calibration(
        **{f.name: getattr(camera, f.name) for f in fields(camera)},
        T_event_cpf=_matrix4(_get(doc, "T_event_cpf", "", path), "T_event_cpf", path),
        gaze_to_event_time_offset_us=offset,
        rgb_camera=rgb,
    )


def calibration_to_dict(calib: Calibration) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "event_camera": intrinsics_to_dict(calib),
        "T_event_cpf": np.asarray(calib.T_event_cpf, dtype=np.float64).tolist(),
        "gaze_to_event_time_offset_us": int(calib.gaze_to_event_time_offset_us),
    }
    if calib.rgb_camera is not None:
        doc["rgb_camera"] = calib.rgb_camera
    return doc


def save_calibration(path: str | Path, calib: Calibration) -> None:
    """Write ``calibration.json`` in the recording format (round-trips through ``load_calibration``)."""
    Path(path).write_text(json.dumps(calibration_to_dict(calib), indent=2) + "\n", encoding="utf-8")
