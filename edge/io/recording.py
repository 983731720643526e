"""A recording: ``events.raw`` + ``general_eye_gaze.csv`` + ``calibration.json`` (+ text, meta, rgb, the
head's rotation: ``closed_loop_trajectory.csv``).

Opens either a directory in the recording format or a bare ``.raw`` file with its gaze CSV and
calibration given explicitly. Every missing piece is named in one ``RecordingError`` so a user can
fix them all at once. The events are not read here: use ``read_raw`` / ``RawReader`` on
``raw_path`` (or ``Recording.reader()``), which stream big files in chunks.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from darkread.edge.errors import RecordingError
from darkread.edge.io.calibration import Calibration, load_calibration
from darkread.edge.io.gaze_csv import GazeTrack, read_gaze_csv
from darkread.edge.io.imu_csv import IMU_NAME, ImuTrack, read_imu_csv
from darkread.edge.io.raw import RawReader

logger = logging.getLogger(__name__)

RAW_NAME = "events.raw"
GAZE_NAME = "general_eye_gaze.csv"
CALIBRATION_NAME = "calibration.json"
TEXT_NAME = "text.txt"
META_NAME = "meta.json"
RGB_NAME = "rgb.png"


@dataclass
class Recording:
    path: Path
    raw_path: Path
    gaze_path: Path
    calibration: Calibration
    text: str | None
    meta: dict
    rgb_path: Path | None = None
    imu_path: Path | None = None  # the gyroscope's stream, when the recording has one
    _gaze: GazeTrack | None = field(default=None, repr=False)

    def gaze(self) -> GazeTrack:
        """The gaze track (read once, then cached)."""
        if self._gaze is None:
            self._gaze = read_gaze_csv(self.gaze_path)
        return self._gaze

    def imu(self) -> ImuTrack | None:
        """The head's angular velocity (``edge.io.imu_csv``), or None when the recording has no IMU stream."""
        return None if self.imu_path is None else read_imu_csv(self.imu_path)

    def reader(self, **kwargs: Any):  # RawReader, imported lazily
        """A chunked reader of ``events.raw`` (``darkread.edge.io.raw.RawReader``)."""

        return RawReader(self.raw_path, **kwargs)


def open_recording(path: str | Path, *, gaze: str | None = None, calibration: str | None = None) -> Recording:
    """Open a recording directory, or a ``.raw`` file with ``gaze`` and ``calibration`` paths.

    Explicit ``gaze`` / ``calibration`` paths override the directory's own files.
    """
    path = Path(path)
    if path.is_dir():
        root, raw_path = path, path / RAW_NAME
    elif path.is_file():
        root, raw_path = path.parent, path
    else:
        raise RecordingError(f"{path}: no such recording (expected a directory or a .raw file)")

    in_directory = path.is_dir()
    gaze_path = Path(gaze) if gaze else (root / GAZE_NAME if in_directory else None)
    calibration_path = Path(calibration) if calibration else (root / CALIBRATION_NAME if in_directory else None)

    missing = []
    if not raw_path.is_file():
        missing.append(f"{raw_path} (event stream)")
    if gaze_path is None:
        missing.append("an eye-gaze CSV (for a bare .raw file: --gaze-csv CSV, or gaze=...)")
    elif not gaze_path.is_file():
        missing.append(f"{gaze_path} (eye-gaze CSV)")
    if calibration_path is None:
        missing.append("a calibration.json (for a bare .raw file: --calibration JSON, or calibration=...)")
    elif not calibration_path.is_file():
        missing.append(f"{calibration_path} (calibration)")
    if missing or gaze_path is None or calibration_path is None:
        raise RecordingError(f"{path}: incomplete recording, missing " + "; ".join(missing))

    text, meta, rgb_path, imu_path = None, {}, None, None
    if in_directory:
        text = _optional_text(root / TEXT_NAME)
        meta = _optional_meta(root / META_NAME)
        rgb_path = root / RGB_NAME if (root / RGB_NAME).is_file() else None
        imu_path = root / IMU_NAME if (root / IMU_NAME).is_file() else None
    return Recording(
        path=path,
        raw_path=raw_path,
        gaze_path=gaze_path,
        calibration=load_calibration(calibration_path),
        text=text,
        meta=meta,
        rgb_path=rgb_path,
        imu_path=imu_path,
    )


def _optional_text(path: Path) -> str | None:
    if not path.is_file():
        logger.warning("%s is missing: the printed text is unknown (reading still works)", path)
        return None
    return path.read_text(encoding="utf-8")


def _optional_meta(path: Path) -> dict:
    if not path.is_file():
        logger.warning("%s is missing (informational only)", path)
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: not valid JSON: {exc}") from exc
    if not isinstance(meta, dict):
        raise RecordingError(f"{path}: expected a JSON object")
    return meta
