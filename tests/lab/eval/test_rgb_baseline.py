"""The RGB baseline: the simulated snapshot read by the OCR, and the fallback to a recording's rgb.png."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from factories import under_light

from darkread.core.text_metrics import error_rates
from darkread.lab.eval.rgb_baseline import read_snapshot
from darkread.lab.synth.rgb_camera import take_snapshot
from darkread.models.synth.session import Session


@pytest.fixture(scope="module")
def ocr():
    from darkread.cloud.ocr.rapid import RapidOcrBackend

    engine = RapidOcrBackend()
    if not engine.ready():
        pytest.skip("rapidocr is not installed")
    return engine


def test_ocr_reads_a_still_snapshot_at_1000_lux(still_pangram: Session, ocr) -> None:
    snap = take_snapshot(still_pangram, 1.0, np.random.default_rng(0))
    assert error_rates(still_pangram.page.text, read_snapshot(snap, ocr)).cer < 0.05


def test_ocr_fails_on_a_walking_snapshot_at_5_lux(walking_pangram: Session, ocr) -> None:
    dark = under_light(walking_pangram, 5.0)
    snaps = [take_snapshot(dark, t, np.random.default_rng(0)) for t in (0.5, 1.0, 1.5)]  # three gait phases
    assert min(s.blur_px for s in snaps) > 5.0
    cers = [error_rates(dark.page.text, read_snapshot(s, ocr)).cer for s in snaps]
    assert np.mean(cers) > 0.5


def test_a_recording_without_a_suite_spec_falls_back_to_its_own_rgb_png(tmp_path: Path) -> None:
    import cv2

    from darkread.lab.eval.rgb_baseline import baseline_snapshot

    with pytest.raises(FileNotFoundError, match="rgb.png"):
        baseline_snapshot(tmp_path)
    image = np.zeros((30, 40, 3), dtype=np.uint8)
    image[..., 0] = 200  # red in RGB order
    cv2.imwrite(str(tmp_path / "rgb.png"), image[..., ::-1])
    (tmp_path / "calibration.json").write_text(json.dumps({"rgb_camera": {"exposure_us": 32000}}))
    (tmp_path / "meta.json").write_text(json.dumps({"lux": 100.0}))
    snap, source = baseline_snapshot(tmp_path)
    assert source == "recorded rgb.png"
    assert np.array_equal(snap.crop, image) and snap.full is snap.crop
    assert snap.exposure_s == pytest.approx(0.032) and snap.lux == 100.0
