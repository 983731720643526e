from __future__ import annotations

import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest
from factories import under_light

from darkread.lab.synth.rgb_camera import (
    RgbCameraModel,
    auto_exposure,
    expose,
    jpeg_round_trip,
    recording_spec,
    snapshot_for_recording,
    take_snapshot,
    to_grey,
)
from darkread.models.synth.recording import RecordingSpec
from darkread.models.synth.session import Session

CAMERA = RgbCameraModel()


def _paper_noise(crop: np.ndarray) -> float:
    """Relative noise on the blank paper strip above the text (the crop's top rows)."""
    patch = crop[:6].astype(np.float64).mean(axis=2)
    return float(patch.std() / max(patch.mean(), 1.0))


def test_exposure_lengthens_as_light_falls_up_to_the_cap_then_gain_rises() -> None:
    levels = [1000.0, 300.0, 100.0, 30.0, 10.0, 5.0, 1.0]
    exposures = [auto_exposure(lux, 0.85) for lux in levels]
    times = [e.exposure_s for e in exposures]
    gains = [e.gain for e in exposures]
    assert times == sorted(times) and times[0] < CAMERA.max_exposure_s
    assert max(times) == pytest.approx(CAMERA.max_exposure_s)
    assert gains == sorted(gains) and gains[0] == 1.0 and max(gains) == CAMERA.max_gain
    assert [e.paper_electrons for e in exposures][-1] < exposures[0].paper_electrons / 100
    with pytest.raises(ValueError):
        auto_exposure(0.0, 0.85)


def test_darker_means_longer_exposure_more_blur_and_more_noise(walking_pangram: Session) -> None:
    bright = take_snapshot(under_light(walking_pangram, 1000.0), 1.0, np.random.default_rng(0))
    dark = take_snapshot(under_light(walking_pangram, 5.0), 1.0, np.random.default_rng(0))
    assert dark.exposure_s > 2 * bright.exposure_s
    assert dark.blur_px > 2 * bright.blur_px and dark.subframes > bright.subframes
    assert _paper_noise(dark.crop) > 2 * _paper_noise(bright.crop)


def test_noise_follows_the_signal_in_electrons() -> None:
    flat = np.full((200, 200), 0.8, dtype=np.float32)
    rng = np.random.default_rng(2)
    raw = RgbCameraModel(jpeg_quality=None)
    for lux in (1000.0, 30.0):
        exposure = auto_exposure(lux, 0.8)
        image = expose(flat, lux, exposure, rng, raw)[..., 1].astype(np.float64)
        assert image.mean() == pytest.approx(255 * 0.7354, rel=0.03)  # paper at linear 0.5 -> sRGB 0.735
        assert image.std() > 0
    bright = expose(flat, 1000.0, auto_exposure(1000.0, 0.8), rng, raw).std()
    dark = expose(flat, 30.0, auto_exposure(30.0, 0.8), rng, raw).std()
    assert dark > 2 * bright  # ~12x fewer electrons at 30 lux: sqrt(12) ~ 3.5x the relative noise


def test_a_bayer_sensor_is_noisier_in_grey_than_three_full_colour_planes() -> None:
    flat = np.full((200, 200), 0.8, dtype=np.float32)
    exposure = auto_exposure(30.0, 0.8)
    mosaic = RgbCameraModel(jpeg_quality=None, lens_psf_sigma_px=0.0)
    planes = replace(mosaic, bayer=False)
    greys = [to_grey(expose(flat, 30.0, exposure, np.random.default_rng(4), cam)).astype(float) for cam in (mosaic, planes)]
    block_noise = [g.reshape(25, 8, 25, 8).mean(axis=(1, 3)).std() for g in greys]
    # one colour per photosite collects a third of the light: sqrt(3) the noise over any patch
    # (demosaicing hides it per pixel by interpolating, so compare 8x8 patches)
    assert block_noise[0] > 1.4 * block_noise[1]


def test_lens_blur_softens_an_edge_and_jpeg_is_lossy() -> None:
    edge = np.zeros((64, 64), dtype=np.float32)
    edge[:, 32:] = 0.8
    exposure = auto_exposure(1000.0, 0.8)
    sharp = RgbCameraModel(jpeg_quality=None, lens_psf_sigma_px=0.0, bayer=False)
    soft = replace(sharp, lens_psf_sigma_px=1.5)
    rows = [to_grey(expose(edge, 1000.0, exposure, np.random.default_rng(5), cam)).astype(float).mean(axis=0)
            for cam in (sharp, soft)]
    assert rows[1][30] > rows[0][30] + 20 and rows[1][33] < rows[0][33] - 10  # light spreads across the edge
    image = expose(edge, 1000.0, exposure, np.random.default_rng(5), sharp)
    decoded = jpeg_round_trip(image, 40)
    assert decoded.shape == image.shape and decoded.dtype == np.uint8
    assert 0 < np.abs(decoded.astype(int) - image).mean() < 10


def test_snapshot_is_reproducible_and_frames_the_page(still_pangram: Session) -> None:
    a = take_snapshot(still_pangram, 1.0, np.random.default_rng(3))
    b = take_snapshot(still_pangram, 1.0, np.random.default_rng(3))
    assert np.array_equal(a.crop, b.crop)
    x0, y0, w, h = a.crop_xywh
    assert a.crop.shape == (h, w, 3)
    assert 0 <= x0 and x0 + w <= CAMERA.width and 0 <= y0 and y0 + h <= CAMERA.height
    # 2 lines of x-height ~11 px plus margins: a small crop near the image centre
    assert 40 < h < 400 and 100 < w < 800
    assert abs(x0 + w / 2 - CAMERA.width / 2) < CAMERA.width / 4


def test_recording_spec_round_trip_recreates_the_page(tmp_path: Path, still_pangram: Session) -> None:
    spec = RecordingSpec(lux=1000.0, motion="still", kind="pangram", seconds=2.0, seed=5, font="DejaVu Sans",
                         xheight_px=11.0, n_lines=2, line_chars=24)
    (tmp_path / "spec.json").write_text(json.dumps(asdict(spec)))
    (tmp_path / "text.txt").write_text(still_pangram.page.text)
    assert recording_spec(tmp_path) == spec
    snap = snapshot_for_recording(tmp_path)
    assert snap.lux == 1000.0 and snap.t_s == 1.0
    (tmp_path / "text.txt").write_text("another page")
    with pytest.raises(ValueError, match="text differs"):
        snapshot_for_recording(tmp_path)
    with pytest.raises(FileNotFoundError, match="make-suite"):
        recording_spec(tmp_path / "missing")
