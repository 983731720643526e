"""The RGB baseline: the simulated RGB snapshot (``darkread.lab.synth.rgb_camera``) of a suite
recording's scene, read by the same OCR engine and scored against its printed text."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from darkread.core.image_codec import read_image, write_png
from darkread.core.text_metrics import error_rates
from darkread.lab.synth.rgb_camera import (
    SPEC_NAME,
    RgbCameraModel,
    RgbSnapshot,
    snapshot_for_recording,
    to_grey,
)

if TYPE_CHECKING:
    from darkread.cloud.ocr import OcrBackend


def recorded_snapshot(recording_dir: str | Path) -> RgbSnapshot | None:
    """The recording's own ``rgb.png`` (the format's optional RGB snapshot) as a snapshot, or None.

    For recordings not made by a suite (real ones): nothing to re-create, so the OCR reads the whole
    recorded image; exposure comes from ``calibration.json``'s ``rgb_camera`` block when present.
    """
    recording_dir = Path(recording_dir)
    path = recording_dir / "rgb.png"
    if not path.is_file():
        return None
    image = read_image(path, colour=True)
    rgb_camera: dict[str, Any] = {}
    calibration = recording_dir / "calibration.json"
    if calibration.is_file():
        rgb_camera = json.loads(calibration.read_text(encoding="utf-8")).get("rgb_camera") or {}
    meta = recording_dir / "meta.json"
    lux = json.loads(meta.read_text(encoding="utf-8")).get("lux", math.nan) if meta.is_file() else math.nan
    h, w = image.shape[:2]
    return RgbSnapshot(
        crop=image, crop_xywh=(0, 0, w, h), lux=float(lux) if lux is not None else math.nan, t_s=math.nan,
        exposure_s=float(rgb_camera.get("exposure_us", math.nan)) * 1e-6, gain=math.nan, paper_electrons=math.nan,
        blur_px=math.nan, subframes=0, full=image,
    )


def baseline_snapshot(recording_dir: str | Path, camera: RgbCameraModel = RgbCameraModel()) -> tuple[RgbSnapshot, str]:
    """The snapshot the baseline reads, and where it comes from: re-simulated for suite recordings
    (``spec.json``), else the recording's own ``rgb.png``."""
    recording_dir = Path(recording_dir)
    if (recording_dir / SPEC_NAME).is_file():
        return snapshot_for_recording(recording_dir, camera, full_frame=True), "simulated"
    recorded = recorded_snapshot(recording_dir)
    if recorded is None:
        raise FileNotFoundError(
            f"{recording_dir}: no RGB snapshot (neither {SPEC_NAME} from `darkread eval make-suite` nor rgb.png)"
        )
    return recorded, "recorded rgb.png"


@dataclass
class RgbReading:
    text: str
    cer: float
    wer: float
    snapshot: dict[str, Any]


def read_snapshot(snapshot: RgbSnapshot, backend: OcrBackend) -> str:
    return backend.read(to_grey(snapshot.crop)).text


def rgb_baseline(recording_dir: str | Path, backend: OcrBackend, *, save_crop: str | Path | None = None) -> RgbReading:
    """OCR of the simulated RGB snapshot of a suite recording, scored against its text.txt."""

    snap = snapshot_for_recording(recording_dir)
    if save_crop is not None:
        write_png(save_crop, snap.crop)
    text = read_snapshot(snap, backend)
    reference = (Path(recording_dir) / "text.txt").read_text(encoding="utf-8")
    rates = error_rates(reference, text)
    return RgbReading(text=text, cer=rates.cer, wer=rates.wer, snapshot=snap.describe())
